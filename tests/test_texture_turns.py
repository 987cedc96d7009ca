"""model.texture_turns and model.offsets_behind: the photo projected from four cameras a quarter turn
apart, behind what the input camera sees (configs/photos.yaml; docs/training.md, "The photo config's
choices"), and the photo config with the roundness priors off for a class that is not round."""

import math

import pytest
import torch

from mitsuba_platonic.config import load_config
from mitsuba_platonic.networks.photo_colours import photo_texture


@pytest.mark.parametrize("θ", [0.0, 0.3])
def test_each_quarter_of_the_azimuth_shows_its_turned_cameras_photo(θ):
    r = 32
    g = torch.Generator().manual_seed(0)
    photo = torch.rand(1, 4, r, r, generator=g)
    photo[:, 3] = 1.0
    t = photo_texture(photo, r, torch.tensor([θ]), turns=4)
    c = -1.0 + (torch.arange(r, dtype=torch.float64) + 0.5) * (2.0 / r)
    x, y, z = c[None, None, :], c.flip(0)[None, :, None], c.flip(0)[:, None, None]   # G's frame: d, h, w
    x, y, z = torch.broadcast_tensors(x, y, z)
    φ = torch.atan2(x, z)
    for k in range(4):
        φ_k = k * math.pi / 2.0
        near = torch.remainder(φ - φ_k + math.pi, 2 * math.pi).sub(math.pi).abs() < math.radians(20.0)
        x_k = x * math.cos(φ_k) - z * math.sin(φ_k)
        z_k = x * math.sin(φ_k) + z * math.cos(φ_k)
        Y = y * math.cos(θ) - z_k * math.sin(θ)
        grid = torch.stack([x_k, -Y], -1).reshape(1, r, r * r, 2).float()
        seen = torch.nn.functional.grid_sample(photo[:, :3], grid, mode="bilinear", padding_mode="border",
                                               align_corners=False).reshape(3, r, r, r)
        assert near.sum() > 1000
        assert (t[0][:, near] - seen[:, near]).abs().max() < 2e-3     # the others' weight ≤ cos(70°)^8 ≈ 2e-4


def test_one_turn_is_the_carried_photo_and_the_key_is_checked(tmp_path):
    photo = torch.rand(2, 4, 16, 16)
    photo[:, 3] = 1.0
    assert torch.equal(photo_texture(photo, 16, None), photo_texture(photo, 16, None, turns=1))
    with pytest.raises(ValueError, match="turns"):
        photo_texture(photo, 16, None, turns=3)
    cfg = load_config("photos", [f"data.path={tmp_path}", "model.texture_turns=4"])
    assert cfg.model.net_config(4).texture_turns == 4
    from mitsuba_platonic.settings_checks import ConfigError
    with pytest.raises(ConfigError, match="model.texture_turns"):
        load_config("photos", [f"data.path={tmp_path}", "model.texture_turns=2"])


def test_the_turned_texture_goes_where_the_input_camera_does_not_see():
    from torch import nn
    from mitsuba_platonic.networks.photo_colours import texture_corrected

    r = 8
    conv = nn.Conv3d(8, 4, 3, padding=1)
    nn.init.zeros_(conv.weight)
    nn.init.zeros_(conv.bias)                                     # no correction: colour = σ(ℓ + logit t)
    carried, behind = torch.full((1, 3, r, r, r), 0.2), torch.full((1, 3, r, r, r), 0.7)
    volume = torch.zeros(1, 4, r, r, r)
    volume[:, 3, :2] = 1.0 - 1e-6                                  # an opaque slab at the front (d = 0, 1)
    colour, _ = texture_corrected(conv, volume, torch.zeros(1, 3, r, r, r), carried, None, behind)
    assert torch.allclose(colour[:, :3, :1], carried[:, :, :1], atol=1e-5)      # seen: the photo's pixel
    assert torch.allclose(colour[:, :3, 2:], behind[:, :, 2:], atol=1e-4)       # behind the slab: the turned one
    plain, _ = texture_corrected(conv, volume, torch.zeros(1, 3, r, r, r), carried, None)
    assert torch.allclose(plain[:, :3], carried, atol=1e-5)


def test_without_offsets_behind_the_body_keeps_the_turned_texture_and_the_seen_surface_its_offsets(tmp_path):
    from torch import nn
    from mitsuba_platonic.networks.photo_colours import texture_corrected
    from mitsuba_platonic.settings_checks import ConfigError

    r = 8
    conv = nn.Conv3d(8, 4, 3, padding=1)
    nn.init.zeros_(conv.weight)
    nn.init.zeros_(conv.bias)
    carried, behind = torch.full((1, 3, r, r, r), 0.2), torch.full((1, 3, r, r, r), 0.7)
    volume = torch.zeros(1, 4, r, r, r)
    volume[:, 3, :2] = 1.0 - 1e-6                                  # an opaque slab at the front (d = 0, 1)
    ℓ = torch.full((1, 3, r, r, r), 1.5, requires_grad=True)       # G's offsets, the same everywhere
    colour, used = texture_corrected(conv, volume, ℓ, carried, None, behind, offsets_behind=False)
    assert torch.allclose(colour[:, :3, :1], torch.sigmoid(torch.logit(carried[:, :, :1]) + 1.5), atol=1e-5)
    assert torch.allclose(colour[:, :3, 2:], behind[:, :, 2:], atol=1e-4)       # behind: the texture as read
    assert used[:, :, 2:].abs().max() < 1e-4 and torch.allclose(used[:, :, :1], ℓ[:, :, :1])
    colour[:, :3].sum().backward()
    assert ℓ.grad[:, :, 2:].abs().max() < 1e-4 < ℓ.grad[:, :, :1].abs().min()   # no gradient to the unseen offsets
    with_offsets, _ = texture_corrected(conv, volume, ℓ.detach(), carried, None, behind)
    assert torch.allclose(with_offsets[:, :3, 2:], torch.sigmoid(torch.logit(behind[:, :, 2:]) + 1.5), atol=1e-4)
    cfg = load_config("photos", [f"data.path={tmp_path}"])
    assert cfg.model.net_config(4).offsets_behind is False and cfg.model.net_config(4).texture_turns == 4
    with pytest.raises(ConfigError, match="model.offsets_behind"):
        load_config("photos", [f"data.path={tmp_path}", "model.texture_turns=1"])


def test_the_photo_config_with_its_roundness_off_loads_as_documented(tmp_path):
    """docs/training.md: a class that is not round about its vertical (chairs, cars) turns off the
    turn and the four cameras together; offsets_behind goes back to true with them."""
    cfg = load_config("photos", [f"data.path={tmp_path}", "train.turn=0", "model.texture_turns=1",
                                 "model.offsets_behind=true"])
    assert (cfg.train.turn, cfg.model.texture_turns, cfg.model.offsets_behind) == (0.0, 1, True)
    assert cfg.train.solidity == 1.0                                  # solidity does not assume a round class
