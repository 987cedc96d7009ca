"""Run folders written before the imports were made to flow one way (issue 26) still load.

A checkpoint stores the run's config as the plain mapping ``Config.to_dict()`` wrote
(:mod:`mitsuba_platonic.files.checkpoint` returns it as such); :mod:`mitsuba_platonic.config.loading` builds the
:class:`Config` from it, filling keys added since with their defaults, and the model from its weights.
"""

from __future__ import annotations

import torch

import pytest

from mitsuba_platonic.files.checkpoint import CHECKPOINT_VERSION, RunError, read_checkpoint
from mitsuba_platonic.config import Config, ModelConfig, TrainConfig
from mitsuba_platonic.config.loading import checkpoint_config
from mitsuba_platonic.config.retired import RETIRED
from mitsuba_platonic.model import Model
from mitsuba_platonic.train import run as R

#: Keys a config saved by an older version lacks (added to the config later).
LATER = {"model": ("critic_width", "init", "critic_init", "upsample", "encoder_hidden", "photo_texture", "texture_conv"),
         "train": ("d_augment", "photo_augment", "ema", "pose", "pose_weight", "colour_tv", "r1_weight",
                   "rec_target", "d_roll", "rec_loss", "colour_match")}


def _old_run(tmp_path, retired=None):
    """A run folder as an older ``platonic train`` left it: ``checkpoints/last.pt`` written with
    ``torch.save`` (version 1, a plain config lacking later keys, E and G's weights, empty optimisers);
    with ``retired``, a config of the versions between that holds the retired keys, at their off
    value unless ``retired`` gives another (``{(section, key): value}``)."""
    cfg = Config()
    cfg.model.resolution, cfg.model.width, cfg.model.latent = 16, 4, 8
    torch.manual_seed(3)
    model = Model.from_config(cfg)
    saved = cfg.to_dict()
    for section, keys in LATER.items():
        for key in keys:
            del saved[section][key]
    if retired is not None:
        for (section, key), (off, _) in RETIRED.items():
            saved[section][key] = retired.get((section, key), off)
    run_dir = tmp_path / "runs" / "old"
    (run_dir / "checkpoints").mkdir(parents=True)
    torch.save({"version": CHECKPOINT_VERSION, "step": 7, "config": saved,
                "trainer": {"nets": model.state_dict(), "opt_g": {}, "opt_d": {}}}, run_dir / "checkpoints" / "last.pt")
    return run_dir, model


def test_an_old_checkpoint_is_read_as_plain_data(tmp_path):
    run_dir, _ = _old_run(tmp_path)
    ckpt = read_checkpoint(run_dir)
    assert type(ckpt.config) is dict and ckpt.config["run"]["name"] == "old" and ckpt.step == 7
    cfg = checkpoint_config(ckpt)
    assert isinstance(cfg, Config) and cfg.model.width == 4 and cfg.run.name == "old"
    assert cfg.model.critic_width == ModelConfig().critic_width and cfg.train.d_augment == TrainConfig().d_augment


def test_an_old_run_folder_loads_its_model(tmp_path):
    run_dir, trained = _old_run(tmp_path)
    for model in (Model.from_checkpoint(run_dir), Model.from_checkpoint(run_dir / "checkpoints" / "last.pt"),
                  R.load_run(run_dir)[1]):
        assert model.step == 7 and model.resolution == 16
        for (name, a), (_, b) in zip(model.state_dict().items(), trained.state_dict().items()):
            assert torch.equal(a, b), name
    cfg, _, step = R.load_run(run_dir)
    assert isinstance(cfg, Config) and step == 7
    x = torch.rand(1, 4, 16, 16)
    assert torch.equal(Model.from_checkpoint(run_dir).reconstruct(x), trained.reconstruct(x))


def test_a_run_saved_with_retired_options_off_loads_and_one_with_an_option_on_names_its_commit(tmp_path):
    run_dir, _ = _old_run(tmp_path / "off", retired={})
    assert Model.from_checkpoint(run_dir).step == 7
    run_dir, _ = _old_run(tmp_path / "on", retired={("model", "texture_blur"): 2.0})
    with pytest.raises(RunError, match=r"model\.texture_blur: 2\.0 was tried and retired .*commit 3afe14f"):
        Model.from_checkpoint(run_dir)


def test_a_run_folders_config_yaml_with_retired_options_off_reads_and_with_one_on_names_its_commit(tmp_path):
    """``RUN/config.yaml`` as a run of the versions before issue 44 wrote it (every key, the retired
    ones at their off value) reads back as the config without them; one with ``train.adv_input: 1``
    is refused naming the commit that has its code."""
    import yaml
    from mitsuba_platonic.train.folder import read_run_config
    saved = Config().to_dict()
    for (section, key), (off, _) in RETIRED.items():
        saved[section][key] = off
    path = tmp_path / "config.yaml"
    path.write_text(yaml.safe_dump(saved))
    assert read_run_config(path).to_dict() == Config().to_dict()
    saved["train"]["adv_input"] = 1.0
    path.write_text(yaml.safe_dump(saved))
    with pytest.raises(RunError, match=r"train\.adv_input: 1\.0 was tried and retired .*commit 3afe14f"):
        read_run_config(path)
