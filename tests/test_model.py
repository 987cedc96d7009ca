"""The inference model: read from a run's checkpoint without the trainer, it reconstructs and
generates exactly what the trained networks do."""

import pytest
import torch

from mitsuba_platonic.files.checkpoint import RunError, load_checkpoint, save_checkpoint
from mitsuba_platonic.config import load_config
from mitsuba_platonic.errors import UserError
from mitsuba_platonic.model import Model
from mitsuba_platonic.train import run as R
from mitsuba_platonic.train.data import load_training_data
from mitsuba_platonic.train.trainer import Trainer
from tiny_shapes import TINY



pytestmark = pytest.mark.usefixtures("tiny_class")


def _cfg(tmp_path, *extra):
    return load_config(None, [
        f"run.out_dir={tmp_path}/runs", "run.name=r", "run.steps=3", "run.sample_every=1000",
        "run.checkpoint_every=1000", f"data.cache={tmp_path}/data", f"data.shape_class={TINY}", "data.n_shapes=3",
        "data.views_per_shape=2", "model.resolution=16", "model.width=4", "model.latent=8", "model.norm=batch",
        "train.batch_size=2", *extra])


def test_a_model_from_a_checkpoint_reconstructs_as_the_trained_networks(tmp_path):
    """A run of 3 steps, then the same 3 steps in memory: the model read from the run folder (and
    from its checkpoint file) gives the trained E and G's volumes, in eval mode (BatchNorm's
    running statistics, which the training steps moved)."""
    cfg = _cfg(tmp_path)
    run_dir = R.train(cfg, progress=False)
    data = load_training_data(cfg, progress=False)
    trainer = Trainer(cfg, data, torch.device("cpu"))
    for step in range(3):
        trainer.step(step)
    x = data.images[:3]
    trainer.nets.eval()
    with torch.no_grad():
        expected = trainer.nets["G"](trainer.nets["E"](x))
        z = torch.randn(2, cfg.model.latent, generator=torch.Generator().manual_seed(5))
        expected_samples = trainer.nets["G"](z)

    model = Model.from_checkpoint(run_dir)
    assert model.step == 3 and model.resolution == 16 and model.channels == 4 and model.formation == "ea"
    assert model.task == "reconstruction" and model.origin == run_dir / "checkpoints" / "last.pt"
    model.train()
    volumes = model.reconstruct(x)
    assert model.training                                       # the caller's mode is restored
    assert volumes.shape == (3, 4, 16, 16, 16)
    assert torch.equal(volumes, expected)
    assert torch.equal(model.generate(2, seed=5), expected_samples)

    from_file = Model.from_checkpoint(run_dir / "checkpoints" / "step_0000003.pt")
    assert torch.equal(from_file.reconstruct(x), expected)

    _, loaded, step = R.load_run(run_dir)                       # load_run gives the same model
    assert step == 3 and isinstance(loaded, Model) and torch.equal(loaded.reconstruct(x), expected)

    fresh = Model.from_config(cfg)                              # not the trained weights: the test can tell
    assert not torch.equal(fresh.reconstruct(x), expected)


def test_the_trainer_holds_the_model_it_trains(tmp_path):
    cfg = _cfg(tmp_path)
    trainer = Trainer(cfg, load_training_data(cfg, progress=False), torch.device("cpu"))
    assert trainer.nets["E"] is trainer.model.E and trainer.nets["G"] is trainer.model.G
    before = {k: v.clone() for k, v in trainer.model.state_dict().items()}
    trainer.step(0)
    assert any(not torch.equal(before[k], v) for k, v in trainer.model.state_dict().items())


def test_a_generation_model_does_not_reconstruct_and_old_checkpoints_are_one_line(tmp_path):
    cfg = _cfg(tmp_path, "train.task=generation", "run.steps=1")
    run_dir = R.train(cfg, progress=False)
    model = Model.from_checkpoint(run_dir)
    assert model.generate(1).shape == (1, 4, 16, 16, 16)
    with pytest.raises(UserError, match="trained for 'generation'.*train.task: reconstruction"):
        model.reconstruct(torch.zeros(1, 4, 16, 16))
    last = run_dir / "checkpoints" / "last.pt"
    state = load_checkpoint(last)
    state["version"] = 0
    save_checkpoint(last, state)
    with pytest.raises(RunError, match=r"last.pt cannot be loaded: checkpoint format 0, this version reads 1$"):
        Model.from_checkpoint(last)
