"""What a pickled file would import and call, read from its opcodes without unpickling it.

:func:`foreign_objects` lists the Python objects (``module.name``, e.g. ``posix.system``) a file's
pickles name beyond the ones ``torch.load(weights_only=True)`` builds: the objects that unpickling
it in full would import and could call. It reads torch's zip format (``*/data.pkl``) and its legacy
format and a plain ``pickle.dump`` (consecutive pickles), with :mod:`pickletools`, which decodes
opcodes and never builds an object. The safe loader's own refusal names only the first object, and
a plain pickle of protocol 4 or 5 it cannot read at all (``Unsupported operand 149``), which looks
like a torn file: this tells such a file apart from a torn one, and names everything a conversion
would run before it runs.
"""

from __future__ import annotations

import io
import pickletools
import zipfile
from pathlib import Path
from typing import Any, Dict, Iterator, List, Optional, Union

import torch
from torch import _weights_only_unpickler as unpickler

__all__ = ["foreign_objects", "pickled_globals"]

#: Opcodes that push a string (the module and name STACK_GLOBAL takes from the stack).
_STRINGS = {"SHORT_BINUNICODE", "BINUNICODE", "BINUNICODE8", "UNICODE", "SHORT_BINSTRING", "BINSTRING", "STRING"}
#: Opcodes that name a global in their argument, ``"module name"``.
_NAMED = {"GLOBAL", "INST"}


def _pickles(path: Path) -> List[bytes]:
    """The pickle streams of ``path``: a torch zip's ``data.pkl`` files, else the file's bytes."""
    if zipfile.is_zipfile(path):
        try:
            with zipfile.ZipFile(path) as archive:
                return [archive.read(name) for name in archive.namelist() if name.endswith("data.pkl")]
        except (zipfile.BadZipFile, OSError, EOFError, ValueError):
            return []
    return [path.read_bytes()]


def _globals_of(data: bytes) -> Iterator[str]:
    """``module.name`` of each global the consecutive pickles in ``data`` name, up to the first bytes
    that are no pickle (a legacy checkpoint's raw storages, or the cut of a torn file)."""
    stream = io.BytesIO(data)
    while stream.tell() < len(data):
        memo: Dict[Any, Any] = {}
        recent: List[Optional[str]] = []
        try:
            for opcode, arg, _ in pickletools.genops(stream):
                name = opcode.name
                if name in _NAMED and isinstance(arg, str):
                    yield ".".join(arg.split(" ", 1))
                elif name == "STACK_GLOBAL":
                    if len(recent) >= 2 and isinstance(recent[-2], str) and isinstance(recent[-1], str):
                        yield f"{recent[-2]}.{recent[-1]}"
                    else:
                        yield "an object named by a computed string"
                if name in _STRINGS:
                    recent.append(arg if isinstance(arg, str) else arg.decode("latin-1"))
                elif name == "MEMOIZE":
                    memo[len(memo)] = recent[-1] if recent else None
                elif name in ("PUT", "BINPUT", "LONG_BINPUT"):
                    memo[arg] = recent[-1] if recent else None
                elif name in ("GET", "BINGET", "LONG_BINGET"):
                    recent.append(memo.get(arg))
                elif name not in ("FRAME", "PROTO"):
                    recent.append(None)
                if name == "STOP":
                    break
            else:
                return                                       # the end of the data
        except Exception:                                    # not (or no longer) a pickle: stop reading
            return


def pickled_globals(path: Union[str, Path]) -> List[str]:
    """Every ``module.name`` the pickles of ``path`` name, in order, each once (nothing is unpickled)."""
    found: Dict[str, None] = {}
    for data in _pickles(Path(path)):
        for name in _globals_of(data):
            found.setdefault(name, None)
    return list(found)


def _allowed() -> set:
    """The globals ``torch.load(weights_only=True)`` builds (its own list and any added with
    ``torch.serialization.add_safe_globals``)."""
    allowed = set(unpickler._get_allowed_globals())
    for entry in torch.serialization.get_safe_globals():
        obj = entry[0] if isinstance(entry, tuple) else entry
        allowed.add(f"{getattr(obj, '__module__', '')}.{getattr(obj, '__qualname__', getattr(obj, '__name__', ''))}")
    return allowed


def foreign_objects(path: Union[str, Path]) -> List[str]:
    """The objects the pickles of ``path`` name that the safe loader does not build (``posix.system``,
    ``builtins.exec``, ``numpy.core.multiarray._reconstruct``): what a full unpickling would import
    and could call; empty for a checkpoint of tensors and plain data. Legacy storages
    (``torch.FloatStorage``) are torch's own and not listed."""
    allowed = _allowed()
    return [g for g in pickled_globals(path)
            if g not in allowed and not (g.startswith("torch.") and g.endswith("Storage"))]
