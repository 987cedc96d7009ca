"""train.d_augment and train.photo_augment (train/augment.py): D's differentiable augmentations and
the photos' own, on images with known answers, their gradients, and where the trainer applies them."""

import math

import pytest
import torch

from mitsuba_platonic.config import ConfigError, load_config
from mitsuba_platonic.config.train_settings import AUGMENTS, PHOTO_AUGMENTS
from mitsuba_platonic.train import augment as A
from mitsuba_platonic.train.augment import BRIGHTNESS, augment, augment_photos, colour_matrices
from mitsuba_platonic.train.data import load_training_data
from mitsuba_platonic.train.trainer import Trainer
from tiny_shapes import TINY


def _images(b=6, h=16):
    """Distinct, asymmetric images: a random pattern inside a centred square, 0 outside."""
    x = torch.zeros(b, 4, h, h, dtype=torch.float64)
    q = h // 4
    x[:, :, q:h - q, q:h - q] = torch.rand(b, 4, h - 2 * q, h - 2 * q, generator=torch.Generator().manual_seed(0),
                                          dtype=torch.float64)
    return x


def _tiny_trainer(tmp_path, *overrides):
    """A trainer on the tiny procedural class at 16³, batch 4, through the closed form."""
    cfg = load_config(None, [f"run.out_dir={tmp_path}/runs", f"data.cache={tmp_path}/data",
                             f"data.shape_class={TINY}", "data.n_shapes=4", "data.views_per_shape=2",
                             "model.resolution=16", "model.width=4", "model.latent=8", "train.batch_size=4",
                             "render.backend=closed_form", *overrides])
    return Trainer(cfg, load_training_data(cfg, progress=False), torch.device("cpu"))


def _gen(seed=1):
    return torch.Generator().manual_seed(seed)


def _shift(img, dy, dx):
    """img moved by (dy, dx) pixels, zeros where nothing moved in."""
    out = torch.zeros_like(img)
    h, w = img.shape[-2:]
    ys, yd = slice(max(0, -dy), min(h, h - dy)), slice(max(0, dy), min(h, h + dy))
    xs, xd = slice(max(0, -dx), min(w, w - dx)), slice(max(0, dx), min(w, w + dx))
    out[..., yd, xd] = img[..., ys, xs]
    return out


def test_flip_mirrors_some_images_and_leaves_the_others():
    x = _images(32)
    y = augment(x, ["flip"], _gen())
    mirrored = [torch.equal(a, b.flip(-1)) for a, b in zip(y, x)]
    same = [torch.equal(a, b) for a, b in zip(y, x)]
    assert all(m != s for m, s in zip(mirrored, same))
    assert 8 <= sum(mirrored) <= 24


def test_translation_shifts_each_image_by_at_most_an_eighth_and_fills_with_empty_space():
    x = _images(16)
    y = augment(x, ["translation"], _gen())
    s = 2                                                       # round(16 / 8)
    shifts = []
    for a, b in zip(y, x):
        found = [(dy, dx) for dy in range(-s, s + 1) for dx in range(-s, s + 1) if torch.equal(a, _shift(b, dy, dx))]
        assert len(found) == 1
        shifts.append(found[0])
    assert len(set(shifts)) > 3                                 # each image its own draw
    assert torch.allclose(y.sum((1, 2, 3)), x.sum((1, 2, 3)))   # the object stays whole inside the frame


def test_cutout_zeroes_one_square_of_half_the_side():
    x = torch.ones(8, 1, 16, 16, dtype=torch.float64)
    y = augment(x, ["cutout"], _gen())
    for img in y[:, 0]:
        hole = img == 0
        rows, cols = hole.any(1).nonzero().flatten(), hole.any(0).nonzero().flatten()
        assert len(rows) <= 7 and len(cols) <= 7                # |Δ| < H/4 = 4: at most 7 pixels a side
        assert hole.sum() == len(rows) * len(cols)              # a rectangle (a square clipped by the border)
        assert torch.equal(img[~hole], torch.ones(int((~hole).sum()), dtype=torch.float64))


def test_the_train_section_lists_the_transforms_in_the_order_they_apply():
    """The lists ``train.d_augment`` and ``train.photo_augment`` are checked against live in the train
    section (config/train_settings.py); the transforms, in train/augment.py, are the same names in the same order."""
    assert tuple(A._TRANSFORMS) == AUGMENTS and tuple(A._PHOTO_TRANSFORMS) == PHOTO_AUGMENTS


def test_augmentations_are_exactly_differentiable():
    x = _images(3, 8).requires_grad_(True)
    for names in (["flip"], ["translation"], ["cutout"], list(AUGMENTS)):
        assert torch.autograd.gradcheck(lambda v: augment(v, names, _gen(5)), (x,))


def test_the_same_generator_draws_the_same_transforms_and_nothing_listed_changes_nothing():
    x = _images()
    assert torch.equal(augment(x, AUGMENTS, _gen(3)), augment(x, AUGMENTS, _gen(3)))
    assert torch.equal(augment(x, [], _gen(3)), x)
    with pytest.raises(ValueError, match="unknown augmentation"):
        augment(x, ["rotate"], _gen())
    with pytest.raises(ValueError, match="B, C, H, W"):
        augment(x[0], ["flip"], _gen())


def test_the_config_names_the_key_for_unknown_or_repeated_augmentations():
    with pytest.raises(ConfigError, match="train.d_augment"):
        load_config(None, ["train.d_augment=[rotate]"])
    with pytest.raises(ConfigError, match="train.d_augment"):
        load_config(None, ["train.d_augment=[flip, flip]"])
    with pytest.raises(ConfigError, match="gan3d"):
        load_config(None, ["train.d_augment=[flip]", "train.mode=gan3d", "train.task=generation"])
    assert load_config(None, ["train.d_augment=[flip, cutout]"]).train.d_augment == ["flip", "cutout"]


@pytest.mark.usefixtures("tiny_class")
def test_the_trainer_shows_d_augmented_reals_and_fakes_and_g_learns_through_them(tmp_path, monkeypatch):
    import mitsuba_platonic.train.trainer as T

    trainer = _tiny_trainer(tmp_path, "train.d_augment=[translation, cutout]")
    seen, fakes = [], []
    real_augment = T.augment

    def spy(x, names, g):
        seen.append((x.requires_grad, list(names)))
        y = real_augment(x, names, g)
        fakes.append(y)
        return y
    monkeypatch.setattr(T, "augment", spy)
    trainer.step(0)
    assert seen == [(False, ["translation", "cutout"]), (True, ["translation", "cutout"])]   # reals, then fakes
    assert fakes[1].grad_fn is not None                          # G's adversarial term runs through T


# -- train.photo_augment: each step's photos, before E, the reconstruction target and D -----------

def _premultiplied(b=5, h=8, seed=0):
    g = torch.Generator().manual_seed(seed)
    α = torch.rand(b, 1, h, h, generator=g, dtype=torch.float64)
    α[:, :, :2] = 0.0                                            # some empty space
    α[:, :, -2:] = 1.0                                           # some opaque pixels
    return torch.cat([torch.rand(b, 3, h, h, generator=g, dtype=torch.float64) * α, α], 1)


def test_the_hue_rotation_keeps_greys_and_a_third_of_a_turn_cycles_the_primaries():
    one = torch.ones(1, dtype=torch.float64)
    M = colour_matrices(one * 2 * math.pi / 3, one, one)[0]
    # a rotation by 120° about (1, 1, 1)/√3 maps the red axis onto green, green onto blue, blue onto red
    assert torch.allclose(M, torch.tensor([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], dtype=torch.float64),
                          atol=1e-12)
    M = colour_matrices(one * 0.4, one * 0.6, one * 1.1)[0]
    assert torch.allclose(M @ torch.ones(3, dtype=torch.float64), torch.full((3,), 1.1, dtype=torch.float64))
    H = colour_matrices(one * 0.4, one, one)[0]
    assert torch.allclose(H @ H.T, torch.eye(3, dtype=torch.float64), atol=1e-12)   # a rotation
    S = colour_matrices(one * 0.0, one * 0.0, one)[0]
    assert torch.allclose(S, torch.full((3, 3), 1.0 / 3.0, dtype=torch.float64))   # saturation 0: grey


def test_colour_keeps_alpha_and_premultiplied_colour_within_alpha():
    x = _premultiplied()
    y = augment_photos(x, ["colour"], _gen())
    assert torch.equal(y[:, 3:], x[:, 3:])
    assert (y[:, :3] >= 0).all() and (y[:, :3] <= y[:, 3:]).all()
    assert (y[:, :3][x[:, 3:].expand(-1, 3, -1, -1) == 0] == 0).all()   # empty space stays empty
    assert not torch.allclose(y, x)


def test_colour_is_a_draw_per_photo_from_the_stated_ranges():
    x = torch.zeros(400, 4, 1, 1, dtype=torch.float64)
    x[:, :3], x[:, 3] = 0.25, 1.0                                # a mid grey: hue cannot move it
    y = augment_photos(x, ["colour"], _gen())
    grey = y[:, :3, 0, 0]
    assert torch.allclose(grey, grey[:, :1].expand(-1, 3))       # greys stay grey
    b = grey[:, 0] / 0.25                                        # brightness alone moves a grey
    assert BRIGHTNESS[0] - 1e-9 <= b.min() and b.max() <= BRIGHTNESS[1] + 1e-9
    assert b.max() - b.min() > 0.3                               # and it is drawn per photo
    red = torch.zeros(1, 4, 1, 1, dtype=torch.float64)
    red[0, 0], red[0, 3] = 0.5, 1.0
    hues = [augment_photos(red, ["colour"], _gen(k))[0, :3, 0, 0] for k in range(50)]
    assert max(abs(float(c[1] - c[2])) for c in hues) > 0.05     # red turned towards yellow or magenta


def test_flip_mirrors_whole_photos_and_a_generator_repeats_its_draw():
    x = _premultiplied(b=64)
    y = augment_photos(x, ["flip"], _gen())
    mirrored = [torch.equal(y[i], x[i].flip(-1)) for i in range(len(x))]
    kept = [torch.equal(y[i], x[i]) for i in range(len(x))]
    assert all(m or k for m, k in zip(mirrored, kept)) and 16 < sum(mirrored) < 48
    assert torch.equal(augment_photos(x, ["flip", "colour"], _gen(5)), augment_photos(x, ["flip", "colour"], _gen(5)))


def test_photo_augment_refuses_what_it_cannot_do():
    with pytest.raises(ValueError, match="unknown photo augmentation"):
        augment_photos(_premultiplied(), ["cutout"], _gen())
    with pytest.raises(ValueError, match="RGBA"):
        augment_photos(torch.rand(2, 1, 8, 8), ["colour"], _gen())
    with pytest.raises(ConfigError, match="train.photo_augment"):
        load_config(None, ["train.photo_augment=[colour, colour]"])
    with pytest.raises(ConfigError, match="train.photo_augment: 'colour' needs colour"):
        load_config(None, ["train.photo_augment=[colour]", "render.model=vh"])
    with pytest.raises(ConfigError, match="ground-truth volumes"):
        load_config(None, ["train.photo_augment=[flip]", "train.mode=platonic3d"])
    assert load_config(None, ["train.photo_augment=[flip, colour]"]).train.photo_augment == ["flip", "colour"]


@pytest.mark.usefixtures("tiny_class")
def test_the_trainer_gives_e_the_target_and_d_the_same_augmented_photos(tmp_path, monkeypatch):
    import mitsuba_platonic.train.trainer as T

    trainer = _tiny_trainer(tmp_path, "train.photo_augment=[flip, colour]", "train.d_augment=[cutout]")
    made, e_saw, d_saw = [], [], []
    real_photos, real_d_augment = T.augment_photos, T.augment
    monkeypatch.setattr(T, "augment_photos", lambda x, names, g: made.append(real_photos(x, names, g)) or made[-1])
    monkeypatch.setattr(T, "augment", lambda x, names, g: d_saw.append(x) or real_d_augment(x, names, g))
    E = trainer.modules["E"]
    hook = E.register_forward_pre_hook(lambda module, args: e_saw.append(args[0]))
    trainer.step(0)
    hook.remove()
    assert len(made) == 1
    photos = made[0]
    assert photos.shape[0] == 4
    assert torch.equal(e_saw[0], photos)                          # E reads the new photos
    assert torch.equal(d_saw[0], photos)                          # D's reals are the same photos
