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


# -- how the critics start (model.critic_init) ----------------------------------------------

def _discs_and_bars(n, g):
    """n dark discs (real) and n dark bars (fake), 32² premultiplied RGBA, random sizes."""
    y, x = torch.meshgrid(torch.linspace(-1, 1, 32), torch.linspace(-1, 1, 32), indexing="ij")
    out = []
    for kind in ("disc", "bar"):
        r = 0.3 + 0.4 * torch.rand(n, 1, 1, generator=g)
        mask = ((x ** 2 + y ** 2).sqrt() < r) if kind == "disc" else ((x.abs() < 0.3 * r) & (y.abs() < r))
        alpha = mask.float()[:, None]
        out.append(torch.cat([alpha * torch.tensor([0.3, 0.1, 0.05])[None, :, None, None], alpha], 1))
    return out


def _critic_accuracy_after_training(init, steps=200):
    from mitsuba_platonic.networks.nets import Discriminator, NetConfig, init_critic_he, init_weights
    torch.manual_seed(0)
    D = Discriminator(NetConfig(resolution=32, width=16, norm="none"))
    D.apply(init_weights)
    if init == "he":
        D.apply(init_critic_he)
    opt = torch.optim.Adam(D.parameters(), lr=2e-5, betas=(0.5, 0.9))         # the default lr_D
    g = torch.Generator().manual_seed(1)
    for _ in range(steps):
        real, fake = _discs_and_bars(8, g)
        loss = d_loss("nonsaturating", D(real), D(fake))
        opt.zero_grad()
        loss.backward()
        opt.step()
    real, fake = _discs_and_bars(64, g)
    with torch.no_grad():
        num, den = soft_accuracy_counts(D(real), D(fake))
    return float(num / den)


def test_a_he_initialised_critic_learns_where_a_dcgan_one_without_norm_barely_moves():
    """lab/critic-that-learns.md: at lr_D 2e-5 and no normalisation,
    200 updates on an easy task (discs against bars) leave a DCGAN-initialised D near chance and
    take a He-initialised one well above it (measured 0.51 and 0.69)."""
    assert _critic_accuracy_after_training("dcgan") < 0.56
    assert _critic_accuracy_after_training("he") > 0.62


def test_critic_init_he_redraws_the_critics_and_nothing_else(tmp_path):
    dcgan = _trainer(tmp_path, "train.mode=platonic3d")
    he = _trainer(tmp_path, "train.mode=platonic3d", "model.critic_init=he")
    for name in ("E", "G"):
        assert all(torch.equal(a, b) for a, b in zip(dcgan.nets[name].parameters(), he.nets[name].parameters()))
    for name in ("D", "D3"):
        w_dcgan, w_he = (t.nets[name].trunk[0].weight for t in (dcgan, he))
        fan_in = w_he[0].numel()
        assert abs(float(w_dcgan.std()) - 0.02) < 0.004
        assert abs(float(w_he.std()) - (2.0 / (1.04 * fan_in)) ** 0.5) < 0.2 * (2.0 / (1.04 * fan_in)) ** 0.5


def test_critic_width_widens_the_critics_and_nothing_else(tmp_path):
    """model.critic_width = 8 at model.width = 4: D's and D3's stages have 8, 16 channels (16³:
    two stages), E and G keep 4, and a training step runs."""
    narrow = _trainer(tmp_path, "train.mode=platonic3d")
    wide = _trainer(tmp_path, "train.mode=platonic3d", "model.critic_width=8")
    for name in ("D", "D3"):
        convs = [m for m in wide.nets[name].trunk if isinstance(m, (torch.nn.Conv2d, torch.nn.Conv3d))]
        assert [m.out_channels for m in convs] == [8, 16]
        assert wide.nets[name].head.in_channels == 16
    for name in ("E", "G"):
        assert [p.shape for p in narrow.nets[name].parameters()] == [p.shape for p in wide.nets[name].parameters()]
    assert [m.out_channels for m in narrow.nets["D"].trunk if isinstance(m, torch.nn.Conv2d)] == [4, 8]
    out = wide.step(0)
    assert math.isfinite(out["loss_d"]) and math.isfinite(out["loss_d3"])
    with pytest.raises(Exception, match="model.critic_width: expected a positive value"):
        load_config(None, ["model.critic_width=0"])


# -- the R1 penalty (train.r1_weight) -----------------------------------------------------------

def test_r1_penalty_of_a_linear_critic_is_its_squared_weight_norm():
    """D(x) = w·x + b has ∇ₓD = w everywhere: the penalty is ‖w‖² for any batch, and its gradient
    in w is 2w (checked against the closed form, not against autograd's own value)."""
    from mitsuba_platonic.train.losses import r1_penalty
    torch.manual_seed(0)
    lin = torch.nn.Linear(12, 1).double()
    D = lambda x: lin(x.flatten(1)).squeeze(1)                      # noqa: E731
    x = torch.rand(5, 3, 2, 2, dtype=torch.float64)
    logits, _, r1 = r1_penalty(D, x)
    w = lin.weight.detach().flatten()
    assert torch.allclose(logits, D(x))
    assert torch.allclose(r1, (w ** 2).sum())
    r1.backward()
    assert torch.allclose(lin.weight.grad.flatten(), 2 * w)
    assert lin.bias.grad is None or float(lin.bias.grad.abs().max()) == 0.0
    assert not x.requires_grad                                        # the caller's batch is left alone


def test_r1_penalty_matches_finite_differences_on_a_nonlinear_critic():
    """Both the penalty's value (‖∇ₓD‖² from central differences of D in x) and its gradient in one
    of D's weights (central differences of the penalty) for a small tanh network in float64."""
    from mitsuba_platonic.train.losses import r1_penalty
    torch.manual_seed(1)
    net = torch.nn.Sequential(torch.nn.Linear(6, 5), torch.nn.Tanh(), torch.nn.Linear(5, 1)).double()
    D = lambda x: net(x).squeeze(1)                                   # noqa: E731
    x = torch.rand(3, 6, dtype=torch.float64)
    h = 1e-6
    want = 0.0
    for i in range(3):
        g = [(D(x[i:i + 1] + h * e) - D(x[i:i + 1] - h * e)).item() / (2 * h) for e in torch.eye(6, dtype=x.dtype)]
        want += sum(v * v for v in g) / 3
    _, _, r1 = r1_penalty(D, x)
    assert abs(float(r1) - want) < 1e-7
    r1.backward()
    w = net[0].weight
    analytic = float(w.grad[2, 4])
    w.data[2, 4] += h                                                 # .data: the penalty needs autograd on
    up = float(r1_penalty(D, x)[2])
    w.data[2, 4] -= 2 * h
    down = float(r1_penalty(D, x)[2])
    w.data[2, 4] += h
    assert abs(analytic - (up - down) / (2 * h)) < 1e-6 * max(1.0, abs(analytic))


@pytest.mark.parametrize("step", [0, 1])
def test_r1_weight_adds_half_gamma_times_the_penalty_at_the_reals_to_the_critic_loss(tmp_path, step):
    """One trainer step with r1_weight γ = 5 makes the Adam step of the loss
    d_loss + γ/2 ‖∇ₓD(x_real)‖² on the batch D saw (penalty at the reals, not at the fakes), on
    every step."""
    from mitsuba_platonic.train.losses import r1_penalty
    γ = 5.0
    trainer = _trainer(tmp_path, f"train.r1_weight={γ}", "train.d_gate=null", "train.lr_d=1e-3")
    net = trainer.nets["D"]
    reference, at_fakes = copy.deepcopy(net), copy.deepcopy(net)
    seen = {}
    original = trainer._critic_update

    def spy(name, opt_, real, fake, *args):
        seen["real"], seen["fake"] = real.detach().clone(), fake.detach().clone()
        return original(name, opt_, real, fake, *args)

    trainer._critic_update = spy
    trainer.step(step)
    betas = tuple(trainer.cfg.train.betas)
    for copy_, where in ((reference, "real"), (at_fakes, "fake")):
        opt = torch.optim.Adam(copy_.parameters(), lr=1e-3, betas=betas)
        loss = d_loss("nonsaturating", copy_(seen["real"]), copy_(seen["fake"]))
        loss = loss + 0.5 * γ * r1_penalty(copy_, seen[where])[2]
        opt.zero_grad()
        loss.backward()
        opt.step()
    assert all(torch.allclose(a, b, atol=1e-6) for a, b in zip(net.parameters(), reference.parameters()))
    assert not all(torch.allclose(a, b, atol=1e-6) for a, b in zip(net.parameters(), at_fakes.parameters()))


def test_r1_penalty_over_reals_and_fakes_together_is_the_reals_own():
    """With the fakes in the same forward pass (a critic whose samples do not interact) the reals'
    logits, the fakes' logits and the penalty are those of separate passes."""
    from mitsuba_platonic.train.losses import r1_penalty
    torch.manual_seed(2)
    net = torch.nn.Sequential(torch.nn.Conv2d(4, 3, 3, 2, 1), torch.nn.LeakyReLU(0.2), torch.nn.Flatten(),
                              torch.nn.Linear(3 * 4 * 4, 1)).double()
    D = lambda x: net(x).squeeze(1)                                   # noqa: E731
    real, fake = torch.rand(3, 4, 8, 8, dtype=torch.float64), torch.rand(2, 4, 8, 8, dtype=torch.float64)
    l_real, none, r1 = r1_penalty(D, real)
    l_real2, l_fake, r1_2 = r1_penalty(D, real, fake)
    assert none is None and l_fake.shape == (2,)
    assert torch.allclose(l_real, l_real2) and torch.allclose(l_fake, D(fake)) and torch.allclose(r1, r1_2)


def test_r1_weight_is_refused_when_negative_or_with_wgan_gp():
    from mitsuba_platonic.config import ConfigError
    with pytest.raises(ConfigError, match=r"train.r1_weight: expected a non-negative value, got -1"):
        load_config(None, ["train.r1_weight=-1"])
    with pytest.raises(ConfigError, match="train.r1_weight: the R1 penalty is for the non-saturating loss"):
        load_config(None, ["train.r1_weight=1", "train.loss=wgan-gp"])
    assert load_config(None, []).train.r1_weight == 0.0
