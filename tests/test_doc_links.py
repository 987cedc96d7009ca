"""Every relative link in the project's Markdown (README.md, docs/, lab/, benchmarks/) names a file or
folder that exists: the guides link the experiment log (lab/) and the log links the guides, and a
moved file must not leave a link behind (issue 57)."""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = sorted([ROOT / "README.md", *ROOT.glob("docs/*.md"), *ROOT.glob("lab/*.md"), *ROOT.glob("benchmarks/*.md")])
LINK = re.compile(r"\]\(([^)\s]+)\)")


def _relative_targets(page: Path):
    """The relative link targets of ``page``, without their anchors (web addresses and in-page anchors left out)."""
    for target in LINK.findall(page.read_text(encoding="utf-8")):
        if re.match(r"[a-z]+:", target) or target.startswith("#"):
            continue
        yield target.split("#")[0]


def test_the_pages_are_found():
    assert len([p for p in PAGES if p.parent.name == "lab"]) >= 20 and len([p for p in PAGES if p.parent.name == "docs"]) >= 5


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_relative_link_resolves(page):
    broken = [t for t in _relative_targets(page) if not (page.parent / t).exists()]
    assert not broken, f"{page.relative_to(ROOT)}: {broken}"


def test_a_broken_link_is_caught(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("[here](gone.md#part) [there](page.md) [web](https://example.org) [anchor](#top)\n")
    assert list(_relative_targets(page)) == ["gone.md", "page.md"]
    assert not (tmp_path / "gone.md").exists()
