"""train.ema: a moving average of E's and G's weights, which never changes training and is what
samples, checkpoints' inference model and evaluation use."""

import pytest
import torch

from mitsuba_platonic.config import ConfigError, load_config
from mitsuba_platonic.model import Model
from mitsuba_platonic.train import run as R
from mitsuba_platonic.train.data import load_training_data
from mitsuba_platonic.train.trainer import Trainer
from tiny_shapes import TINY

pytestmark = pytest.mark.usefixtures("tiny_class")


def _cfg(tmp_path, *extra, name="r"):
    return load_config(None, [
        f"run.out_dir={tmp_path}/runs", f"run.name={name}", "run.steps=4", "run.sample_every=1000",
        "run.checkpoint_every=2", f"data.cache={tmp_path}/data", f"data.shape_class={TINY}", "data.n_shapes=3",
        "data.views_per_shape=2", "model.resolution=16", "model.width=4", "model.latent=8", "model.norm=batch",
        "train.batch_size=2", *extra])


def _trainer(cfg):
    return Trainer(cfg, load_training_data(cfg, progress=False), torch.device("cpu"))


def _copy(module):
    return {k: v.detach().clone() for k, v in module.state_dict().items()}


@pytest.mark.parametrize("steps", [[0, 1], [500]])
def test_the_average_follows_its_formula(tmp_path, steps):
    """After G's update of step t: θ_ema = β_t θ_ema(before) + (1 − β_t) θ(after), β_t = min(β, (1 + t)/(10 + t)),
    for every parameter of E and G; BatchNorm's running statistics are the trained ones."""
    β = 0.9
    trainer = _trainer(_cfg(tmp_path, f"train.ema={β}"))
    params = [n for n, _ in trainer.model.named_parameters()]
    buffers = [n for n, _ in trainer.model.named_buffers()]
    assert params and buffers and any(n.startswith("E.") for n in params)
    for t in steps:
        before = _copy(trainer.ema)
        trainer.step(t)
        after, ema = _copy(trainer.model), _copy(trainer.ema)
        β_t = min(β, (1 + t) / (10 + t))
        assert β_t == (0.1 if t == 0 else 2 / 11 if t == 1 else β)
        for n in params:
            assert not torch.equal(after[n], before[n])            # a step that moved the weights
            torch.testing.assert_close(ema[n], β_t * before[n] + (1 - β_t) * after[n], rtol=1e-6, atol=1e-7)
        for n in buffers:
            assert torch.equal(ema[n], after[n])


def test_the_average_never_changes_what_is_trained(tmp_path):
    """The same 3 steps with and without train.ema give bit-identical E, G and D."""
    plain, averaged = _trainer(_cfg(tmp_path)), _trainer(_cfg(tmp_path, "train.ema=0.5"))
    for t in range(3):
        assert plain.step(t) == averaged.step(t)
    a, b = plain.nets.state_dict(), averaged.nets.state_dict()
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)
    assert averaged.inference_model is averaged.ema and plain.inference_model is plain.model
    assert not all(torch.equal(v, averaged.model.state_dict()[k]) for k, v in averaged.ema.state_dict().items())


def test_checkpoints_keep_the_average_and_the_model_reads_it(tmp_path):
    """A 4-step run with a checkpoint every 2 steps: the model read from the run is the average
    (not the trained weights), and resuming from step 2 ends with the average of an uninterrupted run."""
    cfg = _cfg(tmp_path, "train.ema=0.8")
    trainer = _trainer(cfg)
    for t in range(4):
        trainer.step(t)
    x = trainer.images[:3]
    with torch.no_grad():
        expected, trained = trainer.ema.reconstruct(x), trainer.model.reconstruct(x)
    assert not torch.allclose(expected, trained)

    run_dir = R.train(cfg, progress=False)
    assert torch.equal(Model.from_checkpoint(run_dir).reconstruct(x), expected)

    again = _cfg(tmp_path, "train.ema=0.8", name="resumed")
    R.train(again, progress=False, stop_at=2)
    assert torch.equal(Model.from_checkpoint(tmp_path / "runs" / "resumed").reconstruct(x),
                       _reconstruct_after(cfg, 2, x))      # the checkpoint at step 2 holds step 2's average
    run_2 = R.train(again, resume=True, progress=False)
    assert torch.equal(Model.from_checkpoint(run_2).reconstruct(x), expected)


def _reconstruct_after(cfg, steps, x):
    trainer = _trainer(cfg)
    for t in range(steps):
        trainer.step(t)
    return trainer.ema.reconstruct(x)


@pytest.mark.parametrize("value", [0, 1, 1.5, -0.1])
def test_the_config_refuses_a_decay_outside_0_1(value):
    with pytest.raises(ConfigError, match=r"train.ema: expected null or a decay in \(0, 1\)"):
        load_config(None, [f"train.ema={value}"])
