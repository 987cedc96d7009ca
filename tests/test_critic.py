"""The critic update shared by every mode: the soft-accuracy gate and ``d_steps``."""

import copy
import math

import pytest
import torch

from mitsuba_platonic.config import load_config
from mitsuba_platonic.train.data import load_training_data
from mitsuba_platonic.train.losses import d_loss, hard_accuracy_counts, soft_accuracy_counts
from mitsuba_platonic.train.trainer import Trainer
from tiny_shapes import TINY



pytestmark = pytest.mark.usefixtures("tiny_class")


def _trainer(tmp_path, *extra):
    cfg = load_config(None, [
        f"run.out_dir={tmp_path}/runs", f"data.cache={tmp_path}/data", f"data.shape_class={TINY}",
        "data.n_shapes=4", "data.views_per_shape=2", "model.resolution=16", "model.width=4", "model.latent=8",
        "train.batch_size=4", *extra])
    return Trainer(cfg, load_training_data(cfg, progress=False), torch.device("cpu"))


def test_soft_accuracy_is_the_authors_formula_and_the_hard_one_counts_signs():
    real, fake = torch.tensor([0.3, -1.2, 2.0]), torch.tensor([-0.5, 0.7, 0.1])
    σ = lambda x: 1.0 / (1.0 + math.exp(-x))                       # noqa: E731
    want = 0.5 * (sum(map(σ, real.tolist())) / 3 + 1.0 - sum(map(σ, fake.tolist())) / 3)
    num, den = soft_accuracy_counts(real, fake)
    assert math.isclose(float(num / den), want, rel_tol=1e-6)
    num, den = hard_accuracy_counts(real, fake)
    assert float(num / den) == pytest.approx(3 / 6)                # 0.3, 2.0 real > 0; −0.5 fake < 0
    # an untrained D: logits that differ by 1e-3 are all "correct" by sign, but barely by confidence
    real, fake = torch.full((8,), 5e-4), torch.full((8,), -5e-4)
    hard = hard_accuracy_counts(real, fake)
    soft = soft_accuracy_counts(real, fake)
    assert float(hard[0] / hard[1]) == 1.0
    assert abs(float(soft[0] / soft[1]) - 0.5) < 1e-3


def test_gate_judges_by_soft_accuracy(tmp_path):
    """An untrained D (soft accuracy ≈ ½) trains under the authors' 0.6 gate and not under 0.4."""
    for gate, updated in [(0.6, 1.0), (0.4, 0.0)]:
        trainer = _trainer(tmp_path, f"train.d_gate={gate}")
        d0 = copy.deepcopy(trainer.nets["D"].state_dict())
        out = trainer.step(0)
        assert abs(out["acc_d"] - 0.5) < 0.05, out
        assert out["d_updated"] == updated
        same = all(torch.equal(d0[k], v) for k, v in trainer.nets["D"].state_dict().items())
        assert same == (updated == 0.0)


@pytest.mark.parametrize("mode, task, critic", [("platonic", "reconstruction", "D"),
                                                ("platonic3d", "reconstruction", "D3"),
                                                ("gan3d", "generation", "D3")])
def test_d_steps_make_that_many_fresh_updates_in_every_mode(tmp_path, mode, task, critic):
    """d_steps = 3 equals three Adam steps on the same (real, fake) batch, each with a fresh loss."""
    trainer = _trainer(tmp_path, f"train.mode={mode}", f"train.task={task}", "train.d_steps=3",
                       "train.loss=nonsaturating")
    net = trainer.nets[critic]
    reference = copy.deepcopy(net)
    opt = torch.optim.Adam(reference.parameters(), lr=trainer.cfg.train.lr_d, betas=tuple(trainer.cfg.train.betas))
    seen = {}
    original = trainer._critic_update

    def spy(name, opt_, real, fake, *args):
        if name == critic:
            seen["real"], seen["fake"] = real.detach().clone(), fake.detach().clone()
        return original(name, opt_, real, fake, *args)

    trainer._critic_update = spy
    out = trainer.step(0)
    assert out[f"{critic.lower()}_updated"] == 1.0
    for _ in range(3):
        loss = d_loss("nonsaturating", reference(seen["real"]), reference(seen["fake"]))
        opt.zero_grad()
        loss.backward()
        opt.step()
    for (k, a), b in zip(net.named_parameters(), reference.parameters()):
        assert torch.allclose(a, b, atol=1e-6), k
