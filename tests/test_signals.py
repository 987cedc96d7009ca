"""SIGTERM stops a command as Ctrl-C does, and a signal ends the process by that signal (issue 46).

``kill``, ``timeout``, Slurm, systemd and container runtimes send SIGTERM: training saves a checkpoint
and prints one line, as on Ctrl-C, and then the process dies by the signal (a shell sees 143 or
130), so that a script around it (``platonic train ...; platonic evaluate ...``) stops too. A
second Ctrl-C while the first is handled, and a Ctrl-C while the console script loads, are one
line and no traceback."""

from __future__ import annotations

import os
import shlex
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from mitsuba_platonic.files.checkpoint import read_checkpoint

#: A training that runs far longer than the test and writes a sample after every step (the test
#: waits for the first) but no periodic checkpoint: what it finds afterwards the signal saved.
_SETTINGS = ["run.name=r", "run.steps=1000000", "run.log_every=1", "run.sample_every=1",
             "run.checkpoint_every=1000000", "data.shape_class=mushroom", "data.n_shapes=2",
             "data.views_per_shape=1", "model.resolution=16", "model.width=4", "model.latent=8",
             "train.batch_size=2", "render.backend=closed_form"]


def _train_command(tmp_path: Path):
    sets = [f"run.out_dir={tmp_path / 'runs'}", f"data.cache={tmp_path / 'data'}", *_SETTINGS]
    return [sys.executable, "-m", "mitsuba_platonic.cli", "train", "--quiet",
            *[arg for s in sets for arg in ("--set", s)]]


def _hang_up_as_a_terminal_would() -> None:
    """In the child: SIGHUP with its default action, as under a terminal (the test itself may run under
    ``nohup``, which a child would inherit as an ignored SIGHUP)."""
    signal.signal(signal.SIGHUP, signal.SIG_DFL)


def _wait_for(path: Path, process: subprocess.Popen) -> None:
    """Until ``path`` exists (training has run a step); fail with its output if the process ends first."""
    while not path.exists():
        if process.poll() is not None:
            out, err = process.communicate()
            pytest.fail(f"the training ended before its first step (exit {process.returncode}):\n{out}\n{err}")
        time.sleep(0.2)


@pytest.mark.parametrize("via_shell", [False, True], ids=["train", "bash around train"])
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT, signal.SIGHUP], ids=["SIGTERM", "SIGINT", "SIGHUP"])
def test_a_signal_saves_says_so_in_one_line_and_ends_the_process_by_it(tmp_path, sig, via_shell):
    command = _train_command(tmp_path)
    if via_shell:
        command = ["bash", "-c", f"{shlex.join(command)}; echo next"]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               stdin=subprocess.DEVNULL, cwd=tmp_path, start_new_session=True,
                               preexec_fn=_hang_up_as_a_terminal_would)
    try:
        _wait_for(tmp_path / "runs" / "r" / "samples" / "step_0000001.png", process)
        if via_shell:
            os.killpg(process.pid, sig)              # as a terminal's Ctrl-C, or Slurm's SIGTERM, reaches the job
        else:
            process.send_signal(sig)
        stdout, stderr = process.communicate(timeout=600)
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
    assert process.returncode == -sig, (process.returncode, stderr)
    assert "next" not in stdout                          # the script's next line did not run
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "Traceback" not in stderr, stderr
    what = {signal.SIGTERM: "terminated (SIGTERM)", signal.SIGHUP: "hung up (SIGHUP)"}.get(sig, "interrupted")
    assert lines[0].startswith(f"platonic train: {what}: after step "), lines[0]
    assert "last.pt holds step" in lines[0] and "--resume" in lines[0], lines[0]
    step = read_checkpoint(tmp_path / "runs" / "r").step
    assert step >= 1 and f"holds step {step};" in lines[0], (step, lines[0])


def test_a_hang_up_under_nohup_does_not_stop_a_training(tmp_path):
    """``nohup`` ignores SIGHUP before the command starts: the training keeps that, and runs on."""
    process = subprocess.Popen(["nohup", *_train_command(tmp_path)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True, stdin=subprocess.DEVNULL, cwd=tmp_path, start_new_session=True)
    try:
        samples = tmp_path / "runs" / "r" / "samples"
        _wait_for(samples / "step_0000001.png", process)
        process.send_signal(signal.SIGHUP)
        seen = len(list(samples.glob("step_*.png")))
        deadline = time.monotonic() + 300
        while len(list(samples.glob("step_*.png"))) < seen + 2 and process.poll() is None and time.monotonic() < deadline:
            time.sleep(0.2)
        assert process.poll() is None, process.communicate()      # still training after the hang-up
        assert len(list(samples.glob("step_*.png"))) >= seen + 2
        process.send_signal(signal.SIGTERM)
        process.communicate(timeout=600)
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
    assert process.returncode == -signal.SIGTERM
    assert read_checkpoint(tmp_path / "runs" / "r").step >= 3


_TWICE = """
import os, signal, sys
from mitsuba_platonic import cli
from mitsuba_platonic.cli import exits

def handler(args):                    # a Ctrl-C in evaluate, and a second one while the first unwinds
    try:
        os.kill(os.getpid(), signal.SIGINT)
        while True:
            pass
    finally:
        os.kill(os.getpid(), signal.SIGINT)

parser = cli.build_parser()
parser._subparsers._group_actions[0].choices["evaluate"].set_defaults(handler=handler)
cli.build_parser = lambda: parser
message = exits.interrupt_message

def third(args, e):                   # and a third while its one line is written
    os.kill(os.getpid(), signal.SIGINT)
    return message(args, e)

cli.interrupt_message = third
from mitsuba_platonic.console import main
main(["evaluate", "--run", "r", "--out", "o"])
"""


def test_ctrl_c_twice_in_evaluate_is_one_line_and_the_process_ends_by_it(tmp_path):
    r = subprocess.run([sys.executable, "-c", _TWICE], capture_output=True, text=True, timeout=300,
                       stdin=subprocess.DEVNULL, cwd=tmp_path)
    assert r.returncode == -signal.SIGINT, r.stderr
    err = r.stderr.strip()
    assert "\n" not in err and "Traceback" not in err, err
    assert err.startswith("platonic evaluate: interrupted: no report was written"), err


_WHILE_LOADING = """
import os, signal, sys
class Interrupt:                      # a Ctrl-C while the console script loads the command line
    def find_spec(self, name, path=None, target=None):
        if name == "mitsuba_platonic.cli.args":
            os.kill(os.getpid(), signal.{sig})
        return None
sys.meta_path.insert(0, Interrupt())
from mitsuba_platonic.console import main
main(["train", "--quiet"])
"""


@pytest.mark.parametrize("sig", ["SIGINT", "SIGTERM", "SIGHUP"])
def test_a_signal_while_the_console_script_loads_is_one_line(tmp_path, sig):
    r = subprocess.run([sys.executable, "-c", _WHILE_LOADING.format(sig=sig)], capture_output=True, text=True,
                       timeout=300, stdin=subprocess.DEVNULL, cwd=tmp_path, preexec_fn=_hang_up_as_a_terminal_would)
    assert r.returncode == -getattr(signal, sig), r.stderr
    err = r.stderr.strip()
    what = {"SIGTERM": "terminated (SIGTERM)", "SIGHUP": "hung up (SIGHUP)"}.get(sig, "interrupted")
    assert err == f"platonic: {what}: while starting; nothing was written", err


#: The ``platonic`` console script as pip writes it, with a Ctrl-C as ``{module}`` is imported: while
#: the package itself imports (its LLVM search), before the console script has caught the signals.
_CONSOLE_SCRIPT = """import os, signal, sys
class Interrupt:
    def find_spec(self, name, path=None, target=None):
        if name == "{module}":
            os.kill(os.getpid(), signal.SIGINT)
        return None
sys.meta_path.insert(0, Interrupt())
import re
from mitsuba_platonic.console import main
if __name__ == '__main__':
    sys.argv[0] = re.sub(r'(-script\\.pyw|\\.exe)?$', '', sys.argv[0])
    sys.exit(main())
"""


@pytest.mark.parametrize("module", ["mitsuba_platonic.runtime.backend", "mitsuba_platonic.errors"],
                         ids=["the package's LLVM search", "the console script's own modules"])
def test_ctrl_c_while_the_package_imports_is_one_line_and_ends_by_the_signal(tmp_path, module):
    """The first ~100 ms: a Ctrl-C in the package's ``__init__`` (``preselect_libllvm``) came before the
    console script caught the signals, a ``KeyboardInterrupt`` traceback."""
    script = tmp_path / "bin" / "platonic"
    script.parent.mkdir()
    script.write_text(_CONSOLE_SCRIPT.format(module=module))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(Path(__file__).resolve().parents[1]),
                                                         os.environ.get("PYTHONPATH", "")])}
    r = subprocess.run([sys.executable, str(script), "--version"], capture_output=True, text=True, timeout=300,
                       stdin=subprocess.DEVNULL, cwd=tmp_path, env=env)
    assert r.returncode == -signal.SIGINT, r.stderr
    assert r.stderr.strip() == "platonic: interrupted: while starting; nothing was written", r.stderr


def test_importing_the_package_elsewhere_leaves_pythons_exception_hook_alone():
    r = subprocess.run([sys.executable, "-c", "import sys; hook = sys.excepthook; import mitsuba_platonic; "
                                              "print(sys.excepthook is hook)"],
                       capture_output=True, text=True, timeout=300, stdin=subprocess.DEVNULL)
    assert r.stdout.strip() == "True", r.stderr
