"""The project's file writes: whole or not at all, and never through a symbolic link out of the folder
they belong to.

Atomic writes (:func:`atomic_write`): a file is either its old self or completely written, never torn.

Confinement (:func:`confined`): a run folder, a collection or an output folder may come from a colleague
or an archive and hold symbolic links (``checkpoints/`` → someone's folder, ``run.lock`` → a shell
profile). Within ``with confined(root):`` every path below ``root`` that this module writes, creates,
opens, locks or deletes (:func:`atomic_write`, :func:`open_file`, :func:`make_folder`,
:func:`remove`, :func:`remove_temporaries`) is checked part by part from ``root`` down: a folder
on the way that is a symbolic link, and a file that would be opened through one (``O_NOFOLLOW``),
is refused with :class:`LinkRefused` (a one-line :class:`~mitsuba_platonic.errors.UserError`
naming the link) before anything is done through it. A link that is the last part of a path
written atomically or deleted is replaced or removed itself, never followed (``rename`` and
``unlink`` act on the link: a broken ``last.pt`` link is simply replaced). ``root`` itself may be
a link (the user named it); what lies inside may not. ``confined(root, parts)`` checks the
folder's own layout (``parts``, links as the last part included) on entry, so a command refuses
before it has done any work, not at its first write.

Reading (:func:`check_input_file`, :func:`read_input_file`, :func:`read_input_text`): every file a
command reads from a path a user named, or from a folder someone else made (a photo, a volume
file, a config, a run's records), is checked first: a regular file (not a FIFO, which would block
the read for ever, nor a device: ``/dev/zero`` reads without end; also through a link), at most a
size bound, else :class:`InputFileRefused`, one line naming the file. The readers that read whole
open it without blocking and check what they opened (``fstat``), then read at most the bound.
"""

from __future__ import annotations

import contextvars
import errno
import os
import re
import stat
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, List, Optional, Tuple, Union

from ..errors import UserError

__all__ = ["atomic_write", "temporary_name", "remove_temporaries", "interrupt_behind", "LinkRefused", "confined",
           "check_path", "open_file", "make_folder", "remove", "write_text", "InputFileRefused", "check_input_file",
           "read_input_file", "read_input_text", "MAX_TEXT_BYTES", "MAX_IMAGE_BYTES", "MAX_CHECKPOINT_BYTES"]

PathLike = Union[str, Path]

#: What :func:`temporary_name` names a temporary: ``.<stem>.tmp<pid><suffix>``.
_TEMPORARY = re.compile(r"\..+\.tmp\d+(\.[^.]+)?")

#: OS errors a writer that is not Python's own (Mitsuba's, OpenEXR's) may report in its message.
_WRITE_ERRORS = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EIO, errno.EROFS)


def temporary_name(path: Path) -> Path:
    """The hidden sibling ``path`` is written through: ``.<stem>.tmp<pid><suffix>`` (the suffix
    kept, so writers that pick a format by it still do)."""
    return path.with_name(f".{path.stem}.tmp{os.getpid()}{path.suffix}")


def atomic_write(path: Path, write: Callable[[Path], Any], durable: bool = False) -> None:
    """Write ``path`` by calling ``write(tmp)`` on a temporary sibling, then renaming it into place.

    ``durable``: fsync the temporary file before the rename (for files a crash must not lose).
    The temporary file is removed if ``write`` fails (or is interrupted). A failed write (a full
    disk, no permission) raises ``OSError`` naming ``path``, also where the writer reported it
    as its own exception whose message names the OS error (Mitsuba and OpenEXR raise
    ``RuntimeError``), so that the command line shows it as one line. A Ctrl-C inside ``write``
    stays a ``KeyboardInterrupt`` even where the writer's own clean-up then fails on the torn file
    and raises something else (numpy's ``savez`` closing a zip whose entry is still open raises
    ``ValueError``), so the command line reports the interrupt, not the clean-up's error.
    """
    path = check_path(path, itself=False)                   # a link there is replaced by the rename, not followed
    make_folder(path.parent)
    tmp = temporary_name(path)
    try:
        write(tmp)
        if durable:
            with open(tmp, "rb+") as f:
                os.fsync(f.fileno())
        os.replace(tmp, path)
    except Exception as e:
        interrupt = interrupt_behind(e)
        if interrupt is not None:                            # the clean-up of a write Ctrl-C tore
            raise interrupt from None
        failed = _as_os_error(e, path, tmp)
        if failed is None:
            raise
        raise failed from e
    finally:
        if tmp.exists():
            tmp.unlink()


def interrupt_behind(e: BaseException) -> Optional[KeyboardInterrupt]:
    """The ``KeyboardInterrupt`` that ``e`` is or was raised while handling (its context chain), if any:
    Dr.Jit re-raises a Ctrl-C in its callbacks as its own error, the interrupt only in the chain."""
    seen = set()
    while e is not None and id(e) not in seen:
        if isinstance(e, KeyboardInterrupt):
            return e
        seen.add(id(e))
        e = e.__cause__ or e.__context__
    return None


def _as_os_error(e: Exception, path: Path, tmp: Path) -> Optional[OSError]:
    """``e`` as an ``OSError`` naming ``path`` (not the temporary), if it is a failed write."""
    if isinstance(e, OSError):
        if e.errno is None or e.filename not in (None, str(tmp), tmp):
            return None
        return OSError(e.errno, e.strerror or os.strerror(e.errno), str(path))
    text = str(e)
    for code in _WRITE_ERRORS:
        if os.strerror(code) in text:
            return OSError(code, os.strerror(code), str(path))
    return None


def remove_temporaries(folder: Path) -> List[Path]:
    """Delete the temporaries :func:`atomic_write` left in ``folder`` when its process was killed
    (call it only while no other process writes there); return what was deleted."""
    removed = []
    if check_path(folder).is_dir():
        for p in Path(folder).iterdir():
            if _TEMPORARY.fullmatch(p.name) and p.is_file() and not p.is_symlink():
                remove(p)
                removed.append(p)
    return removed


# --------------------------------------------------------------------------- confinement

#: The folders (absolute, not resolved) whose insides :func:`check_path` checks: :func:`confined`'s.
_ROOTS: "contextvars.ContextVar[Tuple[str, ...]]" = contextvars.ContextVar("confined_roots", default=())

#: ``os.open`` flags: never follow a link in the last part, and no inheritance by child processes
#: (each 0 where the platform has none).
_NO_FOLLOW = getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)


class LinkRefused(UserError):
    """A part of a path inside a confined folder is a symbolic link; nothing was done through it."""


def _refusal(link: str, root: str) -> LinkRefused:
    try:
        target = os.readlink(link)
    except OSError:
        target = "?"
    return LinkRefused(f"{link} is a symbolic link (to {target}) inside {root}; platonic writes, locks and deletes "
                       f"only real files and folders there and changed nothing through it: replace the link by a "
                       f"copy of what it points to, or use another folder")


@contextmanager
def confined(root: PathLike, parts: Iterable[str] = ()) -> Iterator[Path]:
    """Within the block, refuse (:class:`LinkRefused`) every write, lock or deletion through this
    module whose path below ``root`` passes through a symbolic link; first check each of ``parts``
    (names relative to ``root``: the folder's layout) so that a link there is refused before any
    work. Blocks nest: a path below several confined folders is checked from the outermost."""
    root = Path(root)
    token = _ROOTS.set(_ROOTS.get() + (os.path.abspath(root),))
    try:
        for part in parts:
            check_path(root / part)
        yield root
    finally:
        _ROOTS.reset(token)


def check_path(path: PathLike, itself: bool = True) -> Path:
    """``path``, after checking that no part of it below a :func:`confined` folder is a symbolic
    link (the last part too unless not ``itself``: a link replaced or removed, never followed);
    :class:`LinkRefused` naming the first that is."""
    path = Path(path)
    full = os.path.abspath(path)
    for root in _ROOTS.get():
        if full == root or not full.startswith(root.rstrip(os.sep) + os.sep):
            continue
        current = root
        parts = Path(os.path.relpath(full, root)).parts
        for part in parts if itself else parts[:-1]:
            current = os.path.join(current, part)
            if os.path.islink(current):
                raise _refusal(current, root)
        break                                                # the outermost root checked every part below it
    return path


def open_file(path: PathLike, flags: int, mode: int = 0o644) -> int:
    """``os.open(path, flags | O_NOFOLLOW)`` after :func:`check_path`: a file descriptor, never one
    of a link's target (a link that appears meanwhile is refused by the kernel, and here in words)."""
    path = check_path(path)
    try:
        return os.open(path, flags | _NO_FOLLOW, mode)
    except OSError as e:
        if e.errno == errno.ELOOP and os.path.islink(path):
            raise _refusal(os.path.abspath(path), os.path.dirname(os.path.abspath(path))) from None
        raise


def make_folder(path: PathLike) -> Path:
    """Create the folder ``path`` and its missing parents (``mkdir -p``) after :func:`check_path`."""
    path = check_path(path)
    path.mkdir(parents=True, exist_ok=True)
    return path


def remove(path: PathLike, missing_ok: bool = False) -> None:
    """Delete the file ``path`` after :func:`check_path` (never a file a linked folder holds; a link
    itself is removed, not what it points to)."""
    check_path(path, itself=False).unlink(missing_ok=missing_ok)


def write_text(path: PathLike, text: str) -> Path:
    """Write ``text`` to ``path`` atomically (:func:`atomic_write`); return the path."""
    path = Path(path)
    atomic_write(path, lambda tmp: tmp.write_text(text))
    return path


# --------------------------------------------------------------------------- reading a user's file

#: The largest text file (a config, a run's or a collection's records) a command reads: 16 MiB.
MAX_TEXT_BYTES = 16 * 2 ** 20
#: The largest image file a command reads: 1 GiB (Pillow refuses more than 179 megapixels anyway).
MAX_IMAGE_BYTES = 2 ** 30
#: The largest checkpoint a command reads: 16 GiB, a training state of 4 billion float32 numbers
#: (networks and both optimisers' moments): far beyond any PlatonicGAN configuration, which save tens
#: to hundreds of MB; torch.load holds every tensor in memory, so a larger file would end in an
#: out-of-memory kill instead of one line.
MAX_CHECKPOINT_BYTES = 16 * 2 ** 30


class InputFileRefused(UserError):
    """A file to read that is no regular file (``reason`` ``'not_a_file'``) or too large (``'too_large'``)."""

    def __init__(self, message: str, reason: str):
        super().__init__(message)
        self.reason = reason


def _kind(mode: int) -> str:
    for test, name in ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
                       (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                       (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return "not a regular file"


def _checked_stat(st: os.stat_result, path: PathLike, what: str, max_bytes: Optional[int]) -> os.stat_result:
    label = f"{what} {str(path)!r}" if what else repr(str(path))
    if not stat.S_ISREG(st.st_mode):
        via = f" (through a link to {os.path.realpath(path)!r})" if os.path.islink(path) else ""
        raise InputFileRefused(f"{label} is {_kind(st.st_mode)}{via}, not a regular file; nothing was read from "
                               f"it: name a file", "not_a_file")
    if max_bytes is not None and st.st_size > max_bytes:
        raise InputFileRefused(f"{label} is {st.st_size:,} bytes, more than the {max_bytes:,} such a file may be; "
                               f"nothing was read from it", "too_large")
    return st


def check_input_file(path: PathLike, what: str = "", max_bytes: Optional[int] = None) -> Path:
    """``path`` after checking that it is (or links to) a regular file of at most ``max_bytes``
    bytes (None: any size): :class:`InputFileRefused` naming it (``what``: how the command line
    calls it, ``--photo``) otherwise; ``OSError`` (``FileNotFoundError``) where it cannot be looked at.
    For readers that take a path (numpy, torch, Pillow); :func:`read_input_file` reads it in one go."""
    _checked_stat(os.stat(path), path, what, max_bytes)
    return Path(path)


def read_input_file(path: PathLike, what: str = "", max_bytes: Optional[int] = MAX_IMAGE_BYTES) -> bytes:
    """The bytes of the regular file ``path`` (:func:`check_input_file`'s checks, made on the file
    opened: a FIFO's open does not block, and what is read is what was checked), at most ``max_bytes``."""
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    try:
        st = _checked_stat(os.fstat(fd), path, what, max_bytes)
        if hasattr(os, "set_blocking"):
            os.set_blocking(fd, True)
        with os.fdopen(fd, "rb", closefd=False) as f:
            data = f.read(st.st_size if max_bytes is None else max_bytes + 1)
    finally:
        os.close(fd)
    if max_bytes is not None and len(data) > max_bytes:                # grew since it was looked at
        _checked_stat(os.stat(path), path, what, max_bytes)
        raise InputFileRefused(f"{what + ' ' if what else ''}{str(path)!r} is more than the {max_bytes:,} bytes such "
                               f"a file may be; nothing was read from it", "too_large")
    return data


def read_input_text(path: PathLike, what: str = "", max_bytes: int = MAX_TEXT_BYTES) -> str:
    """:func:`read_input_file` as UTF-8 text (``UnicodeDecodeError`` where it is not)."""
    return read_input_file(path, what, max_bytes).decode("utf-8")
