"""The guide's option tables are made from the documentation next to the fields
(mitsuba_platonic/config/docs.py): every field of every section has one entry where it is declared,
every field is in a table of docs/training.md, and the tables there are current."""

import dataclasses
import typing
from pathlib import Path

import pytest

from mitsuba_platonic.config import Config
from mitsuba_platonic.config.docs import GUIDES, SECTIONS, field_docs, main, option_table, tabled_keys, with_tables

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("section", SECTIONS)
def test_every_field_has_one_entry(section):
    cls = typing.get_type_hints(Config)[section]
    entries = field_docs(cls)
    keys = [k for keys, _ in entries for k in keys]
    assert sorted(keys) == sorted(f.name for f in dataclasses.fields(cls))
    assert all(text.strip() for _, text in entries)


def test_a_field_without_an_entry_or_with_two_is_refused():
    @dataclasses.dataclass
    class Two:
        """a: one.
        b: two.
        a: again.
        """
        a: int = 1
        b: int = 2
        c: int = 3

    with pytest.raises(ValueError, match=r"undocumented: \['c'\], documented twice: \['a'\]"):
        field_docs(Two)


def test_a_table_holds_each_entry_once_with_its_defaults():
    table = option_table("run", ["name", "out_dir", "log_every", "drjit_threads"])
    rows = table.splitlines()[2:]
    assert rows[0].startswith("| `name`, `out_dir` | `run`, `runs` | the run folder is `out_dir/name`")
    assert rows[1].startswith("| `log_every`, `sample_every`, `checkpoint_every` | 10, 250, 250 | ")
    assert rows[2].startswith("| `drjit_threads` | `auto` | ") and '[training](training.md), "The measurements"' in rows[2]
    in_guide = option_table("run", ["drjit_threads"], headings=["The measurements"]).splitlines()[2]
    assert "([The measurements](#the-measurements))" in in_guide          # the guide's own section: in-page
    assert len(rows) == 3
    assert "| `lr_d` | 2e-5 |" in option_table("train", ["lr_d"])
    assert "`vh` \\| `ao` \\| `ea`" in option_table("render", ["model"])      # a | inside a cell is escaped
    with pytest.raises(ValueError, match="run has no key"):
        option_table("run", ["nope"])


def test_the_guides_tables_are_current_and_hold_every_field():
    for name in GUIDES:
        text = (ROOT / name).read_text()
        assert with_tables(text) == text, f"{name}: run python -m mitsuba_platonic.config.docs"
    assert main(["--root", str(ROOT), "--check"]) == 0
    tabled = tabled_keys((ROOT / "docs/training.md").read_text())
    for section in SECTIONS:
        fields = [f.name for f in dataclasses.fields(typing.get_type_hints(Config)[section])]
        assert sorted(tabled[section]) == sorted(fields), section


def test_check_names_a_stale_guide(tmp_path, capsys):
    guide = tmp_path / GUIDES[0]
    guide.parent.mkdir(parents=True)
    guide.write_text("# x\n\n<!-- options: run seed -->\n| old |\n<!-- end options -->\n")
    assert main(["--root", str(tmp_path), "--check"]) == 1
    assert "out of date" in capsys.readouterr().out and "| old |" in guide.read_text()
    assert main(["--root", str(tmp_path)]) == 0
    assert "| `seed` | 0 | the master seed" in guide.read_text()
