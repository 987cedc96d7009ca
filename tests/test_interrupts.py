"""An interrupt never reports success (issue 29): every Ctrl-C exits 130 with one line on stderr
saying what was saved and how to go on, in every command and at any moment (the start-up's
imports included); the quickstart stops instead of evaluating a half-trained model;
reconstruct and generate say how many files they wrote."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest

from mitsuba_platonic import cli
from mitsuba_platonic.config import load_config
from mitsuba_platonic.errors import Interrupted
from mitsuba_platonic.train import run as R
from cli_runner import one_line, run_cli
from tiny_shapes import tiny_run_overrides


def _interrupted_line(stderr: str, command: str) -> str:
    err = one_line(stderr, command, "interrupted")
    return err


# --------------------------------------------------------------------------- the first second


_IMPORT_INTERRUPT = """
import sys
class Interrupt:                      # a Ctrl-C while {module} loads
    def find_spec(self, name, path=None, target=None):
        if name == {module!r}:
            raise KeyboardInterrupt
        return None
sys.meta_path.insert(0, Interrupt())
from mitsuba_platonic.cli import main
sys.exit(main({argv!r}))
"""


@pytest.mark.parametrize("module, argv", [
    ("numpy", ["compare", "--resolution", "8"]),
    ("torch", ["make-dataset", "--help"]),
    ("yaml", ["train", "--quiet"]),
])
def test_ctrl_c_while_the_start_up_imports_is_one_line(tmp_path, module, argv):
    r = subprocess.run([sys.executable, "-c", _IMPORT_INTERRUPT.format(module=module, argv=argv)],
                       capture_output=True, text=True, timeout=300, stdin=subprocess.DEVNULL, cwd=tmp_path)
    assert r.returncode == 130, r.stderr
    err = r.stderr.strip()
    assert "\n" not in err and "Traceback" not in err, err
    assert err.startswith("platonic") and "interrupted" in err and ("nothing" in err or "again" in err), err


def test_importing_the_package_loads_no_numpy_torch_or_drjit():
    code = "import sys, mitsuba_platonic.cli; print(sorted(m for m in ('numpy', 'torch', 'drjit') if m in sys.modules))"
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.stdout.strip() == "[]", r.stdout + r.stderr


def test_an_interrupt_dr_jit_wrapped_in_its_own_error_is_still_an_interrupt(monkeypatch):
    """Dr.Jit re-raises a Ctrl-C in its callbacks as a RuntimeError, the interrupt in the chain."""
    def handler(args):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as e:
            raise RuntimeError("drjit.eval(): a Python callback raised") from e

    parser = cli.build_parser()
    monkeypatch.setattr(cli, "build_parser", lambda: parser)
    parser._subparsers._group_actions[0].choices["evaluate"].set_defaults(handler=handler)
    code, stdout, stderr = run_cli(["evaluate", "--run", "r", "--out", "o"])
    assert code == 130
    err = _interrupted_line(stderr, "evaluate")
    assert "no report was written" in err and "again" in err, err


# --------------------------------------------------------------------------- the quickstart stops


def test_the_quickstart_stops_when_training_is_interrupted(tmp_path, monkeypatch):
    from mitsuba_platonic.quickstart import procedural as Q
    from mitsuba_platonic.train import data as D

    evaluated = []
    monkeypatch.setattr(D, "load_training_data", lambda cfg, progress=True: SimpleNamespace(held_out=[], images=[]))
    monkeypatch.setattr(Q, "held_out_scores", lambda model, data: evaluated.append(model) or {})
    monkeypatch.setattr(Q, "Model", SimpleNamespace(from_config=lambda cfg: "untrained",
                                                    from_checkpoint=lambda run: evaluated.append(run)))

    def train(cfg, resume=False, progress=True):
        raise Interrupted("after step 7 of 400: last.pt holds step 7; continue with --resume",
                          saved="runs/quickstart/checkpoints/last.pt holds step 7")

    monkeypatch.setattr(R, "train", train)
    out = tmp_path / "qs"
    code, stdout, stderr = run_cli(["quickstart", "--out", str(out), "--quiet"])
    assert code == 130, stderr
    err = _interrupted_line(stderr, "quickstart")
    assert "while training" in err and "holds step 7" in err and f"platonic quickstart --out {out}" in err, err
    assert evaluated == ["untrained"]                                # the half-trained model is not evaluated
    assert not (out / "report.md").exists() and stdout == ""


# --------------------------------------------------------------------------- reconstruct / generate count their files


def _overrides(out: Path, data: Path, *extra):
    return tiny_run_overrides(out, data, *extra)


@pytest.fixture(scope="module")
def run(tmp_path_factory, tiny_class):
    root = tmp_path_factory.mktemp("run")
    R.train(load_config(None, _overrides(root / "runs", root / "data")), progress=False)
    return root / "runs" / "r", root / "data"


def test_ctrl_c_in_reconstruct_says_how_many_files_were_written(run, tmp_path, monkeypatch):
    from mitsuba_platonic import export as E

    photo = tmp_path / "x.png"
    photo.write_bytes(sorted(run[1].glob("*/images/*.png"))[0].read_bytes())
    real, calls = E.save_gif, []

    def save_gif(*a, **k):                                          # Ctrl-C while the 2nd input's GIF is made
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(*a, **k)

    monkeypatch.setattr(E, "save_gif", save_gif)
    out = tmp_path / "rec"
    code, stdout, stderr = run_cli(["reconstruct", "--run", str(run[0]), str(photo), str(photo), "--out", str(out)])
    assert code == 130
    notes, last = stderr.strip().splitlines()[:-1], stderr.strip().splitlines()[-1]
    assert all(n.endswith("no surface to extract") for n in notes), notes     # "no mesh" notes, per input
    err = _interrupted_line(last, "reconstruct")
    on_disk = sorted(p.name for p in out.iterdir())
    assert {"x.npz", "x.vol", "x.gif", "x_2.npz", "x_2.vol"} <= set(on_disk), on_disk   # (x.ply if a surface)
    assert f"{len(on_disk)} complete file(s)" in err and "1 of 2 input(s)" in err and str(out) in err, err
    assert not any(p.startswith(".") for p in on_disk)              # no temporary left
