"""What the commands share about their arguments: the error they raise, the argparse types of
numbers, the ``--models`` list and the ``--out`` folder check.

Light on purpose (argparse and the package's errors only), as is every module of the command
line at import time: importing it loads no numpy or torch, and ``platonic --help`` no Mitsuba.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Callable, List, Mapping, Optional, Sequence

from ..errors import UserError
from ..settings_checks import cut

__all__ = ["PROG", "CLIError", "positive_int", "non_negative_int", "resolution", "positive_float", "seed",
           "MAX_SEED", "parse_models", "check_out_folder", "check_settings_once", "add_background"]

PROG = "platonic"


class CLIError(UserError):
    """A user error: reported as ``platonic <command>: error: <message>``, exit code 2."""


# --------------------------------------------------------------------------- argument types


def _number_type(convert: Callable[[str], float], minimum: float, what: str,
                 maximum: float = float("inf")) -> Callable[[str], float]:
    """An argparse type: ``convert(text)``, finite and in [``minimum``, ``maximum``], else an error saying ``what``."""
    def parse(text: str):
        try:
            value = convert(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
        if not (minimum <= value <= maximum and value != float("inf")):
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}")
        return value
    return parse


positive_int = _number_type(int, 1, "a positive integer")
non_negative_int = _number_type(int, 0, "a non-negative integer")
resolution = _number_type(int, 2, "an integer resolution of at least 2")
#: The largest seed: torch's and numpy's generators take a 64-bit signed integer.
MAX_SEED = 2 ** 63 - 1
seed = _number_type(int, 0, f"a seed, an integer from 0 to 2⁶³ − 1 = {MAX_SEED}", maximum=MAX_SEED)
positive_float = _number_type(float, float.fromhex("0x1p-1074"), "a positive finite number")


# --------------------------------------------------------------------------- checks after parsing


def parse_models(text: str) -> List[str]:
    """``"vh,ao,ea"`` → ``['vh', 'ao', 'ea']`` (validated, duplicates dropped, order kept)."""
    from ..volume import MODELS          # lazy: volume imports torch

    models: List[str] = []
    for m in (s.strip().lower() for s in text.split(",")):
        if not m:
            continue
        if m not in MODELS:
            raise CLIError(f"unknown model {m!r} in --models {text!r}; expected a comma-separated "
                           f"subset of {','.join(MODELS)}")
        if m not in models:
            models.append(m)
    if not models:
        raise CLIError(f"--models {text!r} names no model; expected e.g. vh,ao,ea")
    return models


def add_background(p: argparse.ArgumentParser, what: str = "RGB photos") -> None:
    """``--background white``: mask ``what`` (images without an alpha channel) on a white background
    (the photo loader's ``background``); ``reconstruct``'s and ``view``'s."""
    p.add_argument("--background", choices=("white",), default=None, help=f"mask {what} on white")


def check_out_folder(out: Path) -> None:
    """Refuse an ``--out`` that exists and is not a folder (before any work)."""
    if out.exists() and not out.is_dir():
        raise CLIError(f"--out {str(out)!r} exists and is not a folder")


def check_settings_once(sets: Optional[Sequence[str]], flags: Mapping[str, str]) -> None:
    """Refuse a config key that a flag and a ``--set`` item both give (``flags``: key → the flag as
    given, ``{'run.steps': '--steps 5'}``), naming both: one of them would win without a word. (Two
    ``--set`` items of one key are one spelling given twice: the later wins, as ``--set``'s help says.)
    An item without ``=`` is left to the config's own message."""
    for item in sets or ():
        key = item.split("=", 1)[0].strip() if "=" in item else None
        if key in flags:
            raise CLIError(f"{key}: given twice, by {flags[key]} and by --set {cut(item)}; expected one of them")
