"""An output folder the user made is not overwritten (issues 46, 60): ``evaluate``, ``quickstart`` (and
``--photos``), ``compare`` and ``bench`` write into a new or empty ``--out``, or one they made before (marked by
``platonic.json``; a quickstart continues there); any other folder that holds something is refused
with one line, nothing in it changed, unless ``--overwrite``. One command at a time writes into an
``--out`` (``platonic.lock``): a second is refused with one line naming the first. And ``~`` in the
config's paths means the home folder, never a folder literally named ``~``."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest

from mitsuba_platonic.config import load_config
from mitsuba_platonic.errors import Interrupted
from mitsuba_platonic.evaluate import report as E
from mitsuba_platonic.files.outputs import LOCK, MARKER, made_by, output_lock
from cli_runner import one_line, run_cli
from tiny_shapes import TINY


def _snapshot(folder: Path):
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _users_folder(folder: Path, name: str) -> None:
    folder.mkdir(parents=True)
    (folder / name).write_text("# my own notes\nline two\n")
    (folder / "notes.txt").write_text("keep\n")


def _refused(stderr: str, command: str, out: Path) -> None:
    err = one_line(stderr, command, "error")
    assert f"--out {out}" in err and "--overwrite" in err and "did not write" in err, err


# --------------------------------------------------------------------------- evaluate


@pytest.fixture
def scored(monkeypatch):
    """evaluate with its scoring replaced by one synthetic row: what it writes, and where, is real."""
    calls = []

    def scoring(*args):
        calls.append(args)
        return [E.Row("run (platonic, step 1)", "EA", pairs=[{"iou": 1.0}])], ["synthetic"], [], []   # rows, notes, photo and generation sections

    monkeypatch.setattr(E, "_evaluate_runs", scoring)
    return calls


def test_evaluate_refuses_a_users_folder_and_overwrites_only_when_asked(tmp_path, scored):
    out = tmp_path / "eval"
    _users_folder(out, "report.md")
    before = _snapshot(out)
    code, _, stderr = run_cli(["evaluate", "--run", "r", "--out", str(out), "--quiet"])
    assert code == 2
    _refused(stderr, "evaluate", out)
    assert _snapshot(out) == before and not scored                   # refused before any scoring
    code, stdout, stderr = run_cli(["evaluate", "--run", "r", "--out", str(out), "--quiet", "--overwrite"])
    assert code == 0, stderr
    assert (out / "report.md").read_text().startswith("# Evaluation") and (out / "notes.txt").read_text() == "keep\n"
    assert made_by(out) == "platonic evaluate"
    code, _, stderr = run_cli(["evaluate", "--run", "r", "--out", str(out), "--quiet"])   # its own: redone in place
    assert code == 0, stderr


def test_evaluate_into_a_new_folder_marks_it_and_an_earlier_unmarked_evaluation_is_its_own(tmp_path, scored):
    out = tmp_path / "eval"
    assert run_cli(["evaluate", "--run", "r", "--out", str(out), "--quiet"])[0] == 0
    assert json.loads((out / MARKER).read_text())["written_by"] == "platonic evaluate"
    (out / MARKER).unlink()                                           # as written before the marker existed
    code, _, stderr = run_cli(["evaluate", "--run", "r", "--out", str(out), "--quiet"])
    assert code == 0, stderr


def test_evaluate_with_a_bad_run_leaves_no_new_folder(tmp_path):
    out = tmp_path / "eval"
    code, _, stderr = run_cli(["evaluate", "--run", str(tmp_path / "missing"), "--out", str(out), "--quiet"])
    assert code == 2 and not out.exists(), stderr


# --------------------------------------------------------------------------- quickstart


@pytest.fixture
def stopped_training(monkeypatch):
    """The quickstart with its data and training replaced: training stops with a Ctrl-C at step 7,
    so the test sees where it was allowed to start (exit 130) and where it was refused (exit 2)."""
    from mitsuba_platonic.quickstart import procedural as Q
    from mitsuba_platonic.train import data as D
    from mitsuba_platonic.train import run as R

    trained = []
    monkeypatch.setattr(D, "load_training_data", lambda cfg, progress=True: SimpleNamespace(held_out=[], images=[]))
    monkeypatch.setattr(Q, "held_out_scores", lambda model, data: {})
    monkeypatch.setattr(Q, "Model", SimpleNamespace(from_config=lambda cfg: "untrained"))

    def train(cfg, resume=False, progress=True):
        trained.append(resume)
        raise Interrupted("after step 7 of 400", saved="last.pt holds step 7")

    monkeypatch.setattr(R, "train", train)
    return trained


def test_quickstart_refuses_a_users_folder_unless_overwrite(tmp_path, stopped_training):
    out = tmp_path / "qs"
    _users_folder(out, "report.md")
    before = _snapshot(out)
    code, _, stderr = run_cli(["quickstart", "--out", str(out), "--quiet"])
    assert code == 2
    _refused(stderr, "quickstart", out)
    assert _snapshot(out) == before and not stopped_training
    code, _, stderr = run_cli(["quickstart", "--out", str(out), "--quiet", "--overwrite"])
    assert code == 130 and stopped_training == [False], stderr
    assert made_by(out) == "platonic quickstart"


def test_quickstart_continues_in_its_own_folder(tmp_path, stopped_training):
    out = tmp_path / "qs"
    for _ in range(2):                                                # new, then its own (marked)
        code, _, stderr = run_cli(["quickstart", "--out", str(out), "--quiet"])
        assert code == 130, stderr
    assert made_by(out) == "platonic quickstart"
    legacy = tmp_path / "old"                                         # from before the marker: its run folder says so
    (legacy / "run").mkdir(parents=True)
    (legacy / "run" / "run.json").write_text("{}\n")
    (legacy / "report.md").write_text("# mitsuba-platonic quickstart report\n")
    code, _, stderr = run_cli(["quickstart", "--out", str(legacy), "--quiet"])
    assert code == 130, stderr
    assert len(stopped_training) == 3


def test_photo_quickstart_refuses_a_users_folder(tmp_path, stopped_training):
    from test_links import _photo_folder

    out = tmp_path / "qp"
    _users_folder(out, "report.md")
    before = _snapshot(out)
    code, _, stderr = run_cli(["quickstart", "--photos", str(_photo_folder(tmp_path)), "--out", str(out), "--quiet",
                               "--set", "model.resolution=16"])
    assert code == 2
    _refused(stderr, "quickstart", out)
    assert _snapshot(out) == before and not stopped_training


# --------------------------------------------------------------------------- compare


def _compare(out: Path, *extra: str):
    return run_cli(["compare", "--resolution", "8", "--views", "1", "--repeats", "1", "--models", "vh",
                    "--out", str(out), *extra])


def test_compare_refuses_a_users_compare_json_and_redoes_its_own(tmp_path):
    out = tmp_path / "cmp"
    _users_folder(out, "compare.json")
    before = _snapshot(out)
    code, _, stderr = _compare(out)
    assert code == 2
    _refused(stderr, "compare", out)
    assert _snapshot(out) == before
    code, _, stderr = _compare(out, "--overwrite")
    assert code == 0, stderr
    assert json.loads((out / "compare.json").read_text())["results"][0]["model"] == "vh"
    assert (out / "notes.txt").read_text() == "keep\n"
    code, _, stderr = _compare(out)                                    # its own: redone in place
    assert code == 0, stderr


# --------------------------------------------------------------------------- bench


@pytest.fixture
def benched(monkeypatch):
    """bench with its measurements replaced by an empty result: what it writes, and where, is real."""
    import mitsuba_platonic.bench as B
    from mitsuba_platonic.bench import report

    calls = []

    def run_bench(settings, log=print):
        calls.append(settings)
        return {"meta": {"settings": {"batch": 2}}, "views": {}, "rows": [], "train": []}

    monkeypatch.setattr(B, "run_bench", run_bench)
    monkeypatch.setattr(report, "markdown_tables", lambda result, plot_dir=None: "(tables)")
    return calls


def _bench(out: Path, *extra: str):
    return run_cli(["bench", "--quick", "--resolutions", "16", "--out", str(out), *extra])


def test_bench_refuses_a_users_folder_and_overwrites_only_when_asked(tmp_path, benched):
    out = tmp_path / "b"
    _users_folder(out, "bench.md")
    before = _snapshot(out)
    code, _, stderr = _bench(out)
    assert code == 2
    _refused(stderr, "bench", out)
    assert _snapshot(out) == before and not benched                  # refused before any measurement
    code, _, stderr = _bench(out, "--overwrite")
    assert code == 0, stderr
    assert (out / "bench.md").read_text().startswith("# platonic bench") and (out / "notes.txt").read_text() == "keep\n"
    assert made_by(out) == "platonic bench" and not (out / LOCK).exists()
    code, _, stderr = _bench(out)                                      # its own: redone in place
    assert code == 0 and len(benched) == 2, stderr


@pytest.mark.parametrize("where", ["bench.md", "out"])
def test_bench_writes_nothing_through_a_link(tmp_path, benched, where):
    """``--out``'s ``bench.md`` a link to a user's file: refused, naming the link; ``--out`` itself a link
    to a user's folder: refused as that folder is (it holds their files); the targets as they were."""
    outside = tmp_path / "outside"
    _users_folder(outside, "bench.md")
    before = _snapshot(outside)
    out = tmp_path / "b"
    if where == "out":
        out.symlink_to(outside)
    else:
        out.mkdir()
        (out / "bench.md").symlink_to(outside / "bench.md")
    code, _, stderr = _bench(out, *(["--overwrite"] if where == "bench.md" else []))
    assert code == 2 and not benched
    err = one_line(stderr, "bench", "error")
    assert (f"{out / 'bench.md'} is a symbolic link" in err) if where == "bench.md" else ("did not write" in err), err
    assert _snapshot(outside) == before


_HOLD = """
import sys, time
from mitsuba_platonic.files.outputs import output_lock
with output_lock(sys.argv[1], sys.argv[2]):
    print("held", flush=True)
    time.sleep(600)
"""


def test_a_second_evaluate_into_the_same_out_is_refused_naming_the_first(tmp_path, scored):
    """Two evaluations into one ``--out`` at once would mix their reports: the second is refused
    before any scoring, with one line naming the first's pid; once it has ended the folder is free."""
    out = tmp_path / "eval"
    holder = subprocess.Popen([sys.executable, "-c", _HOLD, str(out), "evaluate"], stdout=subprocess.PIPE, text=True,
                              stdin=subprocess.DEVNULL)
    try:
        assert holder.stdout.readline().strip() == "held"
        code, _, stderr = run_cli(["evaluate", "--run", "r", "--out", str(out), "--quiet"])
        assert code == 2 and not scored, stderr
        err = one_line(stderr, "evaluate", "error")
        assert f"--out {out} is in use" in err and f"pid {holder.pid}, platonic evaluate" in err, err
        assert not (out / "report.md").exists()
    finally:
        holder.kill()
        holder.wait()
    code, _, stderr = run_cli(["evaluate", "--run", "r", "--out", str(out), "--quiet"])
    assert code == 0 and len(scored) == 1, stderr
    assert not (out / LOCK).exists()                                  # released at the end


@pytest.mark.parametrize("command", ["bench", "compare", "quickstart"])
def test_every_output_folder_command_takes_the_lock(tmp_path, benched, stopped_training, command):
    out = tmp_path / "o"
    argv = {"bench": ["bench", "--quick", "--resolutions", "16"],
            "compare": ["compare", "--resolution", "8", "--views", "1", "--repeats", "1", "--models", "vh"],
            "quickstart": ["quickstart", "--quiet"]}[command]
    with output_lock(out, "evaluate"):
        code, _, stderr = run_cli([*argv, "--out", str(out)])
        assert code == 2, stderr
        assert f"pid {os.getpid()}, platonic evaluate" in one_line(stderr, command, "error")
        assert sorted(p.name for p in out.iterdir()) == [LOCK] and not benched and not stopped_training
    assert not out.exists()                                           # made for the lock alone: removed again


def test_make_dataset_preview_takes_the_lock(tmp_path, tiny_class):
    """Contact sheets into an ``--out`` another command is writing: refused in one line naming it,
    no sheet written; with the folder free they are written and the lock is gone."""
    out = tmp_path / "o"
    argv = ["make-dataset", "--preview", "--class", TINY, "--preview-shapes", "1", "--resolution", "16",
            "--out", str(out)]
    with output_lock(out, "evaluate"):
        code, _, stderr = run_cli(argv)
        assert code == 2, stderr
        err = one_line(stderr, "make-dataset", "error")
        assert err == (f"platonic make-dataset: error: --out {out} is in use by another command (pid {os.getpid()}, "
                       f"platonic evaluate; lock {out / LOCK}); nothing was written: wait for it to end, or choose "
                       f"another --out"), err
        assert sorted(p.name for p in out.iterdir()) == [LOCK]
    code, _, stderr = run_cli(argv)
    assert code == 0, stderr
    assert sorted(p.name for p in out.iterdir()) == [f"preview_{TINY}.png"]


# --------------------------------------------------------------------------- ~ in the config


def test_a_tilde_in_the_configs_paths_is_the_home_folder(tmp_path, monkeypatch):
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    cfg = load_config(None, ["run.out_dir=~/runs", "data.cache=~/data", "data.source=folder", "data.path=~/photos"])
    assert cfg.run.out_dir == str(tmp_path / "home" / "runs")
    assert cfg.data.cache == str(tmp_path / "home" / "data")
    assert cfg.data.path == str(tmp_path / "home" / "photos")
    assert load_config(None, ["run.out_dir=runs/~x"]).run.out_dir == "runs/~x"   # only a leading ~ is home
