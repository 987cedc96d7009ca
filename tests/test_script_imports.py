"""The scripts outside the package (benchmarks/, lab/scripts/) import only what the
package has: every ``from mitsuba_platonic… import names`` and ``import mitsuba_platonic…`` in them,
at any depth of the file, names a module that imports and names that module defines. The package's
layers move (lab/README.md, "Scripts", says the experiment scripts run from HEAD); this
catches a script left behind without running it."""

import ast
import importlib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPTS = sorted([*ROOT.glob("benchmarks/*.py"), *ROOT.glob("lab/scripts/*.py")])


def _package_imports(path: Path):
    """(line, module, names) of each import of the package in ``path``; names empty for ``import m``."""
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.ImportFrom) and node.level == 0 and (node.module or "").split(".")[0] == "mitsuba_platonic":
            yield node.lineno, node.module, [a.name for a in node.names]
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] == "mitsuba_platonic":
                    yield node.lineno, a.name, []


def test_the_scripts_are_found():
    assert len([p for p in SCRIPTS if "lab" in p.parts]) >= 10 and len(SCRIPTS) >= 20


def _missing(path: Path):
    """What ``path`` imports from the package that the package does not have, one line each."""
    missing = []
    for line, module, names in sorted(_package_imports(path)):
        try:
            mod = importlib.import_module(module)
        except ImportError as e:
            missing.append(f"line {line}: {module} ({e})")
            continue
        for name in names:
            if name != "*" and not hasattr(mod, name):
                try:                                     # a submodule imported by name: from pkg import sub
                    importlib.import_module(f"{module}.{name}")
                except ImportError:
                    missing.append(f"line {line}: {module}.{name}")
    return missing


@pytest.mark.parametrize("path", SCRIPTS, ids=lambda p: str(p.relative_to(ROOT)))
def test_a_script_imports_only_what_the_package_has(path):
    missing = _missing(path)
    assert not missing, f"{path.relative_to(ROOT)} imports what the package does not have: {missing}"


def test_a_stale_import_is_caught_at_any_depth(tmp_path):
    """The check itself: a module that moved (inside a function) and a name a module lacks are both
    found; what the package has is not."""
    script = tmp_path / "old.py"
    script.write_text("from mitsuba_platonic.views import front_view\n"
                      "def f():\n    from mitsuba_platonic.checkpoint import read_checkpoint\n"
                      "from mitsuba_platonic.views import no_such_name\n", encoding="utf-8")
    missing = _missing(script)
    assert len(missing) == 2
    assert missing[0].startswith("line 3: mitsuba_platonic.checkpoint (")
    assert missing[1] == "line 4: mitsuba_platonic.views.no_such_name"
