"""train.colour_tv: the density-weighted colour total variation (train/losses.colour_tv) on known
volumes, its gradient (colour only, never density), and the trainer handing it to G."""

import pytest
import torch

from mitsuba_platonic.config import ConfigError, load_config
from mitsuba_platonic.train.losses import colour_tv


def _volume(n=4, colour=(0.2, 0.5, 0.7), density=1.0):
    v = torch.empty(1, 4, n, n, n, dtype=torch.float64)
    v[:, :3] = torch.tensor(colour, dtype=torch.float64)[None, :, None, None, None]
    v[:, 3] = density
    return v


def test_a_uniform_colour_costs_nothing_and_an_empty_volume_gives_zero():
    assert float(colour_tv(_volume())) == 0.0
    v = _volume(density=0.0)
    v[:, :3] = torch.rand(1, 3, 4, 4, 4, dtype=torch.float64)          # any colour where nothing is
    assert float(colour_tv(v)) == 0.0


def test_a_colour_step_inside_matter_costs_its_size_over_the_weighted_pairs():
    """A 4³ solid (ρ = ½ everywhere) with red in the front half (d < 2) and blue behind: of the
    3 · 4 · 4 · 3 = 144 neighbour pairs (each of weight ½), the 16 across d = 1|2 differ by
    ‖(1, 0, 0) − (0, 0, 1)‖₁ = 2, so L = 16 · ½ · 2 / (3 · 144 · ½) = 32 / 432."""
    v = _volume(density=0.5)
    v[:, :3, :2] = torch.tensor([1.0, 0.0, 0.0], dtype=torch.float64)[None, :, None, None, None]
    v[:, :3, 2:] = torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64)[None, :, None, None, None]
    assert float(colour_tv(v)) == pytest.approx(32 / 432, rel=1e-12)
    # the same step where the back half is empty costs nothing: w = min(ρ_i, ρ_j) = 0 across it
    v[:, 3, 2:] = 0.0
    assert float(colour_tv(v)) == 0.0


def test_colour_tv_moves_colour_not_density_and_matches_finite_differences():
    torch.manual_seed(0)
    v = torch.rand(2, 4, 5, 5, 5, dtype=torch.float64, requires_grad=True)
    colour_tv(v).backward()
    assert float(v.grad[:, 3].abs().max()) == 0.0                     # weights held constant
    assert float(v.grad[:, :3].abs().max()) > 0.0
    h, idx = 1e-6, (1, 2, 3, 1, 4)
    with torch.no_grad():
        up, down = v.clone(), v.clone()
        up[idx] += h
        down[idx] -= h
        fd = (float(colour_tv(up)) - float(colour_tv(down))) / (2 * h)
    assert abs(float(v.grad[idx]) - fd) < 1e-6


def test_colour_tv_refuses_a_volume_without_colour():
    with pytest.raises(ValueError, match=r"colour_tv: expected an EA volume \(B, 4, D, H, W\), got \(1, 1, 4, 4, 4\)"):
        colour_tv(torch.zeros(1, 1, 4, 4, 4))


def test_the_config_refuses_colour_tv_without_colour_or_below_zero():
    with pytest.raises(ConfigError, match="train.colour_tv: colour needs render.model 'ea', got 'vh'"):
        load_config(None, ["train.colour_tv=0.1", "render.model=vh", "data.formation=vh"])
    with pytest.raises(ConfigError, match=r"train.colour_tv: expected a non-negative value, got -0.5"):
        load_config(None, ["train.colour_tv=-0.5"])
    assert load_config(None, []).train.colour_tv == 0.0


@pytest.mark.usefixtures("tiny_class")
def test_the_trainer_hands_colour_tv_to_g_only_when_its_weight_is_set(tmp_path):
    from mitsuba_platonic.train.data import load_training_data
    from mitsuba_platonic.train.trainer import Trainer
    from tiny_shapes import TINY
    seen = {}
    for weight in (0.0, 0.5):
        cfg = load_config(None, [
            f"data.cache={tmp_path}", f"data.shape_class={TINY}", "data.n_shapes=4", "data.views_per_shape=2",
            "model.resolution=16", "model.width=4", "model.latent=8", "train.batch_size=2",
            "render.backend=closed_form", f"train.colour_tv={weight}"])
        trainer = Trainer(cfg, load_training_data(cfg, progress=False), torch.device("cpu"))
        original = trainer._g_objective

        def probe(terms, weight=weight, original=original):
            seen[weight] = {k: v.detach().clone() for k, v in terms.items()}
            return original(terms)

        trainer._g_objective = probe
        trainer.step(0)
    assert "colour_tv" not in seen[0.0]
    assert float(seen[0.5]["colour_tv"]) > 0.0
    with pytest.raises(ConfigError, match="train.colour_tv: the 'gan3d' baseline"):
        load_config(None, ["train.colour_tv=0.1", "train.mode=gan3d", "train.loss=wgan-gp",
                           "train.rec_target=volume"])
