"""The notebooks are executed so they never rot (short chains; see each notebook), show
their figures (inline images, not a silent Agg backend), and are stored executed so that
a reader on the web sees the figures without running anything."""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import pytest

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")

NOTEBOOKS = sorted((Path(__file__).resolve().parents[1] / "notebooks").glob("*.ipynb"))
#: Notebooks shipped with their outputs (re-run them with
#: `jupyter nbconvert --to notebook --execute --inplace NOTEBOOK` after changing them).
STORED_EXECUTED = ["discover-missing-effect.ipynb", "posterior.ipynb"]


def _figure_cells(nb) -> list[int]:
    """Code cells that draw: they call a plot method or pyplot."""
    return [i for i, c in enumerate(nb.cells) if c.cell_type == "code"
            and (".plot" in c.source or "plt." in c.source)]


def _has_image(cell) -> bool:
    return any("image/png" in o.get("data", {}) for o in cell.get("outputs", []))


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.name for p in NOTEBOOKS])
def test_notebook_does_not_hide_its_figures(path):
    # matplotlib.use("Agg") + plt.show() shows nothing in Jupyter or nbconvert (issue 18).
    nb = nbformat.read(path, as_version=4)
    src = "\n".join(c.source for c in nb.cells if c.cell_type == "code")
    assert 'matplotlib.use("Agg")' not in src and "matplotlib.use('Agg')" not in src


@pytest.mark.parametrize("name", STORED_EXECUTED)
def test_notebook_is_stored_executed_with_figures(name):
    path = NOTEBOOKS[0].parent / name
    nb = nbformat.read(path, as_version=4)
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert all(c.get("execution_count") for c in code), "run the notebook and save it"
    counts = [c.execution_count for c in code]
    assert counts == sorted(counts), "cells were run out of order"
    figures = _figure_cells(nb)
    assert figures
    missing = [i for i in figures if not _has_image(nb.cells[i])]
    assert not missing, f"cells {missing} draw a figure but hold no image"
    errors = [o for c in code for o in c.get("outputs", []) if o.get("output_type") == "error"]
    assert not errors
    # no machine-specific paths in what a reader sees
    text = json.dumps([o for c in code for o in c.get("outputs", []) if o.get("output_type") == "stream"])
    assert "/tmp/" not in text and "/home/" not in text and "/work/" not in text


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.name for p in NOTEBOOKS])
def test_notebook_executes(path, monkeypatch):
    monkeypatch.setenv("HDID_NOTEBOOK_STEPS", os.environ.get("HDID_NOTEBOOK_STEPS", "300"))
    nb = nbformat.read(path, as_version=4)
    client = nbclient.NotebookClient(
        nb, timeout=900, kernel_name="python3", resources={"metadata": {"path": str(path.parent)}}
    )
    client.execute()  # raises CellExecutionError on any failing cell (including its asserts)
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", []) if o.get("output_type") == "error"]
    assert not errors
    missing = [i for i in _figure_cells(nb) if not _has_image(nb.cells[i])]
    assert not missing, f"cells {missing} draw a figure but show no image"


#: Statements a notebook's text (markdown or code comments) makes about what its stored
#: outputs print: (what the text says, what the output prints), each a pattern whose
#: groups must agree. The SMC size is the one stated today ("4 runs × 300 particles").
STATED = [
    (r"(\d+) runs × (\d+) particles", r"(\d+) independent runs × (\d+) particles"),
]


@pytest.mark.parametrize("name", STORED_EXECUTED)
def test_notebook_text_agrees_with_its_outputs(name):
    nb = nbformat.read(NOTEBOOKS[0].parent / name, as_version=4)
    said = "\n".join(c.source if c.cell_type == "markdown" else
                     "\n".join(line.partition("#")[2] for line in c.source.splitlines())
                     for c in nb.cells)
    printed = "\n".join(o.get("text", "") for c in nb.cells if c.cell_type == "code"
                        for o in c.get("outputs", []) if o.get("output_type") == "stream")
    for claim, output in STATED:
        shown = set(re.findall(output, printed))
        for stated in re.findall(claim, said):
            assert not shown or stated in shown, (
                f"{name}: the text says {stated} ({claim}), the stored output prints {sorted(shown)}")
