"""train.azimuth: auto: read where the photos' silhouettes say the class is not round, every azimuth where
they say it is or where there are too few photos to say (mitsuba_platonic/train/azimuth_choice.py)."""

from __future__ import annotations

import pytest
import torch

from mitsuba_platonic.config import ConfigError, load_config
from mitsuba_platonic.evaluate import priors as P
from mitsuba_platonic.files.resources import config_path
from mitsuba_platonic.train.azimuth_choice import choice_line, choose_azimuth
from test_shape_priors import _animal, _lathe


def _photos(masks):
    """RGBA photos (M, 4, R, R) whose opacity is ``masks``: what the choice reads is the last channel."""
    a = torch.stack(masks).float()
    return torch.cat([0.5 * a[:, None].expand(-1, 3, -1, -1), a[:, None]], 1)


def _auto():
    return load_config(config_path("photos"), ["data.path=photos", "train.azimuth=auto"])


def test_lopsided_silhouettes_choose_read_azimuths_and_round_ones_every_azimuth():
    animals = _photos([_animal(left=i % 2 == 1) for i in range(10)])     # U = 40 / 140 = 0.29 each
    lathes = _photos([_lathe(seed=i) for i in range(10)])                # U = 0 each
    cfg = _auto()
    chosen, evidence = choose_azimuth(cfg, animals)
    assert chosen.train.azimuth == "read" and evidence.upper_asymmetry == pytest.approx(40 / 140)
    assert cfg.train.azimuth == "auto"                                   # the caller's config is not changed
    assert chosen.train.turn == cfg.train.turn and chosen.model == cfg.model   # nothing else is
    chosen, evidence = choose_azimuth(cfg, lathes)
    assert chosen.train.azimuth == "every" and evidence.upper_asymmetry == pytest.approx(0.0, abs=1e-12)
    assert "auto → read" in choice_line("read", P.round_evidence(animals)) and "0.286 is above 0.25" in \
        choice_line("read", P.round_evidence(animals))
    assert "is at most 0.25: the class is round" in choice_line("every", P.round_evidence(lathes))


def test_too_few_photos_to_say_choose_every_azimuth():
    few = _photos([_animal() for _ in range(P.MIN_PHOTOS - 1)])
    chosen, evidence = choose_azimuth(_auto(), few)
    assert not evidence.decided and chosen.train.azimuth == "every"
    assert f"{P.MIN_PHOTOS - 1} photos with a silhouette, fewer than a verdict needs" in choice_line("every", evidence)


@pytest.mark.parametrize("value", ["read", "every"])
def test_a_config_that_says_which_azimuths_keeps_them(value):
    cfg = load_config(config_path("photos"), ["data.path=photos", f"train.azimuth={value}"])
    lathes = _photos([_lathe(seed=i) for i in range(10)])
    assert choose_azimuth(cfg, lathes)[0] is cfg


def test_auto_needs_the_upright_pose_and_its_head_as_read_does():
    with pytest.raises(ConfigError, match="train.azimuth: 'auto'.*pose 'input'"):
        load_config(None, ["train.azimuth=auto"])


def test_the_trainer_makes_the_choice_and_builds_the_head_it_needs():
    from mitsuba_platonic.train.data import TrainingData
    from mitsuba_platonic.train.trainer import Trainer
    tiny = ["data.path=photos", "train.azimuth=auto", "model.resolution=32", "model.width=4", "model.latent=8",
            "model.critic_width=4", "train.batch_size=2"]
    cfg = load_config(config_path("photos"), tiny)
    for masks, chosen in (([_animal(left=i % 2 == 1) for i in range(10)], "read"),
                          ([_lathe(seed=i) for i in range(10)], "every")):
        photos = _photos(masks)
        trainer = Trainer(cfg, TrainingData(images=photos[:8], held_out=photos[8:]), torch.device("cpu"))
        assert trainer.cfg.train.azimuth == chosen and cfg.train.azimuth == "auto"
        assert ("A" in trainer.nets) == (chosen == "read")
        assert trainer.azimuth_evidence.photos == 10                 # training and held-out photos alike
