"""train.colour_tv: the density-weighted colour total variation (train/losses.colour_tv) on known
volumes, its gradient (colour only, never density), and the trainer handing it to G; and
train.colour_match (train/losses.colour_match): the mean colour of the object from every side; and
train.colour_offset (train/losses.colour_offset): G's colour held to the photo's; and
train.depth_spread (train/losses.depth_spread): the input view's colour from a thin surface."""

import pytest
import torch

from mitsuba_platonic.config import ConfigError, load_config
from mitsuba_platonic.train.losses import colour_match, colour_offset, colour_tv, depth_spread, mean_colour


def _volume(n=4, colour=(0.2, 0.5, 0.7), density=1.0):
    v = torch.empty(1, 4, n, n, n, dtype=torch.float64)
    v[:, :3] = torch.tensor(colour, dtype=torch.float64)[None, :, None, None, None]
    v[:, 3] = density
    return v


def _tiny_trainer(tmp_path, *overrides):
    """A trainer on the tiny procedural class (16³ volumes, batch 2, the closed-form layer), with ``overrides``."""
    from mitsuba_platonic.train.data import load_training_data
    from mitsuba_platonic.train.trainer import Trainer
    from tiny_shapes import TINY
    cfg = load_config(None, [
        f"data.cache={tmp_path}", f"data.shape_class={TINY}", "data.n_shapes=4", "data.views_per_shape=2",
        "model.resolution=16", "model.width=4", "model.latent=8", "train.batch_size=2", "render.backend=closed_form",
        *overrides])
    return Trainer(cfg, load_training_data(cfg, progress=False), torch.device("cpu"))


def _g_terms(trainer):
    """G's weighted terms (detached) of ``trainer``'s first step, as its objective received them."""
    terms = {}
    original = trainer._g_objective
    trainer._g_objective = lambda t: terms.update({k: v.detach().clone() for k, v in t.items()}) or original(t)
    trainer.step(0)
    return terms


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
    seen = {}
    for weight in (0.0, 0.5):
        seen[weight] = _g_terms(_tiny_trainer(tmp_path, f"train.colour_tv={weight}"))
    assert "colour_tv" not in seen[0.0]
    assert float(seen[0.5]["colour_tv"]) > 0.0
    with pytest.raises(ConfigError, match="train.colour_tv: the 'gan3d' baseline"):
        load_config(None, ["train.colour_tv=0.1", "train.mode=gan3d", "train.loss=wgan-gp",
                           "train.rec_target=volume"])


def _image(colour, alpha):
    """A premultiplied RGBA image (1, 4, 4, 4): ``colour`` where ``alpha`` ``(4, 4)`` covers."""
    a = torch.as_tensor(alpha, dtype=torch.float64)
    return torch.cat([torch.tensor(colour, dtype=torch.float64)[:, None, None] * a, a[None]])[None]


def test_mean_colour_weighs_each_pixel_by_its_coverage():
    """Four pixels of red at α 1 and four of blue at α ½: Σ rgb = (4, 0, 2) over Σ α = 6, so
    c̄ = (4/6, 0, 2/6): each pixel counts by its coverage."""
    alpha = torch.zeros(4, 4, dtype=torch.float64)
    alpha[:1] = 1.0                                          # 4 pixels of red
    img = _image((1.0, 0.0, 0.0), alpha)
    blue = torch.zeros(4, 4, dtype=torch.float64)
    blue[3] = 0.5                                            # 4 pixels of blue at α ½
    img = img + _image((0.0, 0.0, 1.0), blue)
    assert torch.allclose(mean_colour(img), torch.tensor([[4 / 6, 0.0, 2 / 6]], dtype=torch.float64))
    assert torch.equal(mean_colour(torch.zeros(1, 4, 3, 3)), torch.zeros(1, 3))         # empty: 0, finite
    with pytest.raises(ValueError, match=r"mean_colour: expected RGBA images \(B, 4, H, W\), got \(1, 1, 3, 3\)"):
        mean_colour(torch.zeros(1, 1, 3, 3))


def test_colour_match_is_zero_for_the_same_colour_from_another_side_and_the_mean_difference_otherwise():
    """A view of another silhouette in the photo's colour costs nothing; a view darker by half costs
    the mean over channels of |c/2 − c|; K = 2 views per photo pair up with their own photo."""
    full, part = torch.ones(4, 4, dtype=torch.float64), torch.zeros(4, 4, dtype=torch.float64)
    part[1:3, 1:3] = 0.7
    photo = _image((0.2, 0.4, 0.6), full)
    assert float(colour_match(_image((0.2, 0.4, 0.6), part), photo)) == pytest.approx(0.0, abs=1e-12)
    dark = _image((0.1, 0.2, 0.3), part)
    assert float(colour_match(dark, photo)) == pytest.approx((0.1 + 0.2 + 0.3) / 3, rel=1e-12)
    photos = torch.cat([photo, _image((0.1, 0.2, 0.3), full)])
    views = torch.cat([_image((0.2, 0.4, 0.6), part), dark, dark, dark])   # photo 0: 0, 0.2; photo 1: 0, 0
    assert float(colour_match(views, photos)) == pytest.approx(0.2 / 4, rel=1e-12)
    with pytest.raises(ValueError, match="colour_match: expected K renders per photo, got 3 for 2"):
        colour_match(views[:3], photos)


def test_colour_match_moves_the_views_and_not_the_photos_and_matches_finite_differences():
    torch.manual_seed(1)
    views = torch.rand(4, 4, 3, 3, dtype=torch.float64)
    views[:, :3] *= views[:, 3:]                             # premultiplied
    views.requires_grad_(True)
    photos = torch.rand(2, 4, 3, 3, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda v: colour_match(v, photos), (views,))
    colour_match(views, photos).backward()
    assert photos.grad is None or not photos.grad.any()


def test_the_config_refuses_colour_match_without_colour_or_an_input_photo():
    with pytest.raises(ConfigError, match="train.colour_match: colour needs render.model 'ea', got 'vh'"):
        load_config(None, ["train.colour_match=1", "render.model=vh", "data.formation=vh"])
    with pytest.raises(ConfigError, match=r"train.colour_match: expected a non-negative value, got -1"):
        load_config(None, ["train.colour_match=-1"])
    with pytest.raises(ConfigError, match="train.colour_match: the random views answer to the input photo's colour.*"
                                          "task 'generation'"):
        load_config(None, ["train.colour_match=1", "train.task=generation"])


@pytest.mark.usefixtures("tiny_class")
def test_the_trainer_hands_g_the_colour_match_of_the_views_d_saw_against_the_photos_e_read(tmp_path):
    """With weight w, G's 'colour_match' term is w · mean |c̄(I_view) − c̄(x)|, computed here from
    the random views D's update saw (its fakes) and the photos E read; without it, no such term."""
    for weight in (0.0, 2.0):
        trainer = _tiny_trainer(tmp_path, "train.random_views=2", "train.task=reconstruction", f"train.colour_match={weight}")
        seen = {"D": []}
        trainer.nets["E"].register_forward_hook(lambda m, i, o: [seen.setdefault("x", i[0].detach().clone())] and None)
        trainer.nets["D"].register_forward_hook(lambda m, i, o: seen["D"].append(i[0].detach().clone()))
        terms = _g_terms(trainer)
        if not weight:
            assert "colour_match" not in terms
            continue
        x = seen["x"]
        fakes = seen["D"][0][len(x) * 2:]                    # D's update: 2 · 2 reals (x repeated), 4 views
        assert len(fakes) == 4
        c = lambda im: im[:, :3].sum((2, 3)) / im[:, 3].sum((1, 2))[:, None]
        expected = weight * (c(fakes) - c(x).repeat_interleave(2, 0)).abs().mean()
        assert float(terms["colour_match"].detach()) == pytest.approx(float(expected), rel=1e-5)


def test_colour_offset_is_the_density_weighted_mean_offset_and_moves_colour_only():
    """Two voxels of density 1 and ¼ (the rest empty) with offsets (1, 2, 3) and (−4, 0, 0):
    L = (1 · 6 + ¼ · 4) / (3 · 1¼) = 7 / 3.75; offsets where nothing is cost nothing; the gradient
    reaches the offsets (finite differences), never the density."""
    v = torch.zeros(1, 4, 2, 2, 2, dtype=torch.float64)
    ℓ = torch.zeros(1, 3, 2, 2, 2, dtype=torch.float64)
    v[0, 3, 0, 0, 0], v[0, 3, 1, 1, 1] = 1.0, 0.25
    ℓ[0, :, 0, 0, 0] = torch.tensor([1.0, 2.0, 3.0], dtype=torch.float64)
    ℓ[0, :, 1, 1, 1] = torch.tensor([-4.0, 0.0, 0.0], dtype=torch.float64)
    ℓ[0, :, 0, 1, 0] = 9.0                                      # an empty voxel's offset
    assert float(colour_offset(v, ℓ)) == pytest.approx(7 / 3.75, rel=1e-12)
    assert float(colour_offset(torch.zeros_like(v), ℓ)) == 0.0
    torch.manual_seed(2)
    v = torch.rand(2, 4, 3, 3, 3, dtype=torch.float64, requires_grad=True)
    ℓ = torch.randn(2, 3, 3, 3, 3, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda o: colour_offset(v, o), (ℓ,))
    colour_offset(v, ℓ).backward()
    assert v.grad is None or not v.grad.any()
    with pytest.raises(ValueError, match=r"colour_offset: expected an EA volume .* and \(2, 4, 3, 3, 3\)"):
        colour_offset(v, v)


def test_the_config_refuses_colour_offset_without_a_photo_colour():
    with pytest.raises(ConfigError, match="train.colour_offset: .*needs model.photo_colour: true"):
        load_config(None, ["train.colour_offset=0.1"])
    with pytest.raises(ConfigError, match=r"train.colour_offset: expected a non-negative value, got -1"):
        load_config(None, ["train.colour_offset=-1", "model.photo_colour=true"])


@pytest.mark.usefixtures("tiny_class")
def test_the_trainer_hands_g_the_offsets_of_the_volume_it_made(tmp_path, monkeypatch):
    """With weight w and model.photo_colour, G's 'colour_offset' term is w · L_off of the volume and
    offsets G returned in the step (recorded here), and those offsets are logit c − logit m: the
    colour G made, less the photo's mean colour it offset from."""
    from mitsuba_platonic.networks import nets
    trainer = _tiny_trainer(tmp_path, "train.task=reconstruction", "model.photo_colour=true", "train.colour_offset=0.5")
    seen = {}
    original = nets.Generator.forward

    def spy(self, z, colour=None, offsets=False):
        out = original(self, z, colour, offsets)
        seen.update({"v": out[0].detach().clone(), "offsets": out[1].detach().clone(), "m": colour.detach().clone()})
        return out

    monkeypatch.setattr(nets.Generator, "forward", spy)
    terms = _g_terms(trainer)
    v, ℓ, m = seen["v"], seen["offsets"], seen["m"]
    made = torch.logit(v[:, :3].double()) - torch.logit(m.double().clamp(1 / 255, 254 / 255))[:, :, None, None, None]
    assert torch.allclose(made, ℓ.double(), atol=1e-3)
    w = v[:, 3:]
    expected = 0.5 * (w * ℓ.abs()).sum() / (3 * w.sum())
    assert float(terms["colour_offset"].detach()) == pytest.approx(float(expected), rel=1e-5)


def _rays(opacities):
    """EA volumes (1, 4, N, 1, R) in a camera's frame: ray r's opacities along depth ``opacities[r]``."""
    a = torch.as_tensor(opacities, dtype=torch.float64).T            # (N, R)
    v = torch.full((1, 4, a.shape[0], 1, a.shape[1]), 0.5, dtype=torch.float64)
    v[0, 3, :, 0, :] = a
    return v


def test_depth_spread_of_rays_worked_by_hand():
    """N = 4, s_k = (k + ½)/4. An empty ray: 0. One opaque voxel: w = 1 there, L = 1/(3N) = 1/12.
    a = ½ at the front and 1 at the back: w = (½, 0, 0, ½), L = 2 · ½ · ½ · (7/8 − 1/8) + (¼ + ¼)/12
    = 3/8 + 1/24 = 5/12. The mean over the three rays: (0 + 1/12 + 5/12) / 3 = 1/6."""
    assert float(depth_spread(_rays([[0, 0, 0, 0]]))) == 0.0
    assert float(depth_spread(_rays([[0, 0, 1, 0]]))) == pytest.approx(1 / 12, rel=1e-12)
    assert float(depth_spread(_rays([[0.5, 0, 0, 1]]))) == pytest.approx(5 / 12, rel=1e-12)
    assert float(depth_spread(_rays([[0, 0, 0, 0], [0, 0, 1, 0], [0.5, 0, 0, 1]]))) == pytest.approx(1 / 6, rel=1e-12)


def test_depth_spread_matches_the_pairwise_sum_on_random_rays_with_exact_zeros_and_ones():
    """The O(N) form against the distortion written out pair by pair, on rays holding exact 0s and
    1s (a voxel of 1 stops the ray: nothing behind it has weight); colour does not enter."""
    torch.manual_seed(4)
    n = 7
    a = torch.rand(12, n, dtype=torch.float64)
    a[a < 0.2] = 0.0
    a[a > 0.9] = 1.0
    v = _rays(a)
    expected = 0.0
    for ray in a:
        w, T = [], 1.0
        for k in range(n):
            w.append(T * float(ray[k]))
            T *= 1.0 - float(ray[k])
        s = [(k + 0.5) / n for k in range(n)]
        expected += sum(w[k] * w[l] * abs(s[k] - s[l]) for k in range(n) for l in range(n)) \
            + sum(x * x for x in w) / (3 * n)
    assert float(depth_spread(v)) == pytest.approx(expected / len(a), rel=1e-12)
    v[:, :3] = torch.rand_like(v[:, :3])
    assert float(depth_spread(v)) == pytest.approx(expected / len(a), rel=1e-12)


def test_a_thin_surface_spreads_less_than_a_haze_of_the_same_opacity_and_gradients_match():
    """A ray stopped by one voxel of opacity 0.99 against eight voxels of 1 − 0.01^(1/8) each (the
    same α): the haze costs more; the gradient in the opacities matches finite differences."""
    haze = 1 - 0.01 ** (1 / 8)
    assert float(depth_spread(_rays([[0.99] + [0] * 7]))) < float(depth_spread(_rays([[haze] * 8]))) / 4
    torch.manual_seed(5)
    v = torch.rand(2, 4, 5, 3, 3, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(depth_spread, (v,))


def test_the_config_refuses_depth_spread_without_an_input_view_of_ea_rays():
    with pytest.raises(ConfigError, match="train.depth_spread: .*got 'generation', 'image', 'ea' and 'orthographic'"):
        load_config(None, ["train.depth_spread=1", "train.task=generation"])
    with pytest.raises(ConfigError, match="train.depth_spread: .*got 'reconstruction', 'image', 'ea' and 'perspective'"):
        load_config(None, ["train.depth_spread=1", "render.camera=perspective"])
    with pytest.raises(ConfigError, match=r"train.depth_spread: expected a non-negative value, got -1"):
        load_config(None, ["train.depth_spread=-1"])


@pytest.mark.usefixtures("tiny_class")
def test_the_trainer_hands_g_the_depth_spread_of_the_input_view(tmp_path, monkeypatch):
    """With weight w, G's 'depth_spread' term is w · L_ds of the volume G made (at the front view the
    input camera's frame is the volume's own); without it, no such term."""
    from mitsuba_platonic.networks import nets
    original = nets.Generator.forward
    seen = {}

    def spy(self, *args, **kwargs):
        out = original(self, *args, **kwargs)
        seen["v"] = out.detach().clone()
        return out

    monkeypatch.setattr(nets.Generator, "forward", spy)
    for weight in (0.0, 3.0):
        terms = _g_terms(_tiny_trainer(tmp_path, "train.task=reconstruction", f"train.depth_spread={weight}"))
        if not weight:
            assert "depth_spread" not in terms
            continue
        assert float(terms["depth_spread"].detach()) == pytest.approx(3.0 * float(depth_spread(seen["v"])), rel=1e-5)
        assert float(terms["depth_spread"].detach()) > 0.0
