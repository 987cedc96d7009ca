"""The checks every config section's ``validate()`` shares, and the error they raise.

Each section of a config (``run``, ``data``, ``model``, ``train``) is a dataclass beside the code
that owns it, with a ``validate()`` of its own; these are the helpers they use, so that every
message reads the same way: the key first, then what was expected and what was found
(``train.batch_size: expected a positive value, got 0``). A leaf below every section: it imports
only the error types, and the view conventions inside :func:`check_elevation` (they load torch, and the
command line quotes a user's words with :func:`cut` before it may load torch), never a section or the config.
"""

from __future__ import annotations

import reprlib
from typing import Any, Sequence

from .errors import UserError

__all__ = ["ConfigError", "choice", "positive", "non_negative", "check_elevation", "cut", "quoted", "QUOTE_LIMIT"]

#: The most characters a message quotes of a value: a YAML alias bomb (a few lines that expand to
#: millions of items) is named by its beginning, not printed whole.
QUOTE_LIMIT = 200

_REPR = reprlib.Repr()
_REPR.maxlevel, _REPR.maxlist, _REPR.maxtuple, _REPR.maxdict, _REPR.maxset = 4, 12, 12, 8, 8
_REPR.maxstring, _REPR.maxother, _REPR.maxlong = QUOTE_LIMIT, QUOTE_LIMIT, 60


class ConfigError(UserError):
    """A bad configuration; the message names the key."""


def cut(text: str, limit: int = QUOTE_LIMIT) -> str:
    """``text`` as written, at most ``limit`` characters (``…`` where cut): a user's words in a message."""
    return text if len(text) <= limit else text[:limit - 1] + "…"


def quoted(value: Any, limit: int = QUOTE_LIMIT) -> str:
    """``repr(value)`` for a message, at most ``limit`` characters (``…`` where cut), built without
    the whole repr of a huge value (nested lists a YAML alias expands are shortened level by level)."""
    text = _REPR.repr(value) if isinstance(value, (list, tuple, dict, set, frozenset)) else repr(value)
    return cut(text, limit)


def choice(key: str, value: Any, choices: Sequence[Any]) -> None:
    """``value`` is one of ``choices``; else ``key: expected one of [...], got value``."""
    if value not in choices:
        raise ConfigError(f"{key}: expected one of {list(choices)}, got {quoted(value)}")


def positive(key: str, value: Any) -> None:
    """``value`` > 0; else ``key: expected a positive value, got value``."""
    if not value > 0:
        raise ConfigError(f"{key}: expected a positive value, got {quoted(value)}")


def non_negative(key: str, value: Any) -> None:
    """``value`` ≥ 0; else ``key: expected a non-negative value, got value``."""
    if value < 0:
        raise ConfigError(f"{key}: expected a non-negative value, got {quoted(value)}")


def check_elevation(section: str, distribution: str, elevation: Any) -> None:
    """``<section>.elevation`` fits ``<section>.view_distribution`` (the views' own check, naming the keys)."""
    from .views import DISTRIBUTIONS, sample_views           # here: views loads torch
    if distribution not in DISTRIBUTIONS:
        return                                               # its own check names it
    if distribution == "sphere" or elevation is None:
        return                                               # sphere ignores it (train warns), None: the default
    try:
        sample_views(1, distribution, seed=0, elevation=tuple(elevation) if isinstance(elevation, list) else elevation)
    except (UserError, TypeError) as e:
        raise ConfigError(f"{section}.elevation: {e} (with {section}.view_distribution {distribution!r})") from None
