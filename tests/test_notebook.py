"""The lesson notebook, examples/lesson.ipynb, runs top to bottom in a fresh kernel.

Its cells check the lesson's mathematics with ``assert`` (the rank of ``Jc``, the analytic Jacobian
against finite differences, ``Lambda_c`` positive definite, the KKT solve against the library's stance
dynamics, the foot drift of the pinned simulation, the lift-off on the unilateral ground), so a wrong
result fails this test as an error would. The notebook is stored without outputs.
"""

import time
from pathlib import Path

import nbformat
from nbclient import NotebookClient

NOTEBOOK = Path(__file__).resolve().parents[1] / "examples" / "lesson.ipynb"
TIME_LIMIT = 60.0  # [s] the whole notebook, kernel start included (about 3 s on 2 cores)


def test_the_lesson_notebook_runs_without_error(tmp_path, monkeypatch):
    monkeypatch.setenv("MPLBACKEND", "Agg")  # the kernel inherits the environment: no display
    nb = nbformat.read(NOTEBOOK, as_version=4)
    client = NotebookClient(nb, timeout=120, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}})
    start = time.perf_counter()
    client.execute()  # raises CellExecutionError on the first failing cell (an assert included)
    elapsed = time.perf_counter() - start
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs if o.output_type == "error"]
    assert not errors
    assert elapsed < TIME_LIMIT, f"the notebook took {elapsed:.1f} s"


def test_the_notebook_is_stored_without_outputs():
    nb = nbformat.read(NOTEBOOK, as_version=4)
    nbformat.validate(nb)
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert code
    assert all(not c.outputs and c.execution_count is None for c in code), "clear the outputs before committing"
