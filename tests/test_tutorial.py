"""docs/tutorials/tutorial.ipynb runs as shipped: every code cell, in order, in one namespace."""

import json
from pathlib import Path

import matplotlib

NOTEBOOK = Path(__file__).parent.parent / "docs" / "tutorials" / "tutorial.ipynb"


def test_the_tutorial_notebook_runs(tmp_path, monkeypatch):
    matplotlib.use("Agg")  # as a headless kernel would; the notebook itself sets no backend
    import matplotlib.pyplot as plt

    cells = [c for c in json.loads(NOTEBOOK.read_text())["cells"] if c["cell_type"] == "code"]
    assert len(cells) >= 6
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    for number, cell in enumerate(cells):
        exec(compile("".join(cell["source"]), f"tutorial.ipynb cell {number}", "exec"), namespace)
    table = namespace["table"]
    assert len(table) == 6 and "phase" in table
    assert (tmp_path / "out" / "tutorial.h5").exists()
    assert namespace["rod"].positions.dims == ("node", "xyz")
    assert plt.get_fignums()  # the plotting cells drew into figures of their own
    plt.close("all")
