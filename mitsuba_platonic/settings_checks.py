"""The checks every config section's ``validate()`` shares, and the error they raise.

Each section of a config (``run``, ``data``, ``model``, ``train``) is a dataclass beside the code
that owns it, with a ``validate()`` of its own; these are the helpers they use, so that every
message reads the same way: the key first, then what was expected and what was found
(``train.batch_size: expected a positive value, got 0``). A leaf below every section: it imports
only the error types and the view conventions, never a section or the config.
"""

from __future__ import annotations

from typing import Any, Sequence

from .errors import UserError
from .views import DISTRIBUTIONS, sample_views

__all__ = ["ConfigError", "choice", "positive", "non_negative", "check_elevation"]


class ConfigError(UserError):
    """A bad configuration; the message names the key."""


def choice(key: str, value: Any, choices: Sequence[Any]) -> None:
    """``value`` is one of ``choices``; else ``key: expected one of [...], got value``."""
    if value not in choices:
        raise ConfigError(f"{key}: expected one of {list(choices)}, got {value!r}")


def positive(key: str, value: Any) -> None:
    """``value`` > 0; else ``key: expected a positive value, got value``."""
    if not value > 0:
        raise ConfigError(f"{key}: expected a positive value, got {value!r}")


def non_negative(key: str, value: Any) -> None:
    """``value`` ≥ 0; else ``key: expected a non-negative value, got value``."""
    if value < 0:
        raise ConfigError(f"{key}: expected a non-negative value, got {value!r}")


def check_elevation(section: str, distribution: str, elevation: Any) -> None:
    """``<section>.elevation`` fits ``<section>.view_distribution`` (the views' own check, naming the keys)."""
    if distribution not in DISTRIBUTIONS:
        return                                               # its own check names it
    if distribution == "sphere" or elevation is None:
        return                                               # sphere ignores it (train warns), None: the default
    try:
        sample_views(1, distribution, seed=0, elevation=tuple(elevation) if isinstance(elevation, list) else elevation)
    except (UserError, TypeError) as e:
        raise ConfigError(f"{section}.elevation: {e} (with {section}.view_distribution {distribution!r})") from None
