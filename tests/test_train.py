"""Training: one step per renderer and mode, who changes what, resume, crash-safe checkpoints,
Ctrl-C, data parallel, and the command line."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch

from mitsuba_platonic.config import load_config
from mitsuba_platonic.data import shapes
from mitsuba_platonic.train import run as R
from mitsuba_platonic.train.data import load_training_data
from mitsuba_platonic.train.trainer import Trainer
from mitsuba_platonic.volume import voxel_centres

TINY = "tiny_blob"


def _blob(rng, n):
    """A coloured ellipsoid with a random radius and colour: a cheap class for tests."""
    p = voxel_centres(n)
    radii = torch.tensor(rng.uniform(0.3, 0.7, size=3))
    d = ((p / radii) ** 2).sum(-1).sqrt() - 1.0
    density = torch.sigmoid(-d * n / 2.0)
    rgb = torch.tensor(rng.uniform(0.2, 0.9, size=3))[:, None, None, None].expand(3, n, n, n)
    return torch.cat([rgb, density[None]]).float()


@pytest.fixture(scope="module", autouse=True)
def tiny_class():
    with shapes.registered(TINY, _blob):
        yield


def _cfg(tmp_path, *extra):
    return load_config(None, [
        f"run.out_dir={tmp_path}/runs", "run.name=r", "run.steps=4", "run.log_every=1", "run.sample_every=2",
        "run.checkpoint_every=2", f"data.cache={tmp_path}/data", f"data.shape_class={TINY}", "data.n_shapes=6",
        "data.views_per_shape=2", "model.resolution=16", "model.width=4", "model.latent=8", "train.batch_size=4",
        "train.d_gate=null", *extra])


def _params(module):
    """Learnable parameters only (BatchNorm running statistics move on any training-mode forward)."""
    return {k: v.detach().clone() for k, v in module.named_parameters()}


def _changed(before, module):
    after = _params(module)
    return any(not torch.equal(before[k], after[k]) for k in before)


CASES = [
    ("closed_form", "ea", "reconstruction", "platonic", "nonsaturating"),
    ("closed_form", "vh", "reconstruction", "platonic", "nonsaturating"),
    ("mitsuba", "ao", "reconstruction", "platonic", "nonsaturating"),
    ("mitsuba", "ea", "generation", "platonic", "wgan-gp"),
    ("physical", "ea", "reconstruction", "platonic", "nonsaturating"),
    ("single_scatter", "ea", "generation", "platonic", "nonsaturating"),
    ("closed_form", "ea", "reconstruction", "platonic3d", "nonsaturating"),
    ("closed_form", "ea", "generation", "gan3d", "wgan-gp"),
]


@pytest.mark.parametrize("backend,model,task,mode,loss", CASES)
def test_one_step_changes_what_it_should(tmp_path, backend, model, task, mode, loss):
    formation = "ea" if backend in ("physical", "single_scatter") else model
    cfg = _cfg(tmp_path, f"render.backend={backend}", f"render.model={model}", f"data.formation={formation}",
               f"train.task={task}", f"train.mode={mode}", f"train.loss={loss}", "render.physical_spp=1",
               "render.max_depth=2")
    data = load_training_data(cfg, progress=False)
    trainer = Trainer(cfg, data, torch.device("cpu"))
    before = {k: _params(m) for k, m in trainer.nets.items()}
    out = trainer.step(0)
    assert all(np.isfinite(v) for v in out.values()), out
    changed = {k: _changed(before[k], m) for k, m in trainer.nets.items()}
    assert changed["G"]
    assert changed["E"] == (task == "reconstruction")
    assert changed["D"] == (mode != "gan3d")
    if mode != "platonic":
        assert changed["D3"]


def test_a_bf16_step_with_r1_and_the_pose_head_changes_every_network(tmp_path):
    """``model.precision: bf16`` through the marcher, with R1's double backward through D and the
    pose head's tilt: finite scalars, float32 weights, and E, G, D and P all move."""
    cfg = _cfg(tmp_path, "model.precision=bf16", "render.backend=mitsuba", "render.model=ea", "data.formation=ea",
               "train.task=reconstruction", "train.r1_weight=1.0", "train.pose=elevation", "train.pose_weight=1.0")
    trainer = Trainer(cfg, load_training_data(cfg, progress=False), torch.device("cpu"))
    before = {k: _params(m) for k, m in trainer.nets.items()}
    out = trainer.step(0)
    assert all(np.isfinite(v) for v in out.values()), out
    assert all(p.dtype == torch.float32 for m in trainer.nets.values() for p in m.parameters())
    assert {k: _changed(before[k], m) for k, m in trainer.nets.items()} == {k: True for k in trainer.nets}


def _colour_step(trainer, monkeypatch):
    """One step of ``trainer``, recording what E read (``x``) and wrote (``z``) and the colour G got
    first (``colour``); asserts finite scalars. Returns (what it saw, the parameters before)."""
    from mitsuba_platonic.networks import nets
    seen = {}

    def keep(module, inputs, output):                        # returns None: E's output stays as it is
        seen.setdefault("x", inputs[0].detach().clone())
        seen.setdefault("z", output.detach().clone())

    trainer.nets["E"].register_forward_hook(keep)
    original = nets.Generator.forward

    def spy(self, z, colour=None, offsets=False):
        seen.setdefault("colour", colour.detach().clone())
        return original(self, z, colour, offsets)

    monkeypatch.setattr(nets.Generator, "forward", spy)
    before = {k: _params(m) for k, m in trainer.nets.items()}
    out = trainer.step(0)
    assert all(np.isfinite(v) for v in out.values()), out
    return seen, before


def test_a_photo_colour_step_hands_g_the_mean_colour_of_es_own_input(tmp_path, monkeypatch):
    """``model.photo_colour``: in a step, G gets the mean colour of exactly the photos E read
    (after ``photo_augment``'s recolouring), and E, G and D all move."""
    from mitsuba_platonic.networks import photo_colours
    cfg = _cfg(tmp_path, "model.photo_colour=true", "render.backend=mitsuba", "render.model=ea", "data.formation=ea",
               "train.task=reconstruction", "train.photo_augment=[flip, colour]")
    trainer = Trainer(cfg, load_training_data(cfg, progress=False), torch.device("cpu"))
    seen, before = _colour_step(trainer, monkeypatch)
    assert torch.allclose(seen["colour"], photo_colours.photo_colour(seen["x"]))
    assert all(_changed(before[k], trainer.nets[k]) for k in ("E", "G", "D"))


def test_a_photo_texture_step_hands_g_the_texture_of_es_input_at_the_heads_elevation(tmp_path, monkeypatch):
    """``model.photo_texture`` with the pose head: in a step, G gets the colour per voxel of exactly
    the photos E read, as a camera at the elevation P reads from E's code sees them
    (:func:`~mitsuba_platonic.networks.photo_colours.photo_texture`), and E, G, D and P all move."""
    from mitsuba_platonic.networks import photo_colours
    cfg = _cfg(tmp_path, "model.photo_colour=true", "model.photo_texture=true", "render.backend=mitsuba",
               "render.model=ea", "data.formation=ea", "train.task=reconstruction", "train.pose=elevation",
               "train.pose_weight=1.0")
    trainer = Trainer(cfg, load_training_data(cfg, progress=False), torch.device("cpu"))
    with torch.no_grad():
        trainer.nets["P"].bias.fill_(0.3)                    # an elevation far from 0 from the first step
    seen, before = _colour_step(trainer, monkeypatch)
    with torch.no_grad():
        θ = _frozen_head(before["P"])(seen["z"])
    assert float(θ.abs().min()) > 0.4
    assert torch.allclose(seen["colour"], photo_colours.photo_texture(seen["x"], 16, θ), atol=1e-6)
    assert all(_changed(before[k], trainer.nets[k]) for k in ("E", "G", "D", "P"))


def _frozen_head(params):
    """A pose head with the given parameters (its weights before a step)."""
    from mitsuba_platonic.networks.nets import PoseHead
    head = PoseHead(params["weight"].shape[0])
    head.load_state_dict(params)
    return head


def _input_view_error(trainer, batch, distance, channels="all"):
    """The reconstruction error computed here, not by the trainer: render G(E(x)) from the input
    view with the Mitsuba ray marcher (the trainer renders with the closed form) and take the mean
    squared ('l2') or absolute ('l1') difference from x. Training mode, so BatchNorm normalises this
    batch as it does in a step."""
    from mitsuba_platonic import render
    from mitsuba_platonic.views import front_view
    trainer.nets.train()
    with torch.no_grad():
        v = trainer.nets["G"](trainer.nets["E"](batch))
        rec = render(v, front_view(len(batch)), trainer.cfg.render.model, "mitsuba")
    if channels == "alpha":                                  # the opacity alone
        rec, batch = rec[:, 3:], batch[:, 3:]
    return float(((rec - batch) ** 2).mean() if distance == "l2" else (rec - batch).abs().mean())


@pytest.mark.parametrize("distance, channels", [("l2", "all"), ("l1", "all"), ("l2", "alpha")])
def test_reconstruction_steps_lower_the_input_view_error(tmp_path, distance, channels):
    """On a fixed batch (one image, drawn twice) with the reconstruction term dominating
    (rec_weight 100; lr 1e-2 so that the normalisation-free default networks move within a few
    steps): every step's logged loss_rec is the input-view error in ``train.rec_loss``'s distance
    measured independently before that step (with ``rec_channels: alpha`` on the opacity alone),
    and 8 steps lower it by more than 20 % (MSE 0.266 → 0.13)."""
    cfg = _cfg(tmp_path, "data.n_shapes=1", "data.views_per_shape=1", "train.batch_size=2",
               "train.task=reconstruction", "train.rec_weight=100", "train.lr_g=1e-2", "train.lr_e=1e-2",
               "render.backend=closed_form", "render.model=ea", "data.formation=ea", f"train.rec_loss={distance}",
               f"train.rec_channels={channels}")
    trainer = Trainer(cfg, load_training_data(cfg, progress=False), torch.device("cpu"))
    assert len(trainer.images) == 1
    batch = trainer.images.expand(2, -1, -1, -1)
    measured = [_input_view_error(trainer, batch, distance, channels)]
    for step in range(8):
        out = trainer.step(step)
        assert out["loss_rec"] == pytest.approx(measured[-1], rel=1e-3), (step, out["loss_rec"], measured)
        measured.append(_input_view_error(trainer, batch, distance, channels))
    assert measured[-1] < 0.8 * measured[0], measured


def test_rec_loss_is_refused_unless_it_is_known_and_compares_images(tmp_path):
    from mitsuba_platonic.settings_checks import ConfigError
    with pytest.raises(ConfigError, match=r"^train\.rec_loss: .*'l1'"):
        _cfg(tmp_path, "train.rec_loss=huber")
    with pytest.raises(ConfigError, match=r"^train\.rec_loss: 'l1' applies to the input-view image term"):
        _cfg(tmp_path, "train.mode=platonic3d", "train.rec_target=volume", "train.rec_loss=l1",
             "train.task=reconstruction")
    with pytest.raises(ConfigError, match=r"^train\.rec_channels: .*'alpha'"):
        _cfg(tmp_path, "train.rec_channels=rgb")
    with pytest.raises(ConfigError, match=r"^train\.rec_channels: 'alpha' applies to the input-view image term"):
        _cfg(tmp_path, "train.mode=platonic3d", "train.rec_target=volume", "train.rec_channels=alpha",
             "train.task=reconstruction")


def test_d_step_lowers_d_loss_on_its_batch(tmp_path):
    """D's non-saturating loss −log σ(D(x)) − log(1 − σ(D(I_view))), computed here on the very
    images D saw in its update (recorded by a forward hook; real = rows of the data set), is lower
    after the step than before it, and the logged loss_d is the value before."""
    import copy

    import torch.nn.functional as F
    cfg = _cfg(tmp_path, "train.loss=nonsaturating", "train.lr_d=2e-4")
    trainer = Trainer(cfg, load_training_data(cfg, progress=False), torch.device("cpu"))
    D = trainer.nets["D"]
    before = copy.deepcopy(D)
    seen = []
    hook = D.register_forward_hook(lambda module, inputs, output: seen.append(inputs[0].detach().clone()))
    try:
        out = trainer.step(0)
    finally:
        hook.remove()
    # D's update runs reals and fakes through one forward pass (no BatchNorm here): its first call
    is_real = [any(torch.equal(row, im) for im in trainer.images) for row in seen[0]]
    real = [seen[0][torch.tensor(is_real)]]
    fake = [seen[0][~torch.tensor(is_real)]]
    assert len(real[0]) and len(fake[0])

    def loss(net):
        net.train()                                          # BatchNorm on each batch, as in the step
        with torch.no_grad():
            return float(sum(-F.logsigmoid(net(b)).mean() for b in real) / len(real)
                         + sum(-F.logsigmoid(-net(b)).mean() for b in fake) / len(fake))

    l_before, l_after = loss(before), loss(D)
    assert out["loss_d"] == pytest.approx(l_before, rel=1e-5)
    assert l_after < l_before - 1e-5, (l_before, l_after)    # ≈ 2e-4 lower at lr 2e-4


def test_d_step_leaves_g_alone_and_g_step_leaves_d_alone(tmp_path, monkeypatch):
    cfg = _cfg(tmp_path)
    trainer = Trainer(cfg, load_training_data(cfg, progress=False), torch.device("cpu"))
    g0, d0, e0 = _params(trainer.nets["G"]), _params(trainer.nets["D"]), _params(trainer.nets["E"])
    monkeypatch.setattr(trainer.opt_g, "step", lambda *a, **k: None)         # only D's update happens
    trainer.step(0)
    assert _changed(d0, trainer.nets["D"])
    assert not _changed(g0, trainer.nets["G"]) and not _changed(e0, trainer.nets["E"])
    monkeypatch.undo()
    trainer = Trainer(cfg, load_training_data(cfg, progress=False), torch.device("cpu"))
    d0 = _params(trainer.nets["D"])
    monkeypatch.setattr(trainer.opt_d, "step", lambda *a, **k: None)         # only G's update happens
    trainer.step(0)
    assert not _changed(d0, trainer.nets["D"])


def test_discriminator_gate(tmp_path):
    cfg = _cfg(tmp_path, "train.d_gate=0.01")                # D is never that bad: never updated
    trainer = Trainer(cfg, load_training_data(cfg, progress=False), torch.device("cpu"))
    d0 = _params(trainer.nets["D"])
    out = trainer.step(0)
    assert out["d_updated"] == 0.0 and not _changed(d0, trainer.nets["D"])


def test_resume_matches_an_uninterrupted_run(tmp_path):
    straight = R.train(_cfg(tmp_path / "a", "run.steps=6"), progress=False)
    cfg_b = _cfg(tmp_path / "b", "run.steps=6")
    R.train(cfg_b, progress=False, stop_at=3)
    assert R.load_checkpoint(Path(cfg_b.run.out_dir) / "r" / "checkpoints" / "last.pt")["step"] == 3
    resumed = R.train(cfg_b, resume=True, progress=False)
    a = R.load_checkpoint(straight / "checkpoints" / "last.pt")
    b = R.load_checkpoint(resumed / "checkpoints" / "last.pt")
    assert a["step"] == b["step"] == 6
    for k, v in a["trainer"]["nets"].items():
        assert torch.equal(v, b["trainer"]["nets"][k]), k
    rows_a = (straight / "scalars.csv").read_text().splitlines()
    rows_b = (resumed / "scalars.csv").read_text().splitlines()
    assert rows_a[0] == rows_b[0] and len(rows_a) == len(rows_b) == 7
    assert [r.split(",")[:5] for r in rows_a] == [r.split(",")[:5] for r in rows_b]   # same losses
    assert (resumed / "samples" / "step_0000006.png").exists()
    assert (resumed / "samples" / "turntable_0000006.gif").exists()
    assert list((resumed / "tb").iterdir())


def test_a_kill_while_writing_a_checkpoint_leaves_the_last_one_loadable(tmp_path, monkeypatch):
    run_dir = R.train(_cfg(tmp_path, "run.steps=2"), progress=False)
    last = run_dir / "checkpoints" / "last.pt"
    good = R.load_checkpoint(last)

    def dying_save(obj, f, *a, **k):
        f.write(b"PK\x03\x04 half a checkpoint")
        raise KeyboardInterrupt("killed mid-write")

    monkeypatch.setattr(torch, "save", dying_save)
    with pytest.raises(KeyboardInterrupt):
        R.save_checkpoint(last, {"step": 99})
    monkeypatch.undo()
    again = R.load_checkpoint(last)
    assert again["step"] == good["step"] == 2
    assert not [p for p in last.parent.iterdir() if p.name.startswith(".")]


def test_existing_run_needs_resume_and_same_settings(tmp_path):
    R.train(_cfg(tmp_path, "run.steps=2"), progress=False)
    with pytest.raises(R.RunError, match="--resume"):
        R.train(_cfg(tmp_path, "run.steps=2"), progress=False)
    with pytest.raises(R.RunError, match="train settings differ"):
        R.train(_cfg(tmp_path, "run.steps=3", "train.rec_weight=1.0"), resume=True, progress=False)
    with pytest.raises(R.RunError, match="no checkpoint"):
        R.train(_cfg(tmp_path / "other", "run.steps=2"), resume=True, progress=False)


def test_ctrl_c_saves_and_ends_by_sigint(tmp_path):
    cfg_file = tmp_path / "c.yaml"
    cfg_file.write_text(f"""
run: {{out_dir: {tmp_path}/runs, name: r, steps: 100000, log_every: 1, sample_every: 100000, checkpoint_every: 100000}}
data: {{cache: {tmp_path}/data, shape_class: mushroom, n_shapes: 4, views_per_shape: 1}}
model: {{resolution: 16, width: 4, latent: 8}}
train: {{batch_size: 2}}
""")
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    p = subprocess.Popen([sys.executable, "-m", "mitsuba_platonic.cli", "train", "--config", str(cfg_file), "--quiet"],
                         stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=env, text=True)
    csv = tmp_path / "runs" / "r" / "tb"
    deadline = time.time() + 240
    while not csv.exists() and time.time() < deadline and p.poll() is None:
        time.sleep(0.5)
    time.sleep(2.0)                                          # a few steps in
    p.send_signal(signal.SIGINT)
    out, _ = p.communicate(timeout=240)
    assert p.returncode == -signal.SIGINT, out               # dies by it (a shell: 130): the script stops (issues 29, 46)
    state = R.load_checkpoint(tmp_path / "runs" / "r" / "checkpoints" / "last.pt")
    assert 0 < state["step"] < 100000
    line = out.strip().splitlines()[-1]
    assert line.startswith("platonic train: interrupted: after step ") and "Traceback" not in out, out
    assert f"holds step {state['step']}" in line and "--resume" in line, line


def _ddp_worker(rank, world, port, cfg_overrides, tmp, result_file):
    os.environ.update(MASTER_ADDR="127.0.0.1", MASTER_PORT=str(port), WORLD_SIZE=str(world), RANK=str(rank),
                      LOCAL_RANK=str(rank))
    import torch.distributed as dist
    dist.init_process_group("gloo", rank=rank, world_size=world)
    torch.set_num_threads(1)
    cfg = _cfg(Path(tmp), *cfg_overrides)
    with shapes.registered(TINY, _blob):
        data = load_training_data(cfg, progress=False)
        trainer = Trainer(cfg, data, torch.device("cpu"), rank, world)
        for step in range(2):
            trainer.step(step)
    if rank == 0:
        torch.save(trainer.nets.state_dict(), result_file)
    dist.barrier()
    dist.destroy_process_group()
    # leave without running C++ destructors: a thread pool torn down at interpreter exit has been
    # seen to abort ("terminate called without an active exception") after the work was done
    sys.stdout.flush()
    os._exit(0)


PHOTO_TERMS = ["train.pose=elevation", "train.pose_weight=1.0", "model.photo_colour=true", "model.photo_texture=true",
               "model.texture_conv=true", "train.colour_offset=0.1", "train.colour_match=1.0"]


@pytest.mark.parametrize("pose", [[], ["train.pose=elevation", "train.pose_weight=1.0"], PHOTO_TERMS],
                         ids=["input", "elevation", "photo_terms"])
def test_two_processes_with_half_the_batch_make_the_single_process_update(tmp_path, pose):
    """gloo, 2 processes, no batch-statistics layers (norm: none): same parameters after 2 steps,
    also with the pose head, which E's and P's second forward pass (G's renders) reaches, and
    with the photo config's terms (the texture read at P's elevation and its convolution, the colour
    priors)."""
    import torch.multiprocessing as mp
    overrides = ["model.norm=none", "train.batch_size=4", "train.task=reconstruction", *pose]
    cfg = _cfg(tmp_path, *overrides)
    load_training_data(cfg, progress=False)                  # render the collection once, up front
    single = Trainer(cfg, load_training_data(cfg, progress=False), torch.device("cpu"))
    for step in range(2):
        single.step(step)
    import socket
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    result = tmp_path / "ddp.pt"
    mp.spawn(_ddp_worker, args=(2, port, overrides, str(tmp_path), str(result)), nprocs=2, join=True)
    ddp = torch.load(result)
    for k, v in single.nets.state_dict().items():
        assert torch.allclose(v, ddp[k], atol=1e-5, rtol=1e-4), k


def test_cli_train_reconstruct_generate(tmp_path):
    from mitsuba_platonic.cli import main
    args = [f"run.out_dir={tmp_path}/runs", "run.name=c", "run.steps=2", f"data.cache={tmp_path}/data",
            "data.shape_class=mushroom", "data.n_shapes=4", "data.views_per_shape=1", "model.resolution=16",
            "model.width=4", "model.latent=8", "train.batch_size=2"]
    assert main(["train", "--quiet"] + sum((["--set", a] for a in args), [])) == 0
    run_dir = tmp_path / "runs" / "c"
    img = next((Path(load_config(None, args).data.cache)).glob("*/images/*.png"))
    assert main(["reconstruct", "--run", str(run_dir), str(img), "--out", str(tmp_path / "rec"), "--level", "0.3"]) == 0
    stem = tmp_path / "rec" / img.stem
    assert stem.with_suffix(".npz").exists() and stem.with_suffix(".vol").exists() and stem.with_suffix(".gif").exists()
    assert main(["generate", "--run", str(run_dir), "-n", "2", "--out", str(tmp_path / "gen")]) == 0
    assert (tmp_path / "gen" / "samples.png").exists() and (tmp_path / "gen" / "sample_001.gif").exists()
    assert main(["train", "--set", "train.batch_size=eight"]) == 2
    assert main(["reconstruct", "--run", str(tmp_path / "nope"), str(img)]) == 2


TREE = Path(__file__).resolve().parents[2] / "shared" / "data" / "tree"


@pytest.mark.skipif(not TREE.is_dir(), reason="../shared/data/tree is absent")
def test_photo_collection_config_trains(tmp_path):
    cfg = load_config(Path(__file__).resolve().parents[1] / "configs" / "photos_tree_ea.yaml",
                      [f"data.path={TREE}", "model.resolution=16", "model.width=4", "model.latent=8"])
    data = load_training_data(cfg, progress=False)
    assert data.images.shape == (26, 4, 16, 16) and data.held_out.shape == (6, 4, 16, 16)
    trainer = Trainer(cfg, data, torch.device("cpu"))
    before = _params(trainer.nets["G"])
    trainer.step(0)
    assert _changed(before, trainer.nets["G"])


@pytest.mark.parametrize("overrides, expected", [
    (["render.backend=mitsuba", "model.resolution=32"], 1),             # auto: launches on the training thread
    (["render.backend=mitsuba", "model.resolution=64"], None),          # auto: the pool as it is
    (["render.backend=mitsuba", "model.resolution=64", "run.threads=1"], 1),
    (["render.backend=closed_form", "run.drjit_threads=3"], None),      # no Dr.Jit in the closed form
    (["render.backend=physical", "model.resolution=32"], None),         # long launches: every core
    (["render.backend=mitsuba", "model.resolution=32", "run.drjit_threads=2"], 2),
])
def test_drjit_threads_follow_the_rule_of_docs_training(overrides, expected):
    assert R.drjit_threads(load_config(None, overrides)) == expected


def test_training_threads_are_restored_after_the_run_even_on_an_error():
    import drjit as dr
    cfg = load_config(None, ["render.backend=mitsuba", "model.resolution=32", "run.threads=1"])
    saved = torch.get_num_threads(), dr.thread_count()
    try:
        torch.set_num_threads(2)
        dr.set_thread_count(2)
        with pytest.raises(RuntimeError, match="inside"):
            with R.training_threads(cfg):
                assert (torch.get_num_threads(), dr.thread_count()) == (1, 1)
                raise RuntimeError("inside")
        assert (torch.get_num_threads(), dr.thread_count()) == (2, 2)
    finally:
        torch.set_num_threads(saved[0])
        dr.set_thread_count(saved[1])


def test_a_batch_larger_than_the_training_images_is_warned_with_the_counts(tmp_path):
    """6 shapes × 2 views, split 0.8: 10 training images; a batch of 25 draws each about 2.5 times."""
    with pytest.warns(UserWarning) as caught:
        R.train(_cfg(tmp_path, "run.steps=1", "train.batch_size=25"), progress=False)
    lines = [str(w.message) for w in caught if str(w.message).startswith("train.batch_size:")]
    assert lines == ["train.batch_size: 25 is more than the 10 training images; a step draws its batch with "
                     "replacement, so each image comes about 2.5 times in every batch (under other random views), "
                     "at the cost of 2.5 batches of 10; expected at most 10 (or add images)"], lines


def test_a_batch_within_the_training_images_is_not_warned(tmp_path):
    import warnings

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        R.train(_cfg(tmp_path, "run.steps=1", "train.batch_size=10"), progress=False)
    assert not [w for w in caught if "train.batch_size" in str(w.message)]
