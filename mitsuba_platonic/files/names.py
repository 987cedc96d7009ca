"""File names made from a user's words (a run's name, a photo's file name, a viewer export's name):
readable in any script, never a path.

:func:`readable_name` keeps the letters, combining marks and digits of every script (``Tür``,
``ñandú``, ``木``, ``हिन्दी`` stay as they are, in Unicode's composed form NFC, so that a macOS
decomposed ``ü`` and a typed one are one name) and the few punctuation characters a caller allows;
every other character (``/``, ``\\``, spaces, control and bidirectional formatting characters,
the undecodable bytes of a file name) becomes ``_``.
"""

from __future__ import annotations

import unicodedata

__all__ = ["readable_name", "readable_stem"]


def readable_name(text: str, keep: str = "_-", collapse: bool = False) -> str:
    """``text`` (NFC) with each character that is not a letter, combining mark or digit of any script,
    nor one of ``keep``, replaced by ``_`` (``collapse``: each run of such characters by one ``_``)."""
    out, replaced = [], False
    for c in unicodedata.normalize("NFC", str(text)):
        if c in keep or unicodedata.category(c)[0] in "LMN":
            out.append(c)
            replaced = False
        elif not (collapse and replaced):
            out.append("_")
            replaced = True
    return "".join(out)


def readable_stem(text: str, default: str) -> str:
    """A name (a run's, a method's: ``Stühle (platonic, step 2)``) as a file stem for a figure:
    :func:`readable_name` keeping ``_ . -``, each run of other characters one ``_``, none at either
    end (``Stühle_platonic_step_2``); ``default`` where nothing is left."""
    return readable_name(text, keep="_.-", collapse=True).strip("_") or default
