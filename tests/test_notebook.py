"""examples/quickstart.ipynb runs, cell by cell, in a Jupyter kernel of this
interpreter (a kernel spec written for the test names sys.executable, so the
kernel is the environment's Python, not whatever "python3" a machine has),
from the examples/ folder as a user opens it; it is committed without outputs."""

import json
import os
import sys

import pytest
from conftest import ROOT

NOTEBOOK = ROOT / "examples" / "quickstart.ipynb"
KERNEL = "oclgi-test-python"


def test_the_notebook_is_committed_without_outputs():
    code = [c for c in json.loads(NOTEBOOK.read_text())["cells"] if c["cell_type"] == "code"]
    assert len(code) >= 4 and all(c["outputs"] == [] and c["execution_count"] is None for c in code)


@pytest.fixture
def kernel_of_this_python(tmp_path, monkeypatch):
    spec = tmp_path / "kernels" / KERNEL
    spec.mkdir(parents=True)
    path = os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH")) if p)
    (spec / "kernel.json").write_text(json.dumps({
        "argv": [sys.executable, "-m", "ipykernel_launcher", "-f", "{connection_file}"],
        "display_name": "oclgi tests", "language": "python", "env": {"PYTHONPATH": path}}))
    monkeypatch.setenv("JUPYTER_PATH", str(tmp_path))
    monkeypatch.setenv("JUPYTER_PLATFORM_DIRS", "1")  # jupyter_core's own paths, without a warning
    return KERNEL


def test_the_quickstart_notebook_runs(kernel_of_this_python):
    import nbformat
    from nbclient import NotebookClient

    nb = nbformat.read(NOTEBOOK, as_version=4)
    nb.cells.append(nbformat.v4.new_code_cell("import sys\nprint(sys.executable)"))
    NotebookClient(nb, timeout=300, kernel_name=kernel_of_this_python,
                   resources={"metadata": {"path": str(NOTEBOOK.parent)}}).execute()
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert not [o for c in code for o in c.outputs if o.output_type == "error"]

    def text(cell):
        return "".join(o.get("text", "") for o in cell.outputs if o.output_type == "stream"
                       and o.name == "stdout") + "".join(o.get("data", {}).get("text/plain", "")
                                                         for o in cell.outputs)

    render = next(c for c in code if "engine.render(" in c.source)
    pngs = [o.data["image/png"] for o in render.outputs if o.output_type == "execute_result"]
    assert pngs and pngs[0].startswith("iVBORw0KGgo")  # the render shown inline, a base64 PNG
    assert "detp_disc_index: 100,000 photons" in text(render)
    sensors = next(c for c in code if "engine.irradiance(" in c.source)
    assert text(sensors).startswith("array([[") and text(sensors).count("[") == 4  # (3, 3)
    session = next(c for c in code if "session.move(" in c.source)
    assert "paths traced again" in text(session) and text(code[-1]).strip() == sys.executable
    # progress went to stderr (or a widget), never into stdout
    assert not any("%|" in o.get("text", "") for c in code for o in c.outputs
                   if o.output_type == "stream" and o.name == "stdout")
    assert not any("Warning" in o.get("text", "") for c in code for o in c.outputs if o.output_type == "stream")
