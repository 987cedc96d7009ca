"""train.colour_tv: the density-weighted colour total variation (train/losses.colour_tv) on known
volumes, its gradient (colour only, never density), and the trainer handing it to G; and
train.colour_match (train/losses.colour_match): the mean colour of the object from every side; and
train.colour_offset (train/losses.colour_offset): G's colour held to the photo's; and
train.depth_spread (train/losses.depth_spread): the input view's colour from a thin surface; and
train.turn (train/losses.turn): the object probably round about its vertical; and
train.solidity (train/losses.solidity): no gaps along an input ray between its first and last matter."""

import math

import pytest
import torch

from mitsuba_platonic.config import ConfigError, load_config
from mitsuba_platonic.train.losses import colour_match, colour_offset, colour_tv, depth_spread, mean_colour, solidity, turn, turned


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


def test_a_quarter_turn_matches_a_voxel_loop_with_exact_zeros_and_ones_and_spares_a_vertical_cone():
    """φ = 90° against the sum written out voxel by voxel with the quarter turn about the vertical (h)
    axis, (d, h, w) → (w, h, N − 1 − d), on random volumes holding exact 0s and 1s (voxel centres
    land on voxel centres: no resampling). A vertical cone about the volume's centre scores 0 at
    that turn; a slab as wide as the volume and one voxel deep does not; neither does the cone
    lying along depth."""
    torch.manual_seed(16)
    v = torch.rand(2, 4, 5, 3, 5, dtype=torch.float64)
    a = v[:, 3]
    a[a < 0.2] = 0.0
    a[a > 0.9] = 1.0
    n = a.shape[1]
    diff = total = 0.0
    for b in range(a.shape[0]):
        for d in range(n):
            for h in range(a.shape[2]):
                for w in range(n):
                    x, y = float(a[b, d, h, w]), float(a[b, w, h, n - 1 - d])
                    diff += abs(x - y)
                    total += x + y
    quarter = torch.full((2,), math.pi / 2, dtype=torch.float64)
    assert float(turn(v, quarter)) == pytest.approx(diff / total, rel=1e-9)
    assert float(turn(v, -quarter)) == pytest.approx(diff / total, rel=1e-9)
    cone, slab = _cone(8), torch.zeros(1, 1, 8, 8, 8, dtype=torch.float64)
    slab[0, 0, 4] = 1.0                                          # wide, one voxel deep
    assert float(turn(cone, quarter[:1])) == pytest.approx(0.0, abs=1e-12)
    assert float(turn(slab, quarter[:1])) > 0.8
    assert float(turn(cone.permute(0, 1, 3, 2, 4), quarter[:1])) > 0.1
    with pytest.raises(ValueError, match=r"turn: expected upright volumes \(B, C, N, H, N\), got \(1, 1, 8, 8, 4\)"):
        turn(slab[..., :4], quarter[:1])
    with pytest.raises(ValueError, match=r"turn: expected one angle per volume, shape \(1,\), got \(2,\)"):
        turn(slab, quarter)


def _cone(n: int, points: int = 0) -> torch.Tensor:
    """A vertical cone about the centre of an n³ volume (wider towards the bottom), ``(1, 1, n, n, n)``;
    with ``points`` > 0, a star of that many points instead (its radius swings by half with the angle)."""
    c = torch.arange(n, dtype=torch.float64) - (n - 1) / 2
    r = torch.sqrt(c[:, None] ** 2 + c[None, :] ** 2)            # (d, w) distance from the vertical axis
    θ = torch.atan2(c[:, None], c[None, :])
    radius = torch.linspace(0.3, 0.45, n, dtype=torch.float64)[None, :, None] * n
    if points:
        radius = radius * (0.75 + 0.25 * torch.cos(points * θ))[:, None, :]
    return (r[:, None, :] <= radius).double()[None, None]


def test_a_random_turn_tells_a_round_body_from_a_four_pointed_star():
    """At a quarter turn a four-pointed star scores 0 as a cone does; at an eighth of a turn the star
    scores far more than the cone, whose loss is only the resampling's blur."""
    quarter, eighth = torch.tensor([math.pi / 2], dtype=torch.float64), torch.tensor([math.pi / 4], dtype=torch.float64)
    cone, star = _cone(32), _cone(32, points=4)
    assert float(turn(star, quarter)) == pytest.approx(0.0, abs=1e-12)
    assert float(turn(star, eighth)) > 3.0 * float(turn(cone, eighth))
    assert float(turn(cone, eighth)) < 0.05


def test_turned_goes_the_way_its_docstring_says():
    """A positive quarter turn takes the front's centre line (d = 0, nearest the camera) to the left
    (w = 0), the left to the back, at its height; a negative one to the right."""
    n = 5
    v = torch.zeros(1, 1, n, n, n, dtype=torch.float64)
    v[0, 0, 0, 1, 2] = 1.0
    quarter = torch.tensor([math.pi / 2], dtype=torch.float64)
    def where(x: torch.Tensor) -> list:
        assert float(x.sum()) == pytest.approx(1.0, abs=1e-12)   # all of it moved, up to cos(π/2)'s round-off
        return (x[0, 0] > 0.5).nonzero().tolist()

    assert where(turned(v, quarter)) == [[2, 1, 0]]
    assert where(turned(turned(v, quarter), quarter)) == [[4, 1, 2]]
    assert where(turned(v, -quarter)) == [[2, 1, 4]]


def test_the_turn_gradient_grows_a_shallow_slab_in_depth_and_matches_finite_differences():
    """A slab one voxel deep and as wide as the volume: at a quarter turn the gradient asks for matter
    in front of and behind it on the centre line (negative derivatives there), and less of the slab's
    far ends; at a random angle it matches finite differences."""
    n = 6
    slab = torch.zeros(1, 1, n, n, n, dtype=torch.float64)
    slab[0, 0, n // 2] = 1.0
    slab.requires_grad_(True)
    turn(slab, torch.tensor([math.pi / 2], dtype=torch.float64)).backward()
    assert float(slab.grad[0, 0, 0, 2, n // 2]) < 0.0 and float(slab.grad[0, 0, n - 1, 2, n // 2]) < 0.0
    assert float(slab.grad[0, 0, n // 2, 2, 0]) > 0.0
    torch.manual_seed(17)
    v = (0.05 + 0.9 * torch.rand(2, 4, 4, 3, 4, dtype=torch.float64)).requires_grad_(True)
    assert torch.autograd.gradcheck(lambda x: turn(x, torch.tensor([0.3, 2.1], dtype=torch.float64)), (v,))


def test_the_config_refuses_turn_without_an_upright_volume():
    with pytest.raises(ConfigError, match="train.turn: .*needs train.pose 'elevation', got 'input'"):
        load_config(None, ["train.turn=1", "train.task=reconstruction"])
    with pytest.raises(ConfigError, match=r"train.turn: expected a non-negative value, got -1"):
        load_config(None, ["train.turn=-1"])
    load_config(None, ["train.turn=1", "train.task=reconstruction", "train.pose=elevation", "train.pose_weight=1"])


@pytest.mark.usefixtures("tiny_class")
def test_the_trainer_hands_g_the_turn_of_the_upright_volume_it_made(tmp_path, monkeypatch):
    """With weight w, G's 'turn' term is w · L_turn of the upright volume G made, at one angle per
    volume in [0, 2π) drawn anew each step; without it, none."""
    from mitsuba_platonic.networks import nets
    from mitsuba_platonic.train import terms as T      # where the turn term calls L_turn
    original, original_turn = nets.Generator.forward, T.turn
    seen = {}

    def spy(self, *args, **kwargs):
        out = original(self, *args, **kwargs)
        seen["v"] = out.detach().clone()
        return out

    def turn_spy(volume, φ):
        seen["φ"] = φ.detach().clone()
        return original_turn(volume, φ)

    monkeypatch.setattr(nets.Generator, "forward", spy)
    monkeypatch.setattr(T, "turn", turn_spy)
    for weight in (0.0, 2.0):
        terms = _g_terms(_tiny_trainer(tmp_path, "train.task=reconstruction", "train.pose=elevation",
                                       "train.pose_weight=1", f"train.turn={weight}"))
        if not weight:
            assert "turn" not in terms
            continue
        φ = seen["φ"]
        assert φ.shape == (2,) and bool(((φ >= 0) & (φ < 2 * math.pi)).all()) and float(φ[0]) != float(φ[1])
        assert float(terms["turn"]) == pytest.approx(2.0 * float(turn(seen["v"], φ.to(seen["v"]))), rel=1e-5)
        assert float(terms["turn"]) > 0.0


def test_solidity_of_rays_worked_by_hand():
    """Rays along depth (N = 4). Empty, one shell, a solid body, one peak: 0. A front and a back
    shell with a gap: hull (1, 1, 1, 1), 2 missing of 4, so ½. α = (½, 0, 1, 0) (½ is a surface):
    hull min(cummax front (½, ½, 1, 1), cummax back (1, 1, 1, 0)) = (½, ½, 1, 0), ½ missing of 2,
    so ¼. Pooled over the batch: a full ray beside the gapped one (0 + 2) / (4 + 4) = ¼. A haze
    below ½ has no surfaces: (0.4, 0, 0, 0.4) is not filled, and (0.4, 0, 1, 0) has the hull
    (0, 0, 1, 0): 0."""
    assert float(solidity(_rays([[0, 0, 0, 0]]))) == 0.0
    assert float(solidity(_rays([[1, 1, 0, 0]]))) == 0.0
    assert float(solidity(_rays([[0.2, 0.7, 1, 0.4]]))) == 0.0
    assert float(solidity(_rays([[1, 0, 0, 1]]))) == 0.5
    assert float(solidity(_rays([[0.5, 0, 1, 0]]))) == pytest.approx(0.25, rel=1e-12)
    assert float(solidity(_rays([[1, 1, 1, 1], [1, 0, 0, 1]]))) == pytest.approx(0.25, rel=1e-12)
    assert float(solidity(_rays([[0.4, 0, 0, 0.4]]))) == 0.0
    assert float(solidity(_rays([[0.4, 0, 1, 0]]))) == 0.0


def test_solidity_leaves_a_haze_alone_and_fills_between_surfaces_inside_it():
    """G's first volumes are a haze: every voxel below ½ with gaps. Filling it would make each ray
    an opaque block (32 voxels of 0.3: opacity 1 − 0.7³² ≈ 1), so a haze costs nothing; two
    surfaces of 0.9 in the same haze ask for the gap between them alone."""
    torch.manual_seed(9)
    haze = 0.3 * torch.rand(1, 32, dtype=torch.float64)
    haze[:, ::3] = 0.0
    assert float(solidity(_rays(haze))) == 0.0
    walls = haze.clone()
    walls[0, 5] = walls[0, 20] = 0.9
    v = _rays(walls).requires_grad_(True)
    solidity(v).backward()
    asked = (v.grad[0, 3, :, 0, 0] < 0).nonzero().flatten().tolist()
    assert asked and min(asked) > 5 and max(asked) < 20, asked


def test_solidity_matches_a_per_ray_loop_with_exact_zeros_and_ones_and_fills_only_gaps():
    """Against each ray's hull of surfaces (α ≥ ½) written out with Python's max and min, on random
    volumes holding exact 0s and 1s; the gradient is −1/Σh at a voxel below its hull and 0 elsewhere (the hull
    held constant: walls are never lowered, nothing beyond the outermost matter is asked for)."""
    torch.manual_seed(8)
    v = torch.rand(2, 4, 6, 3, 2, dtype=torch.float64)
    a = v[:, 3]
    a[a < 0.3] = 0.0
    a[a > 0.9] = 1.0
    n = a.shape[1]
    missing = total = 0.0
    below = torch.zeros_like(a, dtype=torch.bool)
    for b in range(a.shape[0]):
        for h in range(a.shape[2]):
            for w in range(a.shape[3]):
                ray = [float(a[b, d, h, w]) for d in range(n)]
                surfaces = [x if x >= 0.5 else 0.0 for x in ray]
                for d in range(n):
                    hull = min(max(surfaces[:d + 1]), max(surfaces[d:]))
                    missing += max(hull - ray[d], 0.0)
                    total += hull
                    below[b, d, h, w] = hull > ray[d]
    v.requires_grad_(True)
    loss = solidity(v)
    assert float(loss.detach()) == pytest.approx(missing / total, rel=1e-12)
    loss.backward()
    g = v.grad[:, 3]
    assert torch.allclose(g[below], torch.full_like(g[below], -1.0 / total))
    assert float(g[~below].abs().max()) == 0.0 and float(v.grad[:, :3].abs().max()) == 0.0


def test_the_config_refuses_solidity_without_the_input_cameras_parallel_rays():
    with pytest.raises(ConfigError, match="train.solidity: .*got 'generation', 'platonic' and 'orthographic'"):
        load_config(None, ["train.solidity=1", "train.task=generation"])
    with pytest.raises(ConfigError, match="train.solidity: .*got 'reconstruction', 'platonic' and 'perspective'"):
        load_config(None, ["train.solidity=1", "render.camera=perspective"])
    with pytest.raises(ConfigError, match=r"train.solidity: expected a non-negative value, got -1"):
        load_config(None, ["train.solidity=-1"])


@pytest.mark.usefixtures("tiny_class")
def test_the_trainer_hands_g_the_solidity_of_the_input_view(tmp_path, monkeypatch):
    """With weight w, G's 'solidity' term is w · L_solid of the volume G made (at the front view the
    input camera's frame is the volume's own); without it, none. G's first volumes are a haze with
    no surfaces, so G's output gets two walls of 0.9 with a gap between them along depth."""
    from mitsuba_platonic.networks import nets
    original = nets.Generator.forward
    seen = {}

    def spy(self, *args, **kwargs):
        out = original(self, *args, **kwargs)
        walls = torch.zeros_like(out)
        walls[:, -1, [1, -2]] = 0.9 - out[:, -1, [1, -2]].detach()   # α = 0.9 there, the graph kept
        out = out + walls
        seen["v"] = out.detach().clone()
        return out

    monkeypatch.setattr(nets.Generator, "forward", spy)
    for weight in (0.0, 2.0):
        terms = _g_terms(_tiny_trainer(tmp_path, "train.task=reconstruction", f"train.solidity={weight}"))
        if not weight:
            assert "solidity" not in terms
            continue
        assert float(terms["solidity"]) == pytest.approx(2.0 * float(solidity(seen["v"])), rel=1e-5)
        assert float(terms["solidity"]) > 0.0                   # the gap between the walls
