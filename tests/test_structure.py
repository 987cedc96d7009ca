"""The package's imports flow one way (issue 26): no import cycle, read from the source.

Every ``import`` and ``from ... import`` in ``mitsuba_platonic/`` is parsed with :mod:`ast`, those
inside functions too (a function-level import that closes a loop is a cycle all the same: it only
hides it until the function runs). An edge A → B means A imports B; ``from .pkg import name`` is an
edge to ``pkg.name`` where that is a module, else to ``pkg``. A package's ``__init__`` imported by
its own children is not counted (the children of a package that re-exports them are no loop of design),
Static, so nothing is imported.
"""

from __future__ import annotations

import ast
from pathlib import Path
from typing import Dict, List, NamedTuple, Set

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "mitsuba_platonic"


class Import(NamedTuple):
    source: str            # the importing module
    target: str            # the imported module
    line: int
    lazy: bool             # inside a function


def modules(root: Path = PACKAGE) -> Dict[str, Path]:
    """``{dotted module name: file}`` of every module under ``root`` (a package is its ``__init__``)."""
    out = {}
    for f in sorted(root.rglob("*.py")):
        parts = list(f.relative_to(root.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = f
    return out


def imports(mods: Dict[str, Path], parents: bool = False) -> List[Import]:
    """Every import of one module of ``mods`` by another, with its line and whether it is in a function
    (``parents``: also a child's imports of the packages it is in, which the cycles leave out)."""
    found: List[Import] = []
    for name, path in mods.items():
        is_package = path.name == "__init__.py"
        tree = ast.parse(path.read_text(), str(path))
        lazy_nodes: Set[int] = set()
        for fn in ast.walk(tree):
            if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
                lazy_nodes.update(id(n) for n in ast.walk(fn) if n is not fn)
        for node in ast.walk(tree):
            targets: List[str] = []
            if isinstance(node, ast.ImportFrom):
                if node.level:
                    base = name.split(".") if is_package else name.split(".")[:-1]
                    base = base[:len(base) - (node.level - 1)]
                    where = ".".join(base + ([node.module] if node.module else []))
                else:
                    where = node.module or ""
                for alias in node.names:
                    full = f"{where}.{alias.name}"
                    targets.append(full if full in mods else where)
            elif isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            for target in targets:
                edge = Import(name, target, node.lineno, id(node) in lazy_nodes)
                if (target in mods and target != name and (parents or not name.startswith(target + "."))
                        and edge not in found):
                    found.append(edge)
    return found


def cycles(edges: List[Import]) -> List[List[str]]:
    """The strongly connected sets of two or more modules (Tarjan), each sorted."""
    graph: Dict[str, Set[str]] = {}
    for e in edges:
        graph.setdefault(e.source, set()).add(e.target)
        graph.setdefault(e.target, set())
    index: Dict[str, int] = {}
    low: Dict[str, int] = {}
    stack: List[str] = []
    on_stack: Set[str] = set()
    found: List[List[str]] = []

    def strong(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                strong(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            strong(v)
    return found


def describe(component: List[str], edges: List[Import]) -> str:
    """A cycle's modules and the imports that bind them, ``a.py:12 → b`` (``(in a function)`` where lazy)."""
    inside = set(component)
    lines = [f"import cycle of {len(component)} modules: {', '.join(component)}"]
    for e in sorted(edges, key=lambda e: (e.source, e.line)):
        if e.source in inside and e.target in inside:
            path = modules()[e.source].relative_to(PACKAGE.parent)
            lines.append(f"  {path}:{e.line} → {e.target}" + ("  (in a function)" if e.lazy else ""))
    return "\n".join(lines)


def test_the_package_has_no_import_cycle():
    edges = imports(modules())
    found = cycles(edges)
    report = "\n".join(describe(c, edges) for c in found)
    print(report)
    assert not found, "\n" + report


#: The data flow, lowest first (README, "Layout"): a module imports its own layer and those below,
#: never one above. Names are module prefixes under ``mitsuba_platonic``; the package itself (its
#: face, which re-exports the renderer) sits on top.
LAYERS = [
    ("foundation", ["errors", "_data"]),
    ("conventions: views, volume", ["views", "volume"]),
    ("I/O: files (writes, output folders, package data, volume files, checkpoints) and images", ["files", "images"]),
    ("the machine: Dr.Jit's backend, memory and disk, progress", ["runtime"]),
    ("the checks every settings section shares", ["settings_checks"]),
    ("the renderer's floor: its camera window, the medium's grids, Mitsuba's variant",
     ["render.window", "render.grids", "render.variant"]),
    ("the renderers in PyTorch: the closed form, single scattering", ["render.pytorch"]),
    ("the renderer settings (their filters are the closed form's)", ["render.settings"]),
    ("the Dr.Jit kernels: the marcher, single scattering at its speed, the sky's occlusion, their launches",
     ["render.drjit"]),
    ("the Mitsuba scene side: scene files, the per-pair integrator, the path tracer, skies", ["render.mitsuba"]),
    ("the renderer's face: the one dispatcher, turntables", ["render"]),
    ("data: collections, photos, the data section", ["data"]),
    ("networks, the colour they read from a photo and the model section", ["networks"]),
    ("the config: every section composed, training's own (train, run), what runs saved read back", ["config"]),
    ("the model: E and G for inference", ["model"]),
    ("training: data, trainer, runs", ["train"]),
    ("evaluation and export", ["evaluate", "export", "sheets", "bench", "viewer"]),
    ("the quickstart pipelines", ["quickstart"]),
    ("command line", ["cli", "console"]),
]



def layer(module: str) -> int:
    """The index into :data:`LAYERS` of a module (the package itself: above every layer)."""
    rel = module.split(".", 1)[1] if "." in module else None
    if rel is None:
        return len(LAYERS)
    for i, (_, prefixes) in enumerate(LAYERS):
        if any(rel == p or rel.startswith(p + ".") for p in prefixes):
            return i
    raise KeyError(f"{module} is in no layer of LAYERS: add it to the one it belongs to")


def test_every_module_has_a_layer():
    for name in modules():
        layer(name)


def test_no_module_imports_a_layer_above_its_own():
    """No exception: every import, at the top or in a function, goes to its own layer or one below
    (issue 44 removed the last, the model's of the checkpoint loader, by putting the model above it)."""
    upward = []
    for e in imports(modules()):
        if layer(e.target) > layer(e.source):
            upward.append(f"  {modules()[e.source].relative_to(PACKAGE.parent)}:{e.line} → {e.target}: "
                          f"{LAYERS[layer(e.source)][0]} → {LAYERS[layer(e.target)][0]}")
    assert not upward, "imports up the data flow:\n" + "\n".join(upward)


def test_the_backends_import_nothing_of_the_dispatcher():
    """The renderer's face (``render/__init__.py``: ``render``, ``render_with``) is the one dispatcher
    and sits above its backends: no module of ``render/`` imports it but the turntables
    (``render/frames.py``), which render through it. A child's import of its own package is no edge
    of :func:`imports` by default, so the layers alone would not see one."""
    face = "mitsuba_platonic.render"
    back = [f"  {modules()[e.source].relative_to(PACKAGE.parent)}:{e.line} → {e.target}"
            for e in imports(modules(), parents=True)
            if e.target == face and e.source.startswith(face + ".") and e.source != face + ".frames"]
    assert not back, "the backends import the dispatcher:\n" + "\n".join(back)


def test_the_checkpoint_loader_imports_no_training_code_and_the_model_imports_it():
    """What runs saved is read without the trainer, its data or its runs, and the model reads its
    checkpoints through it at the top of its module, as a layer above."""
    edges = imports(modules())
    from_loading = {e.target for e in edges if e.source == "mitsuba_platonic.config.loading"}
    assert not {t for t in from_loading if t.startswith("mitsuba_platonic.train")}, from_loading
    assert any(e.target == "mitsuba_platonic.config.loading" and not e.lazy for e in edges
               if e.source == "mitsuba_platonic.model")
    assert layer("mitsuba_platonic.config.loading") < layer("mitsuba_platonic.train.trainer")


def test_the_config_imports_nothing_of_training():
    """The back-import is gone (issue 44): the config composed the train and run sections from inside
    ``train/``, whose runs and trainer import the config, so the training package straddled the config
    (its ``__init__`` had to import lazily, and the structure listed five of its modules apart). The
    two sections and every training choice list are the config's now: nothing in ``config/`` (nor
    anything else below training) imports ``train/``, which sits whole in one layer."""
    edges = imports(modules())
    back = [f"  {modules()[e.source].relative_to(PACKAGE.parent)}:{e.line} → {e.target}" for e in edges
            if e.source.split(".")[:2] == ["mitsuba_platonic", "config"] and e.target.startswith("mitsuba_platonic.train")]
    assert not back, "the config imports training:\n" + "\n".join(back)
    assert [p for _, prefixes in LAYERS for p in prefixes if p == "train" or p.startswith("train.")] == ["train"]


def test_an_import_up_a_layer_is_found_and_named(tmp_path):
    """The check itself: a module of a low layer that imports one of a higher layer, even inside a
    function, is reported."""
    pkg = tmp_path / "mitsuba_platonic"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "errors.py").write_text("def f():\n    from .config import x\n    return x\n")
    (pkg / "config.py").write_text("x = 1\n")
    edges = imports(modules(pkg))
    up = [e for e in edges if layer(e.target) > layer(e.source)]
    assert up == [Import("mitsuba_platonic.errors", "mitsuba_platonic.config", 2, True)]


#: Modules whose function-level imports of the package are lazy by design, and why.
LAZY_BY_DESIGN = {
    "mitsuba_platonic.cli": "each command imports what it runs when it runs: --help and a wrong flag answer "
                            "without importing torch, Mitsuba or the trainer (the package and its modules)",
}


def lazy_by_design(module: str) -> bool:
    """Whether ``module`` is, or is inside, a package of :data:`LAZY_BY_DESIGN`."""
    return any(module == m or module.startswith(m + ".") for m in LAZY_BY_DESIGN)


def test_each_function_level_import_of_the_package_says_why():
    """A function-level import of a package module hides nothing: it has a comment saying why (on its
    line or the comment lines right above it), or its module is lazy by design (:data:`LAZY_BY_DESIGN`).
    Optional heavy third-party imports (Dr.Jit, Mitsuba, matplotlib, scipy) are not this test's."""
    silent = []
    for e in imports(modules()):
        if not e.lazy or lazy_by_design(e.source):
            continue
        lines = modules()[e.source].read_text().split("\n")
        above, k = [], e.line - 2
        while k >= 0 and lines[k].strip().startswith("#"):
            above.append(lines[k])
            k -= 1
        if "#" not in lines[e.line - 1] and not above:
            silent.append(f"  {modules()[e.source].relative_to(PACKAGE.parent)}:{e.line} → {e.target}")
    assert not silent, ("function-level imports that do not say why (import at the top, or comment why "
                        "not):\n" + "\n".join(silent))


def _says_why(lines: List[str], first: int) -> bool:
    """Whether the import starting on line ``first`` (1-based) has a comment: on its own line, on the
    comment lines right above it, or on the first import of the block of imports it ends."""
    if "#" in lines[first - 1]:
        return True
    k = first - 2
    while k >= 0 and lines[k].strip().startswith(("import ", "from ")) and "#" not in lines[k]:
        k -= 1
    return k >= 0 and "#" in lines[k] and lines[k].strip().startswith(("#", "import ", "from "))


def test_each_function_level_import_says_why():
    """Third-party imports too (issue 26): an import inside a function says why it is not at the top
    (an optional or slow dependency: ``# lazy: matplotlib is slow to import``), outside the modules
    that are lazy by design."""
    silent = []
    for name, path in modules().items():
        if lazy_by_design(name):
            continue
        text = path.read_text()
        lines = text.split("\n")
        for fn in ast.walk(ast.parse(text)):
            if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            for node in ast.walk(fn):
                if isinstance(node, (ast.Import, ast.ImportFrom)) and not _says_why(lines, node.lineno):
                    where = f"{path.relative_to(PACKAGE.parent)}:{node.lineno}"
                    silent.append(f"  {where}: {lines[node.lineno - 1].strip()}")
    assert not silent, ("function-level imports that do not say why (import at the top, or comment why "
                        "not):\n" + "\n".join(sorted(set(silent))))


def test_a_cycle_is_found_and_named(tmp_path):
    """The check itself: a module importing, inside a function, one that imports it is a cycle,
    named with the file and line of each import."""
    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "sub" / "__init__.py").write_text("from .low import x\n")
    (pkg / "sub" / "low.py").write_text("x = 1\n\ndef f():\n    from ..high import y\n    return y\n")
    (pkg / "high.py").write_text("from .sub.low import x\ny = x\n")
    edges = imports(modules(pkg))
    assert Import("pkg.high", "pkg.sub.low", 1, False) in edges
    assert Import("pkg.sub.low", "pkg.high", 4, True) in edges
    assert cycles(edges) == [["pkg.high", "pkg.sub.low"]]
    assert cycles([e for e in edges if not e.lazy]) == []


#: Where no module may import another's underscored names: the package, the benchmarks and the
#: experiment log's scripts (each folder's scripts import their neighbours by bare name).
PUBLIC_NAMES_ROOTS = [PACKAGE, PACKAGE.parent / "benchmarks", PACKAGE.parent / "lab" / "scripts"]


def private(name: str) -> bool:
    """Whether ``name`` is underscored (``_x``), not a dunder (``__version__``)."""
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def private_imports(root: Path, project: Path = PACKAGE.parent) -> List[str]:
    """``path:line name`` for every underscored name that a module under ``root`` takes from another
    module of the project: by ``from ... import _name`` (relative, from ``mitsuba_platonic``, or from a
    script of the same folder), or as ``module._name`` of a module it imported by name (``import
    mitsuba_platonic.x as M``, ``from mitsuba_platonic import x as M``, ``import neighbour``).
    ``project``: the folder that holds ``mitsuba_platonic/`` (paths are named from it)."""
    found: List[str] = []
    for path in sorted(root.rglob("*.py")):
        neighbours = {p.stem for p in path.parent.glob("*.py")} - {path.stem}
        tree = ast.parse(path.read_text(), str(path))
        where = path.relative_to(project)
        aliases: Set[str] = set()                       # local names bound to a project module
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                module = node.module or ""
                ours = node.level > 0 or module.split(".")[0] in {"mitsuba_platonic"} | neighbours
                if not ours:
                    continue
                for alias in node.names:
                    if private(alias.name):
                        found.append(f"{where}:{node.lineno} {alias.name}")
                    elif node.level == 0 and module.split(".")[0] == "mitsuba_platonic":
                        full = f"{module}.{alias.name}".replace(".", "/")
                        if (project / f"{full}.py").is_file() or (project / full / "__init__.py").is_file():
                            aliases.add(alias.asname or alias.name)
                    elif node.level > 0:
                        aliases.add(alias.asname or alias.name)   # a name or a module: either, _x on it is theirs
            elif isinstance(node, ast.Import):
                for alias in node.names:
                    if alias.name.split(".")[0] in {"mitsuba_platonic"} | neighbours:
                        aliases.add(alias.asname or alias.name.split(".")[0])
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and private(node.attr) and isinstance(node.value, ast.Name)
                    and node.value.id in aliases):
                found.append(f"{where}:{node.lineno} {node.value.id}.{node.attr}")
    return found


def test_no_module_imports_an_underscored_name_from_another():
    """Public names between modules (issue 57): what two modules share has a public name, documented,
    in a module of its own where neither owns it; a benchmark or a script of the log uses the
    package's public face. Names read by ``importlib`` at run time are not seen."""
    found = [f for root in PUBLIC_NAMES_ROOTS for f in private_imports(root)]
    assert not found, f"{len(found)} underscored names taken from another module:\n  " + "\n  ".join(found)


def test_an_underscored_import_is_found_and_named(tmp_path):
    """The check itself: ``from .x import _y``, ``from mitsuba_platonic.x import _y``, a neighbour
    script's ``_y`` and ``M._y`` of an imported module are found; a dunder, a public name and a
    third party's private module are not."""
    pkg = tmp_path / "mitsuba_platonic"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("__version__ = '1'\n")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "sub" / "low.py").write_text("_x = 1\ny = 2\n")
    (pkg / "sub" / "high.py").write_text("from .low import _x, y\nfrom .. import __version__\n")
    (pkg / "user.py").write_text("import mitsuba_platonic.sub.low as L\nfrom mitsuba_platonic.sub import low\n"
                                 "from viser._image_encoding import encode\nz = L._x + low._x + low.y\n")
    scripts = tmp_path / "scripts"
    scripts.mkdir()
    (scripts / "helper.py").write_text("_h = 1\n")
    (scripts / "main.py").write_text("from helper import _h\nfrom mitsuba_platonic.sub.low import _x\n")
    assert private_imports(pkg, tmp_path) == ["mitsuba_platonic/sub/high.py:1 _x", "mitsuba_platonic/user.py:4 L._x",
                                              "mitsuba_platonic/user.py:4 low._x"]
    assert private_imports(scripts, tmp_path) == ["scripts/main.py:1 _h", "scripts/main.py:2 _x"]
