"""train.pose: elevation: G builds the object upright, a pose head reads the input camera's
elevation from E's code, and the input view renders the volume tilted by it (train/trainer.py).

The tilt against the closed form's rotation and an analytic blob, its gradient in the angle
against finite differences, the head's range and start, what a training step renders and
which weights the pose term trains, the model read back from a run, and the config's checks."""

import math

import numpy as np
import pytest
import torch

from mitsuba_platonic.config import ConfigError, load_config
from mitsuba_platonic.errors import UserError
from mitsuba_platonic.export import export_held_out
from mitsuba_platonic.model import Model
from mitsuba_platonic.networks.nets import PoseHead, init_he, init_weights
from mitsuba_platonic.render.pytorch.closed_form import rotate, tilt
from mitsuba_platonic.train import run as R
from mitsuba_platonic.train.data import load_training_data
from mitsuba_platonic.train.trainer import Trainer
from mitsuba_platonic.views import from_angles, front_view

from tiny_shapes import TINY

ANGLES = [0.0, 1e-7, 30.0, -30.0, 64.0, 90.0, -90.0]


def test_tilt_is_the_rotation_into_the_frame_of_a_camera_at_that_elevation():
    """tilt(v, θ) = rotate(v, ω(0, θ)), the poles included (rotate's pole frame has right = +x)."""
    v = torch.rand(len(ANGLES), 4, 16, 16, 16, generator=torch.Generator().manual_seed(0))
    θ = torch.deg2rad(torch.tensor(ANGLES))
    expected = rotate(v, from_angles(torch.zeros(len(ANGLES)), torch.tensor(ANGLES)))
    assert torch.allclose(tilt(v, θ), expected, atol=1e-5)
    assert torch.equal(tilt(v[:1], torch.zeros(1)), v[:1])   # the front view: voxel centres on themselves


@pytest.mark.parametrize("elevation", [35.0, -50.0, 90.0])
def test_tilt_brings_an_upright_objects_top_towards_a_camera_above_it(elevation):
    """A blob at height 0.5 on the up axis, seen from elevation θ, sits at (0, 0.5 cos θ, 0.5 sin θ)
    of the camera's frame (y up the image, z towards the camera): its density-weighted centre,
    to a tenth of a voxel."""
    n = 32
    c = -1.0 + (torch.arange(n, dtype=torch.float64) + 0.5) * (2.0 / n)
    z, y, x = -c[:, None, None], -c[None, :, None], c[None, None, :]          # a volume's [k, i, j]
    blob = torch.exp(-(x ** 2 + (y - 0.5) ** 2 + z ** 2) / (2 * 0.12 ** 2))[None, None]
    θ = math.radians(elevation)
    out = tilt(blob, torch.tensor([θ], dtype=torch.float64))[0, 0]
    mass = out.sum()
    centre = [float((out * axis).sum() / mass) for axis in (x.expand_as(out), y.expand_as(out), z.expand_as(out))]
    expected = [0.0, 0.5 * math.cos(θ), 0.5 * math.sin(θ)]
    assert max(abs(a - b) for a, b in zip(centre, expected)) < 0.1 * (2.0 / n), (centre, expected)


def test_tilt_is_differentiable_in_the_elevation():
    """∂/∂θ of a smooth function of the tilted volume against central differences (float64)."""
    v = torch.rand(3, 2, 12, 12, 12, dtype=torch.float64, generator=torch.Generator().manual_seed(1))
    weights = torch.rand_like(v)
    θ = torch.tensor([0.31, -0.7, 1.2], dtype=torch.float64, requires_grad=True)
    (tilt(v, θ) * weights).sum().backward()
    h = 1e-6
    for b in range(3):
        e = torch.zeros(3, dtype=torch.float64)
        e[b] = h
        fd = ((tilt(v, θ.detach() + e) * weights).sum() - (tilt(v, θ.detach() - e) * weights).sum()) / (2 * h)
        assert abs(float(θ.grad[b]) - float(fd)) < 1e-5 * max(1.0, abs(float(fd))), (b, float(θ.grad[b]), float(fd))
    assert torch.autograd.gradcheck(lambda vol: tilt(vol, θ.detach()[:1]), (v[:1, :1, :6, :6, :6].clone().requires_grad_(),))


def test_tilt_checks_one_angle_per_volume():
    with pytest.raises(ValueError, match="one angle per volume"):
        tilt(torch.zeros(2, 1, 4, 4, 4), torch.zeros(3))


def test_the_pose_head_starts_at_zero_keeps_within_90_degrees_and_no_initialisation_redraws_it():
    head = PoseHead(8)
    z = torch.randn(5, 8)
    assert torch.equal(head(z), torch.zeros(5))
    for init in (init_weights, init_he):
        head.apply(init) if init is init_weights else init(head)
        assert torch.equal(head(z), torch.zeros(5))
    with torch.no_grad():
        head.weight.fill_(100.0)
    θ = head(torch.stack([torch.full((8,), 1.0), torch.full((8,), -1.0)]))
    assert (θ.abs() <= math.pi / 2).all() and θ[0] > 1.5 and θ[1] < -1.5
    with pytest.raises(ValueError, match=r"codes \(B, 8\)"):
        head(torch.zeros(2, 7))


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("data")


def _cfg(cache, *extra):
    return load_config(None, [
        "run.name=r", f"data.cache={cache}", f"data.shape_class={TINY}", "data.n_shapes=4",
        "data.views_per_shape=2", "model.resolution=16", "model.width=4", "model.latent=8",
        "train.batch_size=2", "train.random_views=2", "train.d_gate=null", "render.backend=closed_form",
        "train.pose=elevation", "train.pose_weight=2.0", *extra])


@pytest.mark.usefixtures("tiny_class")
def test_a_step_renders_the_input_view_tilted_and_the_random_views_upright(cache, monkeypatch):
    """The input view renders tilt(G(z), P(z)) from ω₀; the random views render G(z) itself. The
    'pose' term is λ_pose · mean (P(E(I_view)) − asin ω_y)² over those renders, and it trains E
    and P, not G (the renders are detached)."""
    trainer = Trainer(_cfg(cache), load_training_data(_cfg(cache), progress=False), torch.device("cpu"))
    with torch.no_grad():                                    # a head that answers something other than 0
        trainer.nets["P"].weight.normal_(0.0, 1.0, generator=torch.Generator().manual_seed(3))
    rendered = []
    render = trainer.render
    trainer.render = lambda v, w, seed: rendered.append((v.detach().clone(), w, render(v, w, seed))) or rendered[-1][2]
    E, G, P = trainer.nets["E"], trainer.nets["G"], trainer.nets["P"]
    checked = {}
    original = trainer._g_objective

    def probe(terms):
        assert set(terms) == {"adv2d", "rec", "pose"}
        (v_view, views, i_view), (v_front, front, _) = rendered
        assert torch.equal(front, front_view(2))
        x = trainer.images[torch.randint(len(trainer.images), (2,), generator=trainer.generator(0))]
        with torch.no_grad():
            z = E(x)
            v = G(z)
            assert torch.allclose(v_view, v.repeat_interleave(2, 0), atol=1e-6)       # upright: as G built it
            assert torch.allclose(v_front, tilt(v, P(z)), atol=1e-6)                  # the input view: tilted by θ̂
            assert not torch.allclose(v_front, v, atol=1e-3)
            θ = torch.asin(views[:, 1].double().clamp(-1, 1)).float()
            expected = 2.0 * ((P(E(i_view)) - θ) ** 2).mean()
        assert torch.allclose(terms["pose"], expected, rtol=1e-5)
        for name, net in (("E", E), ("P", P), ("G", G)):
            grads = torch.autograd.grad(terms["pose"], list(net.parameters()), retain_graph=True, allow_unused=True)
            checked[name] = sum(float(g.norm()) for g in grads if g is not None)
        return original(terms)

    monkeypatch.setattr(trainer, "_g_objective", probe)
    out = trainer.step(0)
    assert checked["E"] > 0 and checked["P"] > 0 and checked["G"] == 0.0
    assert out["loss_pose"] > 0


@pytest.mark.usefixtures("tiny_class")
def test_without_the_pose_term_the_head_still_learns_from_the_input_view(cache):
    """pose_weight 0: G's objective has no 'pose' term, yet the input view's gradient reaches P."""
    trainer = Trainer(_cfg(cache, "train.pose_weight=0"), load_training_data(_cfg(cache), progress=False),
                      torch.device("cpu"))
    terms = []
    original = trainer._g_objective
    trainer._g_objective = lambda t: terms.append(set(t)) or original(t)
    before = [p.detach().clone() for p in trainer.nets["P"].parameters()]
    out = trainer.step(0)
    assert terms == [{"adv2d", "rec"}] and "loss_pose" not in out
    assert any(not torch.equal(a, b) for a, b in zip(before, trainer.nets["P"].parameters()))


@pytest.mark.usefixtures("tiny_class")
def test_a_model_read_from_a_run_reconstructs_in_the_input_frame_and_estimates_the_elevation(tmp_path):
    """Model.reconstruct = tilt(G(z), P(z)) clamped to [0, 1] with the run's trained P (not the
    zero a fresh head gives), and estimate_elevation is P(z) in degrees; reconstruct_upright is
    (G(z), P(z) in degrees), the object in its own frame, which export_held_out writes. A view-space
    model estimates nothing, and its upright reconstruction is its reconstruction, seen from
    elevation 0."""
    cfg = load_config(None, [
        f"run.out_dir={tmp_path}/runs", "run.name=r", "run.steps=3", "run.sample_every=1000",
        "run.checkpoint_every=1000", f"data.cache={tmp_path}/data", f"data.shape_class={TINY}", "data.n_shapes=3",
        "data.views_per_shape=2", "model.resolution=16", "model.width=4", "model.latent=8", "train.batch_size=2",
        "train.pose=elevation", "train.pose_weight=1.0"])
    run_dir = R.train(cfg, progress=False)
    model = Model.from_checkpoint(run_dir)
    assert model.P is not None and float(model.P.weight.detach().abs().sum()) > 0
    x = load_training_data(cfg, progress=False).images[:3]
    with torch.no_grad():
        z = model.E(x)
        expected = tilt(model.G(z), model.P(z)).clamp(0.0, 1.0)
        θ = torch.rad2deg(model.P(z))
    assert torch.equal(model.reconstruct(x), expected)
    assert torch.allclose(model.estimate_elevation(x), θ) and θ.abs().max() > 0
    upright, elevation = model.reconstruct_upright(x)
    with torch.no_grad():
        assert torch.equal(upright, model.G(z)) and torch.allclose(elevation, θ)
    export_held_out(model, x[:1], tmp_path / "held", n=1)
    saved = torch.from_numpy(np.load(tmp_path / "held" / "heldout_0.npz")["volume"])
    assert torch.allclose(saved, upright[0], atol=1e-6) and not torch.allclose(saved, expected[0], atol=1e-3)
    plain = Model.from_config(load_config(None, ["model.resolution=16", "model.width=4", "model.latent=8"]))
    assert plain.P is None
    with pytest.raises(UserError, match="estimates no elevation"):
        plain.estimate_elevation(torch.zeros(1, 4, 16, 16))
    upright, elevation = plain.reconstruct_upright(x)
    assert torch.equal(upright, plain.reconstruct(x)) and torch.equal(elevation, torch.zeros(3))


@pytest.mark.parametrize("overrides, match", [
    (["train.pose=elevation", "train.task=generation"], "'reconstruction'"),
    (["train.pose=elevation", "train.mode=platonic3d"], "mode 'platonic'"),
    (["train.pose=elevation", "train.d_roll=uniform"], "train.d_roll"),
    (["train.pose_weight=1.0"], "train.pose_weight: .*expected 0"),
    (["train.pose=elevation", "train.pose_weight=-1"], "train.pose_weight: expected a non-negative"),
    (["train.pose=object"], "train.pose: expected one of"),
])
def test_config_rejects_a_pose_it_cannot_train(overrides, match):
    with pytest.raises(ConfigError, match=match):
        load_config(None, overrides)
