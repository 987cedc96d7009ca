"""The named terms of G's objective (train/terms.py), one unit at a time: the registry names what
exists, each term is active only where the config sets it, and each one's value on a tiny input is
its weight times the formula computed here independently (explicit loops over voxels, rays, pixels
and pairs, not the library's vectorised losses)."""

import dataclasses
import itertools
import math
from types import SimpleNamespace

import numpy as np
import pytest
import torch
from torch import nn

from mitsuba_platonic.config.train_settings import MODES, TASKS, TrainConfig
from mitsuba_platonic.render.pytorch.single_scatter import SKY_SHARE, sample_lights
from mitsuba_platonic.train.step_state import StepState, side_seed
from mitsuba_platonic.train.terms import G_TERMS, active_terms, g_terms
from mitsuba_platonic.views import sample_views, to_angles

PRIORS = {"colour_tv": "colour_tv", "colour_offset": "colour_offset", "depth_spread": "depth_spread",
          "turn": "turn", "solidity": "solidity", "colour_match": "colour_match", "pose": "pose_weight"}


def _train(**kw) -> TrainConfig:
    return dataclasses.replace(TrainConfig(), **kw)         # a section as a config holds it, unvalidated


def _names(**kw):
    return [t.name for t in active_terms(_train(**kw))]


def _ctx(train, modules=None, seed=5, rank=0, volume_rec=None):
    cfg = SimpleNamespace(train=train, run=SimpleNamespace(seed=seed))
    return SimpleNamespace(cfg=cfg, modules=modules or {}, device=torch.device("cpu"), rank=rank,
                           global_mean=lambda loss: float(loss.detach()), volume_rec=volume_rec)


def _value(name, train, s, **ctx):
    """The weighted value of term ``name`` as the config ``train`` has it."""
    (term,) = [t for t in active_terms(train) if t.name == name]
    return term(_ctx(train, **ctx), s)


def _rand(*shape, seed=0):
    return torch.rand(*shape, generator=torch.Generator().manual_seed(seed), dtype=torch.float64)


# -- the registry ---------------------------------------------------------------------------

def test_the_registry_names_config_keys_and_step_fields_that_exist():
    keys = {f.name for f in dataclasses.fields(TrainConfig)}
    fields = {f.name for f in dataclasses.fields(StepState)}
    for term in G_TERMS:
        assert term.weight is None or term.weight in keys, term
        assert set(term.reads) <= fields, term
    assert [t.name for t in G_TERMS] == ["adv2d", "adv3d", "adv3d", "colour_tv", "colour_offset", "depth_spread",
                                         "turn", "solidity", "colour_match", "rec3d", "rec", "pose", "light"]


@pytest.mark.parametrize("mode,task,target", list(itertools.product(MODES, TASKS, ("image", "volume"))))
def test_every_mode_has_one_term_per_name_and_an_adversarial_one(mode, task, target):
    names = _names(mode=mode, task=task, rec_target=target, colour_tv=1.0, colour_offset=1.0, depth_spread=1.0,
                   turn=1.0, solidity=1.0, colour_match=1.0, pose_weight=1.0, light="head")
    assert len(set(names)) == len(names)
    assert {"adv2d", "adv3d"} & set(names)


def test_the_terms_come_in_the_registrys_order():
    names = _names(colour_tv=1.0, colour_offset=1.0, depth_spread=1.0, turn=1.0, solidity=1.0, colour_match=1.0,
                   pose_weight=1.0, light="head")
    assert names == ["adv2d", "colour_tv", "colour_offset", "depth_spread", "turn", "solidity", "colour_match",
                     "rec", "pose", "light"]


def test_two_active_terms_of_one_name_are_refused(monkeypatch):
    from mitsuba_platonic.train import terms
    monkeypatch.setattr(terms, "G_TERMS", terms.G_TERMS + (terms.G_TERMS[0],))
    with pytest.raises(ValueError, match="two active terms share a name"):
        terms.active_terms(_train())


# -- when each is active ---------------------------------------------------------------------

@pytest.mark.parametrize("name,key", list(PRIORS.items()))
def test_a_prior_is_active_only_where_its_weight_is_set_and_images_are_rendered(name, key):
    assert name not in _names(**{key: 0.0})
    assert name in _names(**{key: 0.5})
    assert name in _names(**{key: 0.5, "mode": "prgan"})
    assert name not in _names(**{key: 0.5, "mode": "gan3d"})      # the 3D-GAN: volumes alone, no priors


def test_the_adversarial_terms_follow_the_mode():
    assert _names() == ["adv2d", "rec"]
    assert _names(mode="prgan") == ["adv2d", "rec"]
    assert _names(mode="platonic3d") == ["adv2d", "adv3d", "rec"]
    assert _names(mode="platonic3d", rec_target="volume") == ["adv2d", "adv3d", "rec3d"]
    assert _names(mode="gan3d", rec_target="volume") == ["adv3d", "rec3d"]
    assert _names(mode="gan3d", task="generation") == ["adv3d"]
    assert _names(task="generation") == ["adv2d"]


def test_the_reconstruction_term_is_there_for_reconstruction_whatever_its_weight():
    assert "rec" in _names(rec_weight=0.0)                    # λ_rec 0 still logs loss_rec
    assert "rec" not in _names(task="generation")
    assert "rec3d" in _names(mode="platonic3d", rec_target="volume", rec_weight=0.0)


def test_the_light_term_is_active_with_the_light_head_alone():
    assert "light" not in _names()
    assert "light" in _names(light="head")


# -- each term's value -----------------------------------------------------------------------

class _Linear(nn.Module):
    """A fixed map of flattened inputs, for the critics and heads."""

    def __init__(self, n_in, n_out, seed):
        super().__init__()
        self.weight = nn.Parameter(torch.randn(n_out, n_in, generator=torch.Generator().manual_seed(seed),
                                               dtype=torch.float64))

    def forward(self, x):
        return x.flatten(1) @ self.weight.T


class _Head(_Linear):
    """One number per row, as the pose head answers: ``(B,)``."""

    def forward(self, x):
        return super().forward(x)[:, 0]


@pytest.mark.parametrize("loss", ["nonsaturating", "wgan-gp"])
def test_adv2d_is_the_generators_loss_on_ds_logits_of_the_views_as_d_sees_them(loss):
    fake_d = _rand(3, 4, 2, 2)
    D = _Linear(16, 1, seed=1)
    w = D.weight.detach()
    l = [sum(float(w[0, j]) * float(fake_d[i].flatten()[j]) for j in range(16)) for i in range(3)]
    expected = (sum(-math.log(1 / (1 + math.exp(-li))) for li in l) / 3 if loss == "nonsaturating"
                else -sum(l) / 3)
    value = _value("adv2d", _train(loss=loss), StepState(0, None, fake_d=fake_d), modules={"D": D})
    assert float(value.detach()) == pytest.approx(expected, rel=1e-12)


def test_adv3d_is_d3s_verdict_weighted_in_platonic3d_and_unweighted_in_gan3d():
    verdict = torch.tensor(0.7, dtype=torch.float64)
    s = StepState(0, None, d3_verdict=verdict)
    assert float(_value("adv3d", _train(mode="platonic3d", weight_3d=3.0), s)) == pytest.approx(2.1, rel=1e-15)
    assert float(_value("adv3d", _train(mode="gan3d", weight_3d=3.0, rec_target="volume"), s)) == 0.7


def test_colour_tv_is_the_density_weighted_colour_step_over_neighbour_pairs():
    v = _rand(1, 4, 2, 3, 2, seed=2)
    num = den = 0.0
    for p in itertools.product(range(2), range(3), range(2)):
        for axis in range(3):
            q = list(p)
            q[axis] += 1
            if q[axis] >= v.shape[2 + axis]:
                continue
            w = min(float(v[0, 3][p]), float(v[0, 3][tuple(q)]))
            num += w * sum(abs(float(v[0, c][p]) - float(v[0, c][tuple(q)])) for c in range(3))
            den += w
    value = _value("colour_tv", _train(colour_tv=0.3), StepState(0, None, v=v))
    assert float(value) == pytest.approx(0.3 * num / (3 * den), rel=1e-12)


def test_colour_offset_is_the_density_weighted_mean_offset():
    v, ℓ = _rand(2, 4, 2, 2, 2, seed=3), _rand(2, 3, 2, 2, 2, seed=4) - 0.5
    ρ, a = v[:, 3].numpy(), np.abs(ℓ.numpy())
    expected = sum(ρ[b][p] * a[b, c][p] for b in range(2) for c in range(3) for p in np.ndindex(2, 2, 2)) / \
        (3 * ρ.sum())
    value = _value("colour_offset", _train(colour_offset=0.2), StepState(0, None, v=v, offsets=ℓ))
    assert float(value) == pytest.approx(0.2 * expected, rel=1e-12)


def test_depth_spread_is_each_rays_weight_distortion_pair_by_pair():
    v = _rand(1, 4, 3, 2, 2, seed=5)
    n, total = 3, 0.0
    for h, w in itertools.product(range(2), range(2)):
        a = [float(v[0, 3, k, h, w]) for k in range(n)]
        weights = [a[k] * math.prod(1 - a[j] for j in range(k)) for k in range(n)]
        s = [(k + 0.5) / n for k in range(n)]
        total += sum(weights[k] * weights[l] * abs(s[k] - s[l]) for k in range(n) for l in range(n)) + \
            sum(x * x for x in weights) / (3 * n)
    value = _value("depth_spread", _train(depth_spread=0.15), StepState(0, None, v_input=v))
    assert float(value) == pytest.approx(0.15 * total / 4, rel=1e-12)


def _turned_by_hand(a: np.ndarray, φ: float) -> np.ndarray:
    """α ``(D, H, W)`` turned by φ about the vertical (the value at p is α's at p' with
    x' = cos φ x − sin φ z, z' = sin φ x + cos φ z in [−1, 1] voxel-centre coordinates), trilinear
    with zeros outside."""
    D, H, W = a.shape

    def at(i, j, k):
        return a[i, j, k] if 0 <= i < D and 0 <= j < H and 0 <= k < W else 0.0

    out = np.zeros_like(a)
    for d, h, w in np.ndindex(D, H, W):
        x, z = (2 * w + 1) / W - 1, (2 * d + 1) / D - 1
        xs, zs = math.cos(φ) * x - math.sin(φ) * z, math.sin(φ) * x + math.cos(φ) * z
        fw, fd = ((xs + 1) * W - 1) / 2, ((zs + 1) * D - 1) / 2
        w0, d0 = math.floor(fw), math.floor(fd)
        tw, td = fw - w0, fd - d0
        out[d, h, w] = sum(at(d0 + i, h, w0 + j) * (td if i else 1 - td) * (tw if j else 1 - tw)
                           for i in (0, 1) for j in (0, 1))
    return out


def test_turn_compares_the_opacity_with_itself_turned_by_the_steps_angle_per_volume():
    v = _rand(2, 4, 4, 3, 4, seed=6)
    seed, step, rank = 5, 9, 0
    g = torch.Generator().manual_seed(side_seed(seed, step, 17, rank))      # the turn stream: tag 17
    φ = (2 * math.pi * torch.rand(2, generator=g, dtype=torch.float64)).tolist()
    a = v[:, 3].numpy()
    t = [_turned_by_hand(a[b], φ[b]) for b in range(2)]
    expected = sum(np.abs(a[b] - t[b]).sum() for b in range(2)) / sum((a[b] + t[b]).sum() for b in range(2))
    train = _train(turn=2.0, pose="elevation")
    value = _value("turn", train, StepState(step, None, v=v), seed=seed, rank=rank)
    assert float(value) == pytest.approx(2.0 * expected, rel=1e-9)
    assert float(_value("turn", train, StepState(step + 1, None, v=v), seed=seed)) != float(value)   # a new angle each step


def test_solidity_is_the_opacity_missing_under_each_rays_hull_of_surfaces():
    v = _rand(1, 4, 5, 2, 2, seed=7)
    v[0, 3, :, 0, 0] = torch.tensor([0.9, 0.2, 0.1, 0.8, 0.3], dtype=torch.float64)    # a gap between two shells
    missing = hull_sum = 0.0
    for h, w in itertools.product(range(2), range(2)):
        a = [float(v[0, 3, k, h, w]) for k in range(5)]
        m = [x if x >= 0.5 else 0.0 for x in a]
        for k in range(5):
            hull = min(max(m[:k + 1]), max(m[k:]))
            missing += max(hull - a[k], 0.0)
            hull_sum += hull
    value = _value("solidity", _train(solidity=1.5), StepState(0, None, v_input=v))
    assert missing > 0 and float(value) == pytest.approx(1.5 * missing / hull_sum, rel=1e-12)


def test_colour_match_holds_each_views_mean_colour_to_its_photos():
    K = 2
    x, i_view = _rand(2, 4, 3, 3, seed=8), _rand(2 * K, 4, 3, 3, seed=9)

    def mean_colour(img):
        return [float(img[c].sum()) / float(img[3].sum()) for c in range(3)]

    expected = sum(abs(mean_colour(i_view[i])[c] - mean_colour(x[i // K])[c]) for i in range(2 * K) for c in range(3))
    value = _value("colour_match", _train(colour_match=1.0, random_views=K), StepState(0, None, i_view=i_view, x=x))
    assert float(value) == pytest.approx(expected / (2 * K * 3), rel=1e-12)


@pytest.mark.parametrize("rec_loss,channels", [("l2", "all"), ("l1", "all"), ("l2", "alpha"), ("l1", "alpha")])
def test_rec_compares_the_input_view_with_the_photo(rec_loss, channels):
    i_front, x = _rand(2, 4, 3, 3, seed=10), _rand(2, 4, 3, 3, seed=11)
    cs = range(4) if channels == "all" else [3]
    d = [float(i_front[b, c, i, j] - x[b, c, i, j]) for b in range(2) for c in cs for i in range(3) for j in range(3)]
    mean = sum(e * e if rec_loss == "l2" else abs(e) for e in d) / len(d)
    out = {}
    value = _value("rec", _train(rec_weight=4.0, rec_loss=rec_loss, rec_channels=channels),
                   StepState(0, None, i_front=i_front, x=x, out=out))
    assert float(value) == pytest.approx(4.0 * mean, rel=1e-12)
    assert out == {"loss_rec": pytest.approx(mean, rel=1e-12)}


def test_rec3d_weights_the_trainers_volume_comparison_of_the_input_volume_and_batch():
    v_input, idx, seen = _rand(2, 4, 2, 2, 2), torch.tensor([3, 1]), {}

    def volume_rec(v, rows, out):
        seen.update(v=v, rows=rows, out=out)
        return torch.tensor(0.25, dtype=torch.float64)

    s = StepState(0, None, v_input=v_input, idx=idx)
    value = _value("rec3d", _train(mode="gan3d", rec_target="volume", rec_weight=3.0), s, volume_rec=volume_rec)
    assert float(value) == 0.75 and seen["v"] is v_input and seen["rows"] is idx and seen["out"] is s.out


def test_pose_teaches_the_head_the_elevations_of_gs_renders_and_not_g():
    views = sample_views(3, "band", seed=2, elevation=(-30.0, 60.0))
    i_view = _rand(3, 4, 2, 2, seed=12).requires_grad_(True)
    E, P = _Linear(16, 5, seed=3), _Head(5, 1, seed=4)
    E_out = [[sum(float(E.weight.detach()[o, j]) * float(i_view.detach()[i].flatten()[j]) for j in range(16)) for o in range(5)]
             for i in range(3)]
    θ_hat = [sum(float(P.weight.detach()[0, o]) * E_out[i][o] for o in range(5)) for i in range(3)]
    θ = [math.asin(float(views[i, 1])) for i in range(3)]
    out = {}
    value = _value("pose", _train(pose="elevation", pose_weight=2.0), StepState(0, None, i_view=i_view, views=views,
                                                                                   out=out), modules={"E": E, "P": P})
    expected = sum((θ_hat[i] - θ[i]) ** 2 for i in range(3)) / 3
    assert float(value.detach()) == pytest.approx(2.0 * expected, rel=1e-9) and out["loss_pose"] == pytest.approx(expected)
    value.backward()
    assert i_view.grad is None and E.weight.grad.abs().sum() > 0 and P.weight.grad.abs().sum() > 0


class _LightHead(nn.Module):
    """Answers a fixed unit direction and share per row, from E's code."""

    def forward(self, code):
        d = torch.nn.functional.normalize(code[:, :3], dim=1)
        return d, torch.sigmoid(code[:, 3])


def test_light_teaches_the_head_the_priors_lights_in_each_views_camera_frame():
    views, seed = sample_views(3, seed=4), 21
    i_view = _rand(3, 4, 2, 2, seed=13).requires_grad_(True)
    E = _Linear(16, 4, seed=5)
    out = {}
    value = _value("light", _train(light="head"), StepState(0, None, i_view=i_view, views=views, seed=seed, out=out),
                   modules={"E": E, "L": _LightHead()})
    with torch.no_grad():
        d_hat, s_hat = _LightHead()(E(i_view))
    prior = sample_lights(3, seed)                           # the renderer's lights for that seed
    lo, hi = SKY_SHARE
    total = 0.0
    for i in range(3):
        φ, θ = (float(a) for a in to_angles(views[i:i + 1], degrees=False))
        right = (math.cos(φ), 0.0, -math.sin(φ))
        up = (-math.sin(θ) * math.sin(φ), math.cos(θ), -math.sin(θ) * math.cos(φ))
        d = prior.direction[i].tolist()
        cam = [sum(a * b for a, b in zip(d, axis)) for axis in (right, up, views[i].tolist())]
        share = float(prior.sky[i, 1]) / 0.5                # L_sky = ½ s for a grey daylight of L̄ = ½
        total += (1 - sum(float(d_hat[i, c]) * cam[c] for c in range(3))) / 3 + \
            ((float(s_hat[i]) - share) / (hi - lo)) ** 2 / 3
    assert float(value.detach()) == pytest.approx(total, rel=1e-6) and out["loss_light"] == pytest.approx(total, rel=1e-6)
    value.backward()
    assert i_view.grad is None and E.weight.grad.abs().sum() > 0


def test_g_terms_hands_every_active_term_its_weighted_value_by_name():
    train = _train(colour_tv=0.5, task="generation")
    v = _rand(1, 4, 2, 2, 2, seed=14)
    s = StepState(0, None, v=v, fake_d=_rand(1, 4, 2, 2))
    ctx = _ctx(train, modules={"D": _Linear(16, 1, seed=6)})
    terms = g_terms(ctx, s, active_terms(train))
    assert list(terms) == ["adv2d", "colour_tv"]
    assert float(terms["colour_tv"]) == pytest.approx(0.5 * float(_value("colour_tv", _train(colour_tv=1.0), s)))
