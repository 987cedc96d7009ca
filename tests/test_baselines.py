"""The baselines train what they claim: which loss terms reach G in each mode (gradient flow),
PrGAN-style views and view codes, Platonic3D's critic frames, and the baseline configs.

Gradient flow is measured inside the real training step: ``Trainer._g_objective`` sees G's named
loss terms just before they are summed; the probe below takes each term's gradient w.r.t. G's
weights there, and a second probe drops a term to compare G's update with and without it.
"""

from pathlib import Path

import pytest
import torch

from mitsuba_platonic.config import ConfigError, load_config
from mitsuba_platonic.model import RING_VIEWS
from mitsuba_platonic.render.pytorch.closed_form import rotate
from mitsuba_platonic.train.data import load_training_data
from mitsuba_platonic.train.trainer import Trainer, ring_views
from mitsuba_platonic.views import front_view, to_angles

from tiny_shapes import TINY

CONFIGS = Path(__file__).resolve().parents[1] / "configs"

#: The named terms of G's objective in each mode, for reconstruction (gan3d's compares volumes).
TERMS = {"platonic": {"adv2d", "rec"}, "platonic3d": {"adv2d", "adv3d", "rec"}, "gan3d": {"adv3d", "rec3d"},
         "prgan": {"adv2d", "rec"}}


pytestmark = pytest.mark.usefixtures("tiny_class")


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("data")


def _cfg(cache, mode, *extra, task="reconstruction"):
    model = "vh" if mode == "prgan" else "ea"
    ring = ["data.view_distribution=ring", "data.elevation=0", "train.view_distribution=ring"] \
        if mode == "prgan" else []
    loss = ["train.loss=wgan-gp", "train.rec_target=volume"] if mode == "gan3d" else []
    return load_config(None, [
        "run.name=r", f"data.cache={cache}", f"data.shape_class={TINY}", "data.n_shapes=4",
        "data.views_per_shape=2", "model.resolution=16", "model.width=4", "model.latent=8",
        "train.batch_size=2", "train.d_gate=null", "render.backend=closed_form", f"render.model={model}",
        f"data.formation={model}", f"train.task={task}", f"train.mode={mode}", *ring, *loss, *extra])


def _trainer(cfg):
    return Trainer(cfg, load_training_data(cfg, progress=False), torch.device("cpu"))


def _probe_terms(trainer, monkeypatch):
    """Record, per named term of G's objective, the norm of its gradient w.r.t. G's weights."""
    norms = {}
    original = Trainer._g_objective

    def probe(self, terms):
        params = list(self.nets["G"].parameters())
        for name, term in terms.items():
            grads = torch.autograd.grad(term, params, retain_graph=True, allow_unused=True)
            norms[name] = sum(float(g.norm()) for g in grads if g is not None)
        return original(self, terms)

    monkeypatch.setattr(trainer, "_g_objective", probe.__get__(trainer))
    return norms


def _g_update(cfg, drop=None):
    """G's weights after one step minus before, with the named term dropped from G's objective."""
    trainer = _trainer(cfg)
    if drop is not None:
        original = trainer._g_objective
        trainer._g_objective = lambda terms: original({k: v for k, v in terms.items() if k != drop})
    before = torch.cat([p.detach().flatten().clone() for p in trainer.nets["G"].parameters()])
    trainer.step(0)
    return torch.cat([p.detach().flatten() for p in trainer.nets["G"].parameters()]) - before


# -- which terms reach G, per mode ----------------------------------------------------------

@pytest.mark.parametrize("mode", list(TERMS))
def test_g_gets_gradient_from_each_term_of_its_mode(cache, mode, monkeypatch):
    trainer = _trainer(_cfg(cache, mode))
    norms = _probe_terms(trainer, monkeypatch)
    if mode == "gan3d":                                   # the 3D-GAN renders nothing
        monkeypatch.setattr(trainer, "render", lambda *a: pytest.fail("gan3d rendered an image"))
    trainer.step(0)
    assert set(norms) == TERMS[mode]
    for name, norm in norms.items():
        assert norm > 0, f"{mode}: G gets no gradient from its {name!r} term"


def test_platonic3d_g_update_needs_both_the_2d_and_the_3d_critic(cache):
    """Unlike the authors' public Platonic3D (whose G never sees the 2D term), our G's update
    changes when the 2D adversarial term is removed, and when the 3D one is."""
    cfg = _cfg(cache, "platonic3d")
    full = _g_update(cfg)
    assert torch.equal(full, _g_update(cfg))              # the comparison is deterministic
    assert (full - _g_update(cfg, drop="adv2d")).abs().max() > 0
    assert (full - _g_update(cfg, drop="adv3d")).abs().max() > 0


def test_platonic_g_update_needs_the_adversarial_and_the_input_view_term(cache):
    cfg = _cfg(cache, "platonic")
    full = _g_update(cfg)
    assert (full - _g_update(cfg, drop="adv2d")).abs().max() > 0
    assert (full - _g_update(cfg, drop="rec")).abs().max() > 0


def test_gan3d_generation_gets_gradient_from_d3_alone(cache, monkeypatch):
    trainer = _trainer(_cfg(cache, "gan3d", task="generation"))
    norms = _probe_terms(trainer, monkeypatch)
    monkeypatch.setattr(trainer, "render", lambda *a: pytest.fail("gan3d rendered an image"))
    trainer.step(0)
    assert set(norms) == {"adv3d"} and norms["adv3d"] > 0


@pytest.mark.parametrize("task", ["generation", "reconstruction"])
def test_gan3d_trains_g_on_d3_only(cache, task):
    trainer = _trainer(_cfg(cache, "gan3d", task=task))
    d_before = [p.detach().clone() for p in trainer.nets["D"].parameters()]
    g_before = [p.detach().clone() for p in trainer.nets["G"].parameters()]
    trainer.step(0)
    assert all(torch.equal(a, b) for a, b in zip(d_before, trainer.nets["D"].parameters()))
    assert any(not torch.equal(a, b) for a, b in zip(g_before, trainer.nets["G"].parameters()))


# -- the volume reconstruction term (rec_target: volume) -------------------------------------

@pytest.mark.parametrize("mode", ["gan3d", "platonic3d"])
def test_volume_rec_term_compares_v_with_its_images_truth_in_the_input_frame(cache, mode, monkeypatch):
    """rec3d = ‖v − v*‖² with v* read here from the image's own collection record (volume file,
    view) through the evaluation's truth_in_input_frame; and v* rendered from the input view
    reproduces the image, so the pairing and the frame are those of the photo."""
    import numpy as np
    from mitsuba_platonic.data.render_collection import load_manifest
    from mitsuba_platonic.evaluate.protocol import truth_in_input_frame
    from mitsuba_platonic.render import render
    from mitsuba_platonic.train.data import collection_folder

    cfg = _cfg(cache, mode, "train.rec_target=volume")
    trainer = _trainer(cfg)
    folder = collection_folder(cfg)
    train_records = [r for r in load_manifest(folder)["images"] if r["shape"] < len(trainer.volumes)]
    assert len(train_records) == len(trainer.images)
    seen = {}
    original = trainer.volume_rec

    def recording(v, idx, out):
        seen["v"], seen["idx"] = v.detach().clone(), idx.clone()
        seen["loss"] = original(v, idx, out)
        return seen["loss"]

    monkeypatch.setattr(trainer, "volume_rec", recording)
    norms = _probe_terms(trainer, monkeypatch)
    if mode == "gan3d":
        monkeypatch.setattr(trainer, "render", lambda *a: pytest.fail("gan3d rendered an image"))
    out = trainer.step(0)
    assert set(norms) == TERMS[mode] - {"rec"} | {"rec3d"} and norms["rec3d"] > 0
    def truth(r):
        vol = torch.from_numpy(np.load(folder / r["volume"])["volume"]).float()
        return truth_in_input_frame(vol, r["view"], "ea")

    rows = [train_records[i] for i in seen["idx"].tolist()]
    truths = torch.stack([truth(r) for r in rows])
    expected = torch.nn.functional.mse_loss(seen["v"], truths)
    assert abs(float(seen["loss"]) - float(expected)) <= 1e-6 * float(expected)
    assert abs(out["loss_rec3d"] - float(expected)) <= 1e-6 * float(expected)
    # the truth seen from the input view is the photo; another shape, or the same shape in the
    # frame of its other view, is not
    images, front = trainer.images[seen["idx"]], front_view(len(rows))
    error = float((render(truths, front, model="ea", backend="closed_form") - images).abs().mean())
    assert error < 0.01 * float(images.abs().mean())        # resampling round-off (0.4–0.5 % here)
    for other in ([next(q for q in train_records if q["shape"] != r["shape"]) for r in rows],
                  [{**r, "view": next(q["view"] for q in train_records
                                      if q["shape"] == r["shape"] and q["view"] != r["view"])} for r in rows]):
        wrong = render(torch.stack([truth(q) for q in other]), front, model="ea", backend="closed_form")
        assert float((wrong - images).abs().mean()) > 5 * error


@pytest.mark.parametrize("extra,key", [
    (("train.rec_target=volume",), "train.rec_target"),          # 'platonic' has no ground truth
    (("train.rec_target=depth",), "train.rec_target"),
])
def test_volume_rec_target_needs_a_3d_mode(cache, extra, key):
    with pytest.raises(ConfigError) as e:
        _cfg(cache, "platonic", *extra)
    assert str(e.value).startswith(key + ":") and "\n" not in str(e.value)


def test_gan3d_reconstruction_refuses_an_image_rec_target(cache):
    with pytest.raises(ConfigError, match=r"^train\.rec_target: the 3D-GAN baseline"):
        _cfg(cache, "gan3d", "train.rec_target=image")


# -- PrGAN-style: VH, 8 ring views, the view in G's input -----------------------------------

def test_prgan_renders_vh_from_ring_views_and_g_sees_the_view(cache, monkeypatch):
    cfg = _cfg(cache, "prgan", "train.random_views=2")
    trainer = _trainer(cfg)
    ring = ring_views(0.0)
    azimuths, elevations = to_angles(ring)
    assert torch.allclose(azimuths.remainder(360.0), torch.arange(8, dtype=torch.float64) * 45.0, atol=1e-6)
    assert torch.allclose(elevations, torch.zeros(8, dtype=torch.float64), atol=1e-6)
    assert torch.equal(ring[0], front_view())             # the input view is ring view 0
    calls, inputs = [], []
    render = trainer.render

    def recording(v, w, seed):
        calls.append((v, w, render(v, w, seed)))
        return calls[-1][2]

    monkeypatch.setattr(trainer, "render", recording)
    trainer.nets["G"].register_forward_pre_hook(lambda m, args: inputs.append(args[0].detach().clone()))
    norms = _probe_terms(trainer, monkeypatch)
    trainer.step(0)

    b, k, latent = cfg.train.batch_size, cfg.train.random_views, cfg.model.latent
    (v_view, w_view, i_view), (v_in, w_in, i_in) = calls    # random ring views, then the input view
    assert v_view.shape[1] == 1 and i_view.shape[1] == 1 and i_in.shape[1] == 1     # visual hull
    index = (w_view @ ring.T).argmax(1)               # which ring view each render used
    assert torch.equal(w_view, ring[index])                 # every random view is one of the 8
    assert torch.equal(w_in, front_view(b))
    (g_input,) = inputs                                      # one G pass: the random views, then the input
    assert g_input.shape == (b * k + b, latent + RING_VIEWS)
    code = g_input[:, latent:]
    assert torch.equal(code.sum(1), torch.ones(b * k + b)) and set(code.unique().tolist()) <= {0.0, 1.0}
    assert torch.equal(code[:b * k].argmax(1), index)      # G is told the view it is rendered from
    assert torch.equal(code[b * k:].argmax(1), torch.zeros(b, dtype=torch.long))
    assert norms["adv2d"] > 0 and norms["rec"] > 0
    first = trainer.nets["G"].net[0].weight.grad            # (latent + 8, ...): the code's rows learn
    assert first[latent:].abs().sum() > 0


def test_prgan_model_reconstructs_and_generates_with_the_input_view_code(cache):
    trainer = _trainer(_cfg(cache, "prgan"))
    model = trainer.model
    x = trainer.images[:2]
    model.eval()
    with torch.no_grad():
        z = model.E(x)
        expected = model.G(torch.cat([z, torch.nn.functional.one_hot(torch.zeros(2, dtype=torch.long), 8).float()], 1))
    assert torch.equal(model.reconstruct(x), expected)
    assert model.generate(3).shape == (3, 1, 16, 16, 16)


@pytest.mark.parametrize("override,key", [
    ("render.model=ea", "render.model"),
    ("data.formation=ao", "data.formation"),
    ("render.backend=physical", "render.model"),          # the path tracer renders colour (EA) only
    ("train.view_distribution=sphere", "train.view_distribution"),
    ("train.elevation=30", "train.elevation"),
    ("data.view_distribution=sphere", "data.view_distribution"),
    ("data.elevation=20", "data.elevation"),
])
def test_prgan_config_refuses_what_prgan_is_not(cache, override, key):
    with pytest.raises(ConfigError) as e:
        _cfg(cache, "prgan", override)
    assert str(e.value).startswith(key + ":") and "\n" not in str(e.value)


def test_prgan_needs_no_3d_data(cache):
    trainer = _trainer(_cfg(cache, "prgan"))
    assert trainer.volumes is None and "D3" not in trainer.nets


# -- Platonic3D: D3 compares volumes in the same frame -------------------------------------

def test_platonic3d_reconstruction_shows_d3_ground_truth_in_input_camera_frames(cache, monkeypatch):
    """G reconstructs in the input camera's frame; D3's real volumes must be in such frames too.
    With every training view at the top pole, each real is a ground truth rotated to that view."""
    cfg = _cfg(cache, "platonic3d", "data.view_distribution=ring", "data.elevation=90")
    trainer = _trainer(cfg)
    seen = {}
    original = trainer._critic_update

    def recording(name, opt, real, *rest):
        seen[name] = real.detach().clone()
        return original(name, opt, real, *rest)

    monkeypatch.setattr(trainer, "_critic_update", recording)
    trainer.step(0)
    top = rotate(trainer.volumes, torch.tensor([[0.0, 1.0, 0.0]]).expand(len(trainer.volumes), 3)).clamp(0, 1)
    for real in seen["D3"]:
        assert min(float((real - t).abs().max()) for t in top) < 1e-5
        assert min(float((real - t).abs().max()) for t in trainer.volumes) > 1e-3


# -- the Table-2 configs ---------------------------------------------------------------------

TABLE2 = ["baseline_platonic_vh.yaml", "baseline_platonic_ao.yaml", "baseline_platonic_ea.yaml",
          "baseline_prgan.yaml", "baseline_platonic3d.yaml", "baseline_gan3d.yaml"]


def test_platonic3d_row_is_the_3d_gan_row_plus_the_2d_adversarial_term():
    """The paper's Platonic3D is "the 3DGAN framework plus the PlatonicGAN adversarial term": the
    two configs differ in the mode alone (the rest of their training, data and networks equal)."""
    p3d, gan = (load_config(CONFIGS / n).to_dict() for n in ("baseline_platonic3d.yaml", "baseline_gan3d.yaml"))
    assert (p3d["train"]["mode"], gan["train"]["mode"]) == ("platonic3d", "gan3d")
    assert p3d["train"]["rec_target"] == "volume"
    for d in (p3d, gan):
        d["train"].pop("mode"), d["run"].pop("name")
    assert p3d["train"] == gan["train"] and p3d["data"] == gan["data"] and p3d["model"] == gan["model"]


@pytest.mark.parametrize("name", TABLE2)
def test_table2_configs_load_and_share_the_quickstart_schedule(name):
    cfg = load_config(CONFIGS / name)
    quick = load_config(CONFIGS / "quickstart.yaml")
    assert cfg.model.resolution == 32 and cfg.data.source == "procedural"
    assert (cfg.data.shape_class, cfg.data.n_shapes, cfg.data.split) == \
        (quick.data.shape_class, quick.data.n_shapes, quick.data.split)
    assert cfg.run.steps == quick.run.steps
