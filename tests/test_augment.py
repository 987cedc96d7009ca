"""train.d_augment: D's differentiable augmentations (train/augment.py) on images with known answers,
their gradients, and where the trainer applies them."""

import pytest
import torch

from mitsuba_platonic.config import ConfigError, load_config
from mitsuba_platonic.train.augment import AUGMENTS, augment
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

    cfg = load_config(None, [f"run.out_dir={tmp_path}/runs", f"data.cache={tmp_path}/data",
                             f"data.shape_class={TINY}", "data.n_shapes=4", "data.views_per_shape=2",
                             "model.resolution=16", "model.width=4", "model.latent=8", "train.batch_size=4",
                             "render.backend=closed_form", "train.d_augment=[translation, cutout]"])
    trainer = Trainer(cfg, load_training_data(cfg, progress=False), torch.device("cpu"))
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
