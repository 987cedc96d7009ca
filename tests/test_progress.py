"""Progress output: live bars on a terminal, a plain line every 10 % anywhere else."""

from __future__ import annotations

import io

import pytest
from tqdm.std import tqdm

from mitsuba_platonic.runtime.progress import LineProgress, progress_bar
from cli_runner import run_cli
from tiny_shapes import TINY


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def _lines(stream: io.StringIO):
    return stream.getvalue().splitlines()


def test_a_stream_that_is_no_terminal_gets_a_line_every_tenth():
    out = io.StringIO()
    bar = progress_bar(200, unit="img", desc="chair ea", file=out)
    assert isinstance(bar, LineProgress)
    for _ in range(200):
        bar.update(1)
    bar.close()
    lines = _lines(out)
    assert "\r" not in out.getvalue()
    assert len(lines) == 10, lines
    assert lines[0].startswith("chair ea: 20/200 img (10%), ") and "left" in lines[0], lines[0]
    assert lines[-1].startswith("chair ea: 200/200 img (100%), ") and "left" not in lines[-1], lines[-1]


def test_lines_resume_where_a_run_stopped_and_end_with_the_last_count():
    out = io.StringIO()
    bar = progress_bar(100, initial=35, unit="step", desc="train", file=out)
    bar.update(3)                                            # 38 %: no line yet
    assert out.getvalue() == ""
    bar.set_postfix({"loss_rec": "0.012"})
    bar.update(2)                                            # 40 %
    bar.update(15)                                           # 55 %: one line for 50 %
    bar.update(2)                                            # 57 %: none
    bar.close()                                              # the last count
    bar.close()                                              # closing twice writes nothing more
    lines = _lines(out)
    assert [line.split(" (")[0] for line in lines] == ["train: 40/100 step", "train: 55/100 step", "train: 57/100 step"]
    assert lines[0].endswith("; loss_rec=0.012"), lines[0]


def test_nothing_done_nothing_written_and_disabled_bars_are_silent():
    out = io.StringIO()
    progress_bar(10, initial=10, file=out).close()
    progress_bar(10, file=out, disable=True).update(10)
    assert out.getvalue() == ""


def test_a_terminal_gets_a_live_bar():
    term = _Terminal()
    bar = progress_bar(10, file=term)
    assert isinstance(bar, tqdm)
    bar.update(10)
    bar.close()
    assert "\r" in term.getvalue()


@pytest.mark.usefixtures("tiny_class")
def test_make_dataset_into_a_log_writes_lines_not_redraws(tmp_path):
    """``platonic make-dataset > log 2>&1``: stderr is no terminal, so plain lines, no ``\\r``."""
    code, out, err = run_cli(["make-dataset", "--class", TINY, "--shapes", "4", "--views", "5", "--resolution", "16",
                              "--out", str(tmp_path / "d")])
    assert code == 0, err
    assert "\r" not in err
    lines = err.splitlines()
    assert 2 <= len(lines) <= 10 and lines[-1].startswith(f"{TINY} ea: 20/20 img (100%)"), lines   # per shape: 25 %


def test_a_first_line_says_the_size_at_once_and_long_tenths_get_timed_lines(monkeypatch):
    """Work whose first tenth takes hours (make-dataset at 10⁶ views, compare at 10⁵) prints its size
    at once and a line every ``seconds`` between the tenths; the clock is the test's."""
    from mitsuba_platonic.runtime import progress as P

    now = [0.0]
    monkeypatch.setattr(P.time, "perf_counter", lambda: now[0])
    out = io.StringIO()
    bar = progress_bar(1000, unit="img", desc="chair ea", file=out, first_line=True, seconds=30.0)
    assert _lines(out) == ["chair ea: 0/1000 img (0%)"]
    bar.update(1)
    now[0] = 29.0
    bar.update(1)
    assert len(_lines(out)) == 1                                   # under 30 s since the last line: none
    now[0] = 31.0
    bar.update(1)
    assert len(_lines(out)) == 2 and _lines(out)[1].startswith("chair ea: 3/1000 img (0%), ")
    now[0] = 40.0
    bar.update(1)
    assert len(_lines(out)) == 2                                   # timed from the last line, not the start


def test_compare_says_its_size_before_the_first_render_and_a_line_per_step(monkeypatch, capsys, tmp_path):
    from mitsuba_platonic.bench import compare as C
    from mitsuba_platonic.volume import test_volume

    before_first = []
    real = C.render
    monkeypatch.setattr(C, "render", lambda *a, **k: (before_first.append(capsys.readouterr().err)
                                                      if not before_first else None) or real(*a, **k))
    shown = []
    monkeypatch.setattr(C, "_figure", lambda model, cf, mi, views, title, path: shown.append((cf.shape[0], title)))
    monkeypatch.setattr(C, "FIGURE_VIEWS", 2)
    C.compare(test_volume(8), C.comparison_views(3), ("vh",), repeats=1, out_dir=tmp_path, progress=True)
    assert before_first[0].strip() == "compare: 3 view(s) at 8³, 2 runs per backend: 0/3 step (0%)"
    lines = capsys.readouterr().err.strip().splitlines()
    assert [line.split("; done=")[-1] for line in lines] == ["vh closed form", "vh Mitsuba", "vh figure and 3 EXR(s)"]
    assert shown[0][0] == 2 and "the first 2 of 3 views" in shown[0][1]       # a figure of at most FIGURE_VIEWS rows
