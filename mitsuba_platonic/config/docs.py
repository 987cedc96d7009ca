"""The guide's option tables, made from the documentation next to the fields.

Each section's dataclass documents its keys in its docstring, one entry per key or group of keys,
each starting a line (``name, out_dir: the run folder is …``; continuation lines follow, and a
blank line ends the entries). The inherited keys are documented where they are declared
(:class:`~mitsuba_platonic.networks.net_settings.NetSettings` for the model's networks,
:class:`~mitsuba_platonic.data.photos.PhotoOptions` for the data's photo options). This module reads
those entries (:func:`field_docs`) and writes them as Markdown tables into the guides, between markers:

    <!-- options: train task mode batch_size -->
    | key | default | what it does, when to change it |
    …
    <!-- end options -->

A marker names a section and the keys whose entries its table holds, in order (every key of an
entry is in its row, with its default from the dataclass). ``python -m mitsuba_platonic.config.docs``
rewrites the tables of :data:`GUIDES`; ``--check`` only says whether they are current (a test runs it).
"""

from __future__ import annotations

import argparse
import dataclasses
import re
import sys
import typing
from pathlib import Path
from typing import Any, Dict, List, Sequence, Tuple

from . import Config

__all__ = ["SECTIONS", "GUIDES", "field_docs", "section_docs", "option_table", "with_tables", "tabled_keys", "main"]

#: The guides (relative to the repository's root) whose option tables this module writes.
GUIDES = ("docs/training.md",)
#: The config's sections, in the order of the config.
SECTIONS = ("run", "data", "model", "render", "train")

_ENTRY = re.compile(r"^\s*([a-z_][a-z0-9_]*(?:, [a-z_][a-z0-9_]*)*): (.*)$")
_MARKER = re.compile(r"^<!-- options: (\w+)((?: \w+)+) -->\n(.*?)^<!-- end options -->$", re.M | re.S)
_ROLE = re.compile(r":(?:func|class|mod|meth|data|attr):`(~?)([^`<]*?)(?: <([^`>]*)>)?`")

Entry = Tuple[Tuple[str, ...], str]


def _section_class(section: str) -> type:
    return typing.get_type_hints(Config)[section]


def field_docs(cls: type) -> List[Entry]:
    """The documentation entries of dataclass ``cls``'s fields, ``[(keys, text), …]``: those of each
    dataclass it inherits from first, each read from the docstring of the class that declares its keys.
    ValueError where a field has no entry, two, or an entry names a key its class does not declare."""
    entries: List[Entry] = []
    for klass in reversed(cls.__mro__):
        own = [name for name in klass.__dict__.get("__annotations__", {})
               if name in klass.__dict__.get("__dataclass_fields__", {})]
        if own:
            entries += _entries(klass, set(own))
    names = [f.name for f in dataclasses.fields(cls)]
    documented = [key for keys, _ in entries for key in keys]
    missing = [n for n in names if n not in documented]
    twice = sorted({k for k in documented if documented.count(k) > 1})
    if missing or twice:
        raise ValueError(f"{cls.__name__}: every field needs one entry in the docstring of the class that declares "
                         f"it; undocumented: {missing}, documented twice: {twice}")
    return entries


def _entries(klass: type, own: set) -> List[Entry]:
    """``klass``'s docstring entries (module docstring): a line ``keys: text`` whose keys are all of ``own``."""
    entries: List[Tuple[Tuple[str, ...], List[str]]] = []
    for line in (klass.__doc__ or "").splitlines():
        match = _ENTRY.match(line)
        if match and set(match.group(1).split(", ")) <= own:
            entries.append((tuple(match.group(1).split(", ")), [match.group(2).strip()]))
        elif match and entries and any(k in own for k in match.group(1).split(", ")):
            raise ValueError(f"{klass.__name__}: the entry {match.group(1)!r} names a key it does not declare")
        elif not line.strip():
            if entries:
                break
        elif entries:
            entries[-1][1].append(line.strip())
    return [(keys, " ".join(text)) for keys, text in entries]


def section_docs(section: str) -> Dict[str, Entry]:
    """Each key of config section ``section`` → its entry (the keys it shares a row with, and the text)."""
    return {key: entry for entry in field_docs(_section_class(section)) for key in entry[0]}


def _value(value: Any) -> str:
    """A default as a config file writes it."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f"`{value}`"
    if isinstance(value, float):
        if not 0 < abs(value) < 1e-2:
            return f"{value:g}"
        mantissa, exponent = f"{value:e}".split("e")                 # 2e-5, as the configs write it
        return f"{mantissa.rstrip('0').rstrip('.')}e{int(exponent)}"
    if isinstance(value, (list, tuple)):
        return "`[" + ", ".join(_value(v).strip("`") for v in value) + "]`"
    return str(value)


def _default(field: dataclasses.Field) -> Any:
    if field.default_factory is not dataclasses.MISSING:        # type: ignore[misc]
        return field.default_factory()                          # type: ignore[misc]
    return field.default


def _markdown(text: str, headings: Sequence[str]) -> str:
    """A docstring entry as a Markdown table cell: roles, ``literals`` and 'choices' as code, the guides as links,
    a quoted heading of this guide as a link to it, ``|`` escaped."""
    def role(m: re.Match) -> str:
        target = m.group(3) or m.group(2)
        return f"`{'.'.join(target.split('.')[-1 if m.group(1) else -2:])}`"      # ~: its name; else also its owner
    text = _ROLE.sub(role, text)
    text = re.sub(r"``([^`]+)``", r"`\1`", text)
    text = re.sub(r"(?<![\w/\[])docs/([\w-]+)\.md", r"[\1](\1.md)", text)
    text = re.sub(r"(?<![\w`])'([\w./-]+)'(?![\w`])", r"`\1`", text)     # a choice, 'cpu': as code
    for heading in headings:
        text = re.sub(rf'\[[\w-]+\]\([\w-]+\.md\), (?="{re.escape(heading)}")', "", text)   # this guide's section
        anchor = re.sub(r"[^\w\- ]", "", heading.lower()).replace(" ", "-")
        text = text.replace(f'"{heading}"', f"[{heading}](#{anchor})")
    return text.replace("|", "\\|")


def option_table(section: str, keys: Sequence[str], headings: Sequence[str] = ()) -> str:
    """The Markdown table of the entries of ``keys`` in config section ``section``, in their order
    (an entry once, at its first key); ``headings``: the guide's, which quoted ones link to."""
    docs = section_docs(section)
    fields = {f.name: f for f in dataclasses.fields(_section_class(section))}
    unknown = [k for k in keys if k not in docs]
    if unknown:
        raise ValueError(f"options: {section} has no key {unknown} (keys: {', '.join(fields)})")
    rows, seen = ["| key | default | what it does, when to change it |", "|---|---|---|"], set()
    for key in keys:
        entry_keys, text = docs[key]
        if entry_keys in seen:
            continue
        seen.add(entry_keys)
        defaults = [_value(_default(fields[k])) for k in entry_keys]
        default = defaults[0] if len(set(defaults)) == 1 else ", ".join(defaults)
        rows.append(f"| {', '.join(f'`{k}`' for k in entry_keys)} | {default} | {_markdown(text, headings)} |")
    return "\n".join(rows) + "\n"


def with_tables(guide: str) -> str:
    """``guide``'s text with every table between markers (module docstring) made again from the fields."""
    headings = [m.group(1).strip() for m in re.finditer(r"^#+ (.+)$", guide, re.M)]

    def table(m: re.Match) -> str:
        section, keys = m.group(1), m.group(2).split()
        if section not in SECTIONS:
            raise ValueError(f"options: unknown section {section!r}; expected one of {list(SECTIONS)}")
        return f"<!-- options: {section} {' '.join(keys)} -->\n{option_table(section, keys, headings)}<!-- end options -->"
    return _MARKER.sub(table, guide)


def tabled_keys(guide: str) -> Dict[str, List[str]]:
    """The keys, by section, whose entries the tables of ``guide`` hold (every key of each entry)."""
    out: Dict[str, List[str]] = {s: [] for s in SECTIONS}
    for m in _MARKER.finditer(guide):
        docs = section_docs(m.group(1))
        for key in m.group(2).split():
            out[m.group(1)] += [k for k in docs[key][0] if k not in out[m.group(1)]]
    return out


def main(argv: Sequence[str] = ()) -> int:
    """Rewrite the option tables of :data:`GUIDES` (``--check``: exit 1, naming them, if any is out of date)."""
    parser = argparse.ArgumentParser(prog="python -m mitsuba_platonic.config.docs", description=__doc__.split("\n")[0])
    parser.add_argument("--root", type=Path, default=Path("."), help="the repository's root (default: here)")
    parser.add_argument("--check", action="store_true", help="write nothing; exit 1 if a table is out of date")
    args = parser.parse_args(list(argv))
    stale = []
    for name in GUIDES:
        path = args.root / name
        text = path.read_text()
        new = with_tables(text)
        if new != text:
            stale.append(name)
            if not args.check:
                path.write_text(new)
    if stale:
        print(("out of date (run python -m mitsuba_platonic.config.docs): " if args.check else "rewrote: ")
              + ", ".join(stale))
    return 1 if stale and args.check else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
