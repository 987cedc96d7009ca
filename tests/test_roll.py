"""train.d_roll: the images D judges turned in-plane (train/image_roll.py): the turn's direction and
exactness, the tilt it exists for, and what D sees in a training step."""

import math

import pytest
import torch

from mitsuba_platonic.config import ConfigError, load_config
from mitsuba_platonic.render import render
from mitsuba_platonic.render.pytorch.closed_form import rotate
from mitsuba_platonic.train import trainer as trainer_module
from mitsuba_platonic.train.data import load_training_data
from mitsuba_platonic.train.image_roll import input_frame_roll, roll
from mitsuba_platonic.train.trainer import Trainer
from mitsuba_platonic.views import camera_frames, from_angles
from mitsuba_platonic.volume import test_volume

from tiny_shapes import TINY


def test_a_quarter_turn_is_counter_clockwise_and_exact():
    images = torch.rand(2, 4, 8, 8)
    # pixel centres land on pixel centres: the same numbers as numpy-style rot90 (counter-clockwise)
    assert torch.allclose(roll(images, torch.full((2,), math.pi / 2)), torch.rot90(images, 1, dims=(2, 3)),
                          atol=1e-6)
    assert torch.allclose(roll(images, torch.zeros(2)), images, atol=1e-6)


def test_each_image_turns_by_its_own_angle():
    dot = torch.zeros(1, 1, 8, 8)
    dot[..., 3:5, 6] = 1.0                                    # right of the centre
    out = roll(dot.expand(2, -1, -1, -1), torch.tensor([math.pi / 2, -math.pi / 2]))
    top, bottom = out[0, 0, :4].sum(), out[1, 0, 4:].sum()    # a turn up, a turn down
    assert top > 0.99 * out[0].sum() and bottom > 0.99 * out[1].sum()


def test_roll_is_differentiable():
    images = torch.rand(2, 1, 6, 6, dtype=torch.float64, requires_grad=True)
    angles = torch.tensor([0.3, 2.0], dtype=torch.float64)
    assert torch.autograd.gradcheck(lambda x: roll(x, angles), (images,))


def test_roll_rejects_mismatched_angles():
    with pytest.raises(ValueError, match="angles"):
        roll(torch.rand(2, 1, 4, 4), torch.zeros(3))


@pytest.mark.parametrize("elevation", [40.0, -25.0])
def test_views_drawn_in_the_input_frame_are_tilted_by_the_input_elevation(elevation):
    """Why d_roll exists: a volume in the frame of an input camera at elevation θ₀, seen from
    beside it (ω = ±x of that frame), is the world's upright photo from that direction turned by
    ±θ₀; the photo itself is far off."""
    v = test_volume(32, "figure", "ao")
    w_in = from_angles(torch.tensor([30.0]), elevation)
    v_in = rotate(v, w_in).clamp(0.0, 1.0)                    # as the trainer's ground truth in input frames
    right = camera_frames(w_in)[0].float()                   # the world direction of view +x of that frame
    for sign in (1.0, -1.0):
        fake = render(v_in, torch.tensor([[sign, 0.0, 0.0]]), "ao")
        photo = render(v, sign * right, "ao")
        tilted = roll(photo, torch.tensor([sign * math.radians(elevation)]))
        assert (fake - tilted).abs().mean() < 0.1 * (fake - photo).abs().mean()


@pytest.mark.parametrize("elevation", [40.0, -25.0, 70.0])
@pytest.mark.parametrize("azimuth, view_elevation", [(45.0, 20.0), (135.0, -30.0), (60.0, 60.0)])
def test_input_frame_roll_turns_the_photo_into_the_frames_view(elevation, azimuth, view_elevation):
    """'matched': for views ω in the frame of an input camera at elevation θ₀ off its horizontal
    plane (beside it, ω = ±x: the test above), the world's upright photo from the same direction
    turned by ψ(θ₀, ω) is the frame's view (up to resampling), where the unturned photo and the
    photo turned the other way are far off."""
    v = test_volume(32, "figure", "ao")
    w_in = from_angles(torch.tensor([30.0]), elevation)
    v_in = rotate(v, w_in).clamp(0.0, 1.0)
    right, up, forward = (a.float() for a in camera_frames(w_in))
    w = from_angles(torch.tensor([azimuth]), view_elevation)
    world = w[:, :1] * right + w[:, 1:2] * up + w[:, 2:] * forward     # ω in world coordinates
    fake, photo = render(v_in, w, "ao"), render(v, world, "ao")
    ψ = input_frame_roll(w, torch.tensor([elevation]))
    turned = (fake - roll(photo, ψ)).abs().mean()
    assert turned < 0.15 * (fake - photo).abs().mean()
    assert turned < 0.15 * (fake - roll(photo, -ψ)).abs().mean()


def test_input_frame_roll_in_closed_form():
    """ψ = ±θ₀ beside the input (ω = ±x of its frame), 0 in front and behind, atan(0.6 tan θ₀) at
    ω = (0.6, 0, 0.8) (r = (0.8, 0, −0.6), t = +y, u·r = −0.6 sin θ₀, u·t = cos θ₀), −π at the
    frame's pole +y (r = +x, t = −z: upside down), and 0 everywhere for θ₀ = 0."""
    views = torch.tensor([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [0.6, 0.0, 0.8],
                          [0.0, 1.0, 0.0]])
    θ0 = math.radians(35.0)
    ψ = input_frame_roll(views, torch.full((6,), 35.0))
    expected = torch.tensor([θ0, -θ0, 0.0, 0.0, math.atan(0.6 * math.tan(θ0)), -math.pi])
    assert torch.allclose(ψ, expected, atol=1e-6)
    assert torch.allclose(input_frame_roll(views[:5], torch.zeros(5)), torch.zeros(5), atol=1e-7)
    with pytest.raises(ValueError, match="elevations"):
        input_frame_roll(views, torch.zeros(4))
    with pytest.raises(ValueError, match="unit"):
        input_frame_roll(torch.zeros(1, 3) + 0.5, torch.zeros(1))


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("data")


def _trainer(cache, roll_setting, *overrides):
    cfg = load_config(None, [
        "run.name=r", f"data.cache={cache}", f"data.shape_class={TINY}", "data.n_shapes=4",
        "data.views_per_shape=2", "model.resolution=16", "model.width=4", "model.latent=8",
        "train.batch_size=2", "train.random_views=2", "train.d_gate=null", "render.backend=closed_form",
        f"train.d_roll={roll_setting}", *overrides])
    return Trainer(cfg, load_training_data(cfg, progress=False), torch.device("cpu"))


def _as_judged(seen):
    """D's inputs of a step as [reals, fakes, G's adversarial images]: D's update runs its reals and
    fakes through one forward pass (no BatchNorm), the first half of which are the reals."""
    both, *rest = seen
    half = len(both) // 2
    return [both[:half], both[half:], *rest]


@pytest.mark.usefixtures("tiny_class")
@pytest.mark.parametrize("setting", ["none", "uniform"])
def test_d_sees_exactly_the_turned_images(cache, monkeypatch, setting):
    """With 'uniform', every image D judges (its update's reals and fakes, G's adversarial term)
    is an output of roll with angles in [0, 2π), one per image; with 'none', roll never runs."""
    trainer = _trainer(cache, setting)
    turned, seen = [], []

    def recording_roll(images, angles):
        out = roll(images, angles)
        turned.append((out, angles))
        return out

    monkeypatch.setattr(trainer_module, "roll", recording_roll)
    trainer.nets["D"].register_forward_hook(lambda module, args, output: seen.append(args[0]))
    trainer.step(0)
    seen = _as_judged(seen)
    assert len(seen) == 3                                    # D's real, D's fake, G's adversarial term
    if setting == "none":
        assert turned == []
        return
    assert len(turned) == 2                                  # the reals, the fakes
    for _, angles in turned:
        assert angles.shape == (4,) and (angles >= 0).all() and (angles < 2 * math.pi).all()
    assert not torch.equal(turned[0][1], turned[1][1])
    outputs = [out for out, _ in turned]
    for image in seen:
        assert any(torch.equal(image, out) for out in outputs)


@pytest.mark.usefixtures("tiny_class")
def test_matched_turns_the_reals_by_their_slots_views_and_leaves_the_fakes(cache, monkeypatch):
    """'matched': roll runs once per step, on D's reals, with ψ(θ₀, ω) for each slot's random view
    ω and an input elevation θ₀ from the collection's views (here a band of 50–60°, where the
    random views span the sphere); D's fakes and G's adversarial images are the renders themselves."""
    trainer = _trainer(cache, "matched", "data.view_distribution=band", "data.elevation=[50.0, 60.0]")
    turned, seen, views = [], [], []

    def recording_roll(images, angles):
        out = roll(images, angles)
        turned.append((images, out, angles))
        return out

    def recording_frame_roll(w, θ0):
        views.append((w, θ0))
        return input_frame_roll(w, θ0)

    monkeypatch.setattr(trainer_module, "roll", recording_roll)
    monkeypatch.setattr(trainer_module, "input_frame_roll", recording_frame_roll)
    rendered = []
    render = trainer.render
    trainer.render = lambda v, w, seed: rendered.append((w, render(v, w, seed))) or rendered[-1][1]
    trainer.nets["D"].register_forward_hook(lambda module, args, output: seen.append(args[0]))
    trainer.step(0)
    seen = _as_judged(seen)
    assert len(turned) == 1 and len(views) == 1
    (w, θ0), (reals, out, angles) = views[0], turned[0]
    random_views, fakes = rendered[0]
    assert torch.equal(w, random_views)                      # each real's own slot's view
    assert θ0.shape == (4,) and (θ0 >= 50 - 1e-4).all() and (θ0 <= 60 + 1e-4).all() and θ0.std() > 0
    assert torch.allclose(angles, input_frame_roll(w, θ0))
    assert torch.equal(reals[0::2], reals[1::2])            # the batch's photos, repeated per view (K = 2)
    assert all((trainer.images == r).flatten(1).all(1).any() for r in reals)
    assert torch.equal(seen[0], out)                         # D's reals: turned
    assert torch.equal(seen[1], fakes) and torch.equal(seen[2], fakes)  # D's fakes, G's term: as rendered


def test_config_rejects_matched_roll_without_an_input_frame():
    for override in ("train.task=generation", "train.mode=gan3d"):
        with pytest.raises(ConfigError, match="'matched'"):
            load_config(None, ["train.d_roll=matched", override, "train.rec_target=volume"]
                        if override.endswith("gan3d") else ["train.d_roll=matched", override])


def test_config_rejects_unknown_roll():
    with pytest.raises(ConfigError, match="train.d_roll"):
        load_config(None, ["train.d_roll=random"])
