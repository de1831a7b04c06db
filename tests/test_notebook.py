"""The example notebook ``docs/examples/first_run.ipynb`` runs top to bottom in a Jupyter kernel
(nbclient, ipykernel) and shows what it says: the results with their units, the run figure,
two runs compared. It is kept without outputs (no run figure is committed by hand)."""

from __future__ import annotations

import os
import struct
from base64 import b64decode
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
NOTEBOOK = ROOT / "docs" / "examples" / "first_run.ipynb"


def test_notebook_is_kept_without_outputs() -> None:
    nbformat = pytest.importorskip("nbformat")
    nb = nbformat.read(NOTEBOOK, as_version=4)
    nbformat.validate(nb)
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert code and all(not c.outputs and c.execution_count is None for c in code)


@pytest.mark.slow
def test_notebook_runs_and_shows_units_figure_and_comparison(tmp_path: Path,
                                                             monkeypatch: pytest.MonkeyPatch
                                                             ) -> None:
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    pytest.importorskip("ipykernel")
    # the kernel imports this checkout's cosim, whatever is installed
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(
        filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])))
    nb = nbformat.read(NOTEBOOK, as_version=4)
    nbclient.NotebookClient(nb, timeout=600, kernel_name="python3",
                            resources={"metadata": {"path": str(tmp_path)}}).execute()
    outputs = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs]
    assert not [o for o in outputs if o.output_type == "error"]
    html = [o.data["text/html"] for o in outputs if "text/html" in o.get("data", {})]
    head = next(h for h in html if ">unit<" in h)  # the (variable, unit) header of the head
    assert ">m/s<" in head and ">plant.v<" in head
    assert any(">nominal<" in h and ">10 % heavier<" in h and ">stop_error_m<" in h
               for h in html)
    pngs = [b64decode(o.data["image/png"]) for o in outputs if "image/png" in o.get("data", {})]
    assert len(pngs) == 1 and pngs[0][:8] == b"\x89PNG\r\n\x1a\n"
    width, height = struct.unpack(">II", pngs[0][16:24])  # the IHDR chunk
    assert width > 100 and height > 100
