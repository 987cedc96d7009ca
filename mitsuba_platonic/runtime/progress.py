"""Progress output that suits where it goes: the one helper every progress bar in the package uses.

On a terminal (or in a Jupyter notebook) :func:`progress_bar` is a live ``tqdm`` bar. Where the
stream is not a terminal (``platonic train > log``, CI, a pipe) a bar's ``\\r`` redraws would
pile up on one line of the log, so it writes a plain line every ``every`` of the way instead
(10 % by default) and one at the end::

    train: 400/2000 step (20%), 3.1 step/s, 1 min 16 s elapsed, ~8 min 36 s left; loss_rec=0.012
"""

from __future__ import annotations

import math
import sys
import time
from typing import IO, Any, Mapping, Optional, Union

__all__ = ["progress_bar", "LineProgress", "is_live"]


def is_live(stream: Optional[IO[str]] = None) -> bool:
    """Whether ``stream`` (default stderr) shows a live bar: a terminal, or a notebook's widget."""
    stream = sys.stderr if stream is None else stream
    try:
        if stream.isatty():
            return True
    except (AttributeError, ValueError):                   # no isatty, or a closed stream
        return False
    from tqdm.autonotebook import tqdm as auto  # lazy: tqdm.autonotebook looks for Jupyter on import
    from tqdm.std import tqdm as plain
    return auto is not plain                               # in a notebook: tqdm picked its widget


def _duration(seconds: float) -> str:
    """'42 s', '3 min 5 s', '2 h 1 min'."""
    s = int(round(seconds))
    if s < 60:
        return f"{s} s"
    if s < 3600:
        return f"{s // 60} min {s % 60} s"
    return f"{s // 3600} h {s % 3600 // 60} min"


class LineProgress:
    """tqdm's interface (``update``, ``set_postfix``, ``close``, ``n``) as occasional plain lines:
    one each time another ``every`` of ``total`` is done, and one when it closes short of that."""

    def __init__(self, total: int, initial: int = 0, unit: str = "it", desc: Optional[str] = None,
                 every: float = 0.1, file: Optional[IO[str]] = None, first_line: bool = False,
                 seconds: Optional[float] = None) -> None:
        self.total, self.n, self.unit, self.desc = int(total), int(initial), unit, desc
        self.every, self.file, self.seconds = every, file, seconds
        self._start_n, self._t0 = self.n, time.perf_counter()
        self._postfix = ""
        self._printed = self._bucket(self.n)
        self._written = self.n
        self._last = self._t0
        if first_line:                                     # the work's size, at once, before the first unit
            self._write()

    def _bucket(self, n: int) -> int:
        """How many ``every`` steps of the total ``n`` has passed."""
        return math.floor(n / self.total / self.every + 1e-9) if self.total > 0 else 0

    def update(self, n: int = 1) -> None:
        """Count ``n`` more; write a line where that passes another ``every`` of the total."""
        self.n += n
        bucket = self._bucket(self.n)
        if bucket > self._printed:
            self._printed = bucket
            self._write()
        elif self.seconds is not None and time.perf_counter() - self._last >= self.seconds:
            self._write()                                  # a long tenth: a line every ``seconds`` as well

    def set_postfix(self, values: Optional[Mapping[str, Any]] = None, **kwargs: Any) -> None:
        """Values shown at the end of the next line (``key=value``)."""
        items = {**(values or {}), **kwargs}
        self._postfix = " ".join(f"{k}={v}" for k, v in items.items())

    def close(self) -> None:
        """The last line, unless the last update wrote it (or nothing was done)."""
        if self.n != self._written:
            self._write()

    def line(self) -> str:
        """The line describing the progress so far."""
        elapsed = time.perf_counter() - self._t0
        done = self.n - self._start_n
        head = f"{self.desc}: " if self.desc else ""
        text = f"{head}{self.n}/{self.total} {self.unit}"
        if self.total > 0:
            text += f" ({100 * self.n / self.total:.0f}%)"
        if done > 0 and elapsed > 0:
            rate = done / elapsed
            text += f", {rate:.3g} {self.unit}/s, {_duration(elapsed)} elapsed"
            if 0 < self.n < self.total:
                text += f", ~{_duration((self.total - self.n) / rate)} left"
        return text + (f"; {self._postfix}" if self._postfix else "")

    def _write(self) -> None:
        self._written, self._last = self.n, time.perf_counter()
        print(self.line(), file=self.file if self.file is not None else sys.stderr, flush=True)


class _Silent:
    """A disabled bar: tqdm's interface, no output."""

    def __init__(self, total: int, initial: int = 0) -> None:
        self.total, self.n = total, initial

    def update(self, n: int = 1) -> None:
        self.n += n

    def set_postfix(self, *args: Any, **kwargs: Any) -> None:
        pass

    def close(self) -> None:
        pass


def progress_bar(total: int, initial: int = 0, unit: str = "it", desc: Optional[str] = None,
                 disable: bool = False, every: float = 0.1, file: Optional[IO[str]] = None,
                 first_line: bool = False,
                 seconds: Optional[float] = None) -> Union["tqdm", LineProgress, _Silent]:  # noqa: F821
    """A progress bar over ``total`` units (``initial`` already done) written to ``file``
    (default stderr): a live tqdm bar on a terminal or in a notebook, else a :class:`LineProgress`
    writing a plain line every ``every`` of the way (with ``first_line`` one at once, saying the
    work's size; with ``seconds`` also one whenever that long passed since the last line, for work
    whose tenths take long); silent with ``disable``. Every bar has ``update(n)``,
    ``set_postfix(dict)`` and ``close()``."""
    if disable:
        return _Silent(total, initial)
    if is_live(file):
        from tqdm.auto import tqdm  # lazy: as in is_live
        return tqdm(total=total, initial=initial, unit=unit, desc=desc, file=file, dynamic_ncols=True)
    return LineProgress(total, initial=initial, unit=unit, desc=desc, every=every, file=file, first_line=first_line,
                        seconds=seconds)
