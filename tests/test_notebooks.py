"""The notebooks of notebooks/: each runs top to bottom in a fresh kernel at a reduced size, and the
committed files carry no outputs.

The kernel is the venv's own Python (nbclient starts the ``python3`` kernel spec with the
interpreter running pytest; the first test checks it). ``MP_NOTEBOOK_SMALL=1`` makes each
notebook's parameters cell pick its test size; ``MP_NOTEBOOK_OUT`` sends what it writes to a
temporary folder instead of ``notebooks/_out/``. A cell that raises fails the test with the
cell's traceback.
"""

import sys
from pathlib import Path

import pytest

nbformat = pytest.importorskip("nbformat", reason="the notebook tests need the test extra: pip install -e '.[test]'")
nbclient = pytest.importorskip("nbclient", reason="the notebook tests need the test extra: pip install -e '.[test]'")

NOTEBOOKS = Path(__file__).resolve().parents[1] / "notebooks"
PATHS = sorted(NOTEBOOKS.glob("*.ipynb"))
IDS = [p.stem for p in PATHS]
CELL_TIMEOUT = 120           # seconds per cell
NOTEBOOK_TIMEOUT = 150       # seconds per notebook (pytest-timeout), kernel start included


def test_there_are_notebooks():
    assert [p.name for p in PATHS] == ["01_renderers.ipynb", "02_collection.ipynb", "03_train_inspect.ipynb",
                                       "04_own_photos.ipynb"]


@pytest.mark.parametrize("path", PATHS, ids=IDS)
def test_committed_notebook_is_clean(path):
    """No outputs, no execution counts, and a first code cell tagged ``parameters`` (papermill)."""
    nb = nbformat.read(path, as_version=4)
    nbformat.validate(nb)
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert code, f"{path.name} has no code cell"
    assert "parameters" in code[0].metadata.get("tags", []), \
        f"{path.name}: the first code cell must be the parameters cell, tagged 'parameters'"
    assert "MP_NOTEBOOK_SMALL" in code[0].source, f"{path.name}: the parameters cell must read MP_NOTEBOOK_SMALL"
    dirty = [i for i, c in enumerate(nb.cells) if c.cell_type == "code" and (c.outputs or c.execution_count)]
    assert not dirty, (f"{path.name}: cells {dirty} carry outputs or execution counts; strip them before "
                       f"committing (jupyter nbconvert --clear-output --inplace {path.name})")


@pytest.mark.slow
@pytest.mark.parametrize("path", PATHS, ids=IDS)
@pytest.mark.timeout(NOTEBOOK_TIMEOUT)
def test_notebook_runs_at_test_size(path, tmp_path, monkeypatch):
    monkeypatch.setenv("MP_NOTEBOOK_SMALL", "1")
    monkeypatch.setenv("MP_NOTEBOOK_OUT", str(tmp_path))
    nb = nbformat.read(path, as_version=4)
    probe = nbformat.v4.new_code_cell("import sys; print(sys.prefix)")
    nb.cells.insert(0, probe)
    client = nbclient.NotebookClient(nb, timeout=CELL_TIMEOUT, kernel_name="python3",
                                     resources={"metadata": {"path": str(NOTEBOOKS)}})
    client.execute()                 # raises CellExecutionError (with the cell's traceback) on any error
    printed = "".join(o.get("text", "") for o in nb.cells[0].outputs).strip()
    assert printed == sys.prefix, f"the kernel ran {printed!r}, not this interpreter's environment {sys.prefix!r}"
    figures = sum("image/png" in o.get("data", {}) for c in nb.cells if c.cell_type == "code" for o in c.outputs)
    assert figures > 0, f"{path.name} drew no inline figure"
