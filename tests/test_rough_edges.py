"""Issue 30: the rough edges a user hits first, each reproduced as the user met it."""

import inspect
import os
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

import rodphase
from rodphase import api, runner
from rodphase import config as C
from rodphase import store as st
from rodphase.cli import _escapes_line, main
from rodphase.result import HISTORY_COLUMNS, RunResult


def cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def one_error(out, *words):
    """Exit 2, exactly one 'error:' line naming every word, no traceback."""
    errors = [ln for ln in out.output.splitlines() if ln.startswith("error:")]
    assert out.exit_code == 2, out.output
    assert len(errors) == 1, out.output
    assert "Traceback" not in out.output and out.exception is None or isinstance(
        out.exception, SystemExit), out.output
    for word in words:
        assert word in errors[0], errors[0]
    return errors[0]


def straight_run(n=8, rows=6, stages=("hold 0",), turns=0.3, status="ok") -> RunResult:
    """A stored-looking run of a straight rod along z, turned `turns` and held."""
    history = {name: np.zeros(rows) for name in HISTORY_COLUMNS}
    history["time"] = np.linspace(0.0, 1.0, rows)
    history["end_rotation"] = np.full(rows, 2 * np.pi * turns)
    history["applied_force"] = np.full(rows, 10.0)
    history["end_force"] = np.full(rows, 10.0)
    history["end_displacement"] = np.full(rows, 0.05)
    history["stage"] = np.zeros(rows)
    for key in ("link", "twist"):
        history[key] = np.full(rows, turns)
    history["writhe"] = np.zeros(rows)
    positions = np.zeros((n + 1, 3))
    positions[:, 2] = np.linspace(0.0, 1.05, n + 1)
    return RunResult(
        status=status, message="completed", positions=positions,
        directors=np.tile(np.eye(3), (n, 1, 1)), radii=np.full(n, 0.025),
        rest_lengths=np.full(n, 1.0 / n), history=history,
        snapshot_positions=positions[None].copy(), snapshot_d1=np.tile([1.0, 0, 0], (1, n, 1)),
        snapshot_rows=np.array([rows - 1]),
        diagnostics={"steps": 100, "wall_time": 0.1, "rest_radius": 0.025, "rest_length": 1.0,
                     "youngs_modulus": 1e6, "elements": n, "notes": [],
                     "stages": [{"label": label} for label in stages]},
        stage_ends=[rows - 1])


def writer(path):
    return st.open_store(path, config_text="sweep: {}\n", config_hash="h", version="0.1.0",
                         kind="sweep")


# ---------------------------------------------------------------- snapshots that cannot fit

def test_a_history_interval_whose_snapshots_cannot_fit_is_refused_before_anything(
        tmp_path, monkeypatch):
    # the user's run took its whole simulation, then died allocating 385 MiB (exit 1)
    monkeypatch.setattr(runner, "available_memory", lambda: 100 * 2**20)
    out = tmp_path / "out.h5"
    line = one_error(cli("run", "twist_under_load", "-o", out, "--set", "rod.elements=20",
                         "--set", "output.history_interval=1e-7"),
                     "output.history_interval", "1e-07", "snapshots", "MiB", "available")
    assert "at least" in line
    assert not out.exists() and not list(tmp_path.iterdir())
    one_error(cli("sweep", "quick", "-o", out, "--set", "output.history_interval=1e-7"),
              "output.history_interval", "run-000")
    assert not list(tmp_path.iterdir())
    with pytest.raises(C.ConfigError, match="output.history_interval"):
        rodphase.run("twist_under_load", output__history_interval=1e-7)
    # the shipped interval fits easily
    runner.check_memory(rodphase.load("twist_under_load"))


def test_the_memory_available_heeds_an_address_space_limit():
    code = ("import resource; resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30)); "
            "from rodphase.runner import available_memory; print(available_memory())")
    got = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert float(got.stdout) < 3 * 2**30


# ---------------------------------------------------------------- plot and classify, any store

@pytest.mark.parametrize("kind", ["phase", "topology", "force", "response", "shape", "hat",
                                  "path"])
def test_every_plot_of_an_empty_store_is_one_line(tmp_path, kind):
    path = tmp_path / "empty.h5"
    writer(path).close()  # a sweep killed before its first run
    png = tmp_path / "x.png"
    one_error(cli("plot", path, "--kind", kind, "-o", png), "empty.h5", "no finished runs")
    assert not png.exists()
    one_error(cli("classify", path), "empty.h5", "no finished runs")


def test_a_hat_curve_of_a_run_that_is_not_turned_says_so(tmp_path):
    path = tmp_path / "sweep.h5"
    with writer(path) as store:
        store.write_run("run-00000", {"twist_density": 0.3}, straight_run(), {})
    png = tmp_path / "hat.png"
    one_error(cli("plot", path, "--kind", "hat", "-o", png), "--kind hat", "hat_curve")
    assert not png.exists()


def test_a_store_being_written_is_drawn_and_classified_so_far(tmp_path):
    path = tmp_path / "live.h5"
    with writer(path) as store:  # the sweep holds the store and has two runs
        for i in range(2):
            store.write_run(f"run-0000{i}", {"twist_density": 0.2 * (i + 1), "extension": 1.05},
                            straight_run(turns=0.1 * (i + 1)), {})
        png = tmp_path / "phase.png"
        out = cli("plot", path, "--kind", "phase", "-o", png)
        assert out.exit_code == 0, out.output
        assert png.stat().st_size > 0 and "error" not in out.output
        assert "2 of 2 runs classified for this figure only" in out.output
        csv = tmp_path / "live.csv"
        out = cli("classify", path, "--csv", csv)
        assert out.exit_code == 0, out.output
        assert "2 runs: straight 2" in out.output
        assert [ln for ln in out.output.splitlines() if ln.startswith("note:")]
        assert pd.read_csv(csv)["phase"].tolist() == ["straight", "straight"]
    # once the sweep has ended, classify stores it and plot needs nothing more
    assert cli("classify", path).exit_code == 0
    out = cli("plot", path, "--kind", "phase", "-o", tmp_path / "again.png")
    assert out.exit_code == 0 and "classified for this figure" not in out.output


def test_an_unknown_run_id_is_named_without_stray_quotes(tmp_path):
    path = tmp_path / "s.h5"
    with writer(path) as store:
        store.write_run("run-00000", {}, straight_run(), {})
    for args in (("plot", path, "--kind", "topology", "--run", "run-99999", "-o",
                  tmp_path / "x.png"),
                 ("movie", path, "--run", "run-99999", "-o", tmp_path / "x.gif"),
                 ("export", path, "--run", "run-99999", "-o", tmp_path / "x.vtk")):
        line = one_error(cli(*args), "run-00000")
        assert line.startswith("error: --run: 'run-99999'"), line
        assert '"' not in line


# ---------------------------------------------------------------- names and help

def test_a_misspelt_scene_or_sweep_gets_the_near_name(tmp_path):
    one_error(cli("run", "twist_under_lod", "-o", tmp_path / "x.h5"),
              "twist_under_lod", "did you mean 'twist_under_load'")
    one_error(cli("sweep", "quik", "-o", tmp_path / "x.h5"), "did you mean 'quick'")
    assert not list(tmp_path.iterdir())


def test_scenes_lists_whole_sentences():
    out = CliRunner().invoke(main, ["scenes"], env={"COLUMNS": "100"})
    text = " ".join(out.output.split())
    # these were cut at the end of their first comment line
    assert "rest length L0: the paper's material coordinate" in text
    assert "rod, n = 80." in text and "on two cores once numba has compiled." in text


def test_plot_help_names_the_formats_it_writes():
    text = CliRunner().invoke(main, ["plot", "--help"]).output
    assert ".pdf" in text and ".svg" in text and "PNG file." not in text


def test_a_run_that_lost_link_says_how_many_escapes_and_turns():
    result = straight_run(rows=4, turns=-6.366)
    result.history["link"] = np.array([0.0, -3.0, -5.0, -4.365])
    result.history["link_escapes"] = np.array([0.0, 2.0, 4.0, 5.0])
    result.diagnostics["notes"] = ["link left the rod 5 time(s) (ΔLk +1.00 at t = 13.8 s, "
                                   "+1.00 at t = 14 s)"]
    line = _escapes_line(result)
    assert "5 escape(s)" in line and "-6.366 turns put in" in line and "+2.00 turns" in line
    assert "t = 13.8 s" in line
    result.history["link_escapes"] = np.zeros(4)
    assert _escapes_line(result) == ""


# ---------------------------------------------------------------- the Python API

def test_store_mismatch_from_python_names_the_keyword(tmp_path):
    path = tmp_path / "quick.h5"
    with st.open_store(path, config_text="x: 1\n", config_hash="another", version="0",
                       kind="sweep") as store:
        store.write_run("a", {}, straight_run(), {})
    with pytest.raises(st.StoreMismatch) as caught:
        rodphase.run_sweep("quick", path, sweep__samples=1, progress=False)
    assert "replace=True" in str(caught.value) and "--force" not in str(caught.value)


def test_the_first_run_announces_compiling(monkeypatch):
    said = []
    monkeypatch.setattr(api, "_warm", False)
    monkeypatch.setattr(api, "COMPILE_NOTICE_AFTER", 0.05)
    monkeypatch.setattr(runner, "compile_kernel", lambda: (__import__("time").sleep(0.3), 0.3)[1])
    api._warm_kernel(said.append)
    assert said[0].startswith("Compiling the kernel") and "ready in" in said[1]
    api._warm_kernel(said.append)  # once per process
    assert len(said) == 2
    calls = []
    monkeypatch.setattr(api, "_warm_kernel", lambda: calls.append(1))
    monkeypatch.setattr(runner, "run_scene", lambda cfg: straight_run())
    rodphase.run("twist_under_load")
    assert calls == [1]


def test_run_sweep_defaults_to_the_cores_and_progress_when_someone_watches(tmp_path,
                                                                          monkeypatch):
    from rodphase import sweep

    sig = inspect.signature(rodphase.run_sweep)
    assert sig.parameters["jobs"].default is None and sig.parameters["progress"].default is None
    seen = {}

    def fake(sweep_cfg, scene_cfg, out, **kwargs):
        seen.update(kwargs)
        return sweep.SweepReport(0, 0, 0, 0, 0.0, [])

    monkeypatch.setattr(sweep, "run_sweep", fake)
    monkeypatch.setattr(api, "classify_file", lambda path: None)
    monkeypatch.setattr(api, "interactive", lambda: True)
    rodphase.run_sweep("quick", tmp_path / "q.h5", sweep__samples=2)
    assert seen["jobs"] == os.cpu_count() and seen["progress"] is True
    monkeypatch.setattr(api, "interactive", lambda: False)
    rodphase.run_sweep("quick", tmp_path / "q.h5", sweep__samples=2, jobs=1)
    assert seen["jobs"] == 1 and seen["progress"] is False


def test_short_reprs_and_names_visible_to_dir(tmp_path):
    result = straight_run(n=60, rows=400)
    text = repr(result)
    assert len(text) < 400 and "status='ok'" in text and "elements=60" in text
    assert "link=" in text and "400 rows" in text
    path = tmp_path / "s.h5"
    with writer(path) as store:
        store.write_run("run-00000", {}, result, {})
    with rodphase.open(path) as store:
        text = repr(store)
        assert "s.h5" in text and "1 run" in text and "read-only" in text
    assert {"run", "load", "run_sweep", "open", "table", "histories"} <= set(dir(rodphase))


def test_history_as_a_dataframe_keeps_the_dict():
    result = straight_run(rows=5)
    frame = result.history_frame
    assert isinstance(result.history, dict) and list(frame.columns) == list(result.history)
    np.testing.assert_array_equal(frame["end_force"], result.history["end_force"])
    assert frame.attrs["units"]["end_force"] == "N" and frame.attrs["units"]["link"] == "turns"


# ---------------------------------------------------------------- self-describing tables

def test_the_stored_classification_and_the_csv_describe_themselves(tmp_path):
    import json

    import h5py

    path = tmp_path / "s.h5"
    with writer(path) as store:
        store.write_run("run-00000", {"twist_density": 0.4, "extension": 1.1}, straight_run(), {})
        store.write_run("run-00001", {"twist_density": 0.8, "extension": 1.2},
                        straight_run(status="not_converged"), {})
    csv = tmp_path / "s.csv"
    assert cli("classify", path, "--csv", csv).exit_code == 0
    with h5py.File(path, "r") as f:
        g = f["classification"]
        # the sample's parameters and status stand beside its labels, every column has a unit
        assert {"twist_density", "extension", "status", "phase", "link"} <= set(g)
        assert list(g["status"].asstr()[()]) == ["ok", "not_converged"]
        assert g["twist_density"][1] == 0.8
        assert g["link"].attrs["units"] == "turns" and g["end_force"].attrs["units"] == "N"
        assert "L/L0" in g["extension"].attrs["long_name"]
        diagnostics = f["runs/run-00000"].attrs["diagnostics"]
    assert "\n" in diagnostics and json.loads(diagnostics)["steps"] == 100  # readable text
    table = st.read_table(path)  # the API's table is as before: no repeated columns
    assert not [c for c in table.columns if c.endswith("_classified")]
    assert table["status"].tolist() == ["ok", "not_converged"]
    frame = pd.read_csv(csv)
    assert {"twist_density", "extension", "status", "phase"} <= set(frame.columns)
    meta = json.loads((tmp_path / "s.csv-metadata.json").read_text())
    units = {c["name"]: c["unit"] for c in meta["tableSchema"]["columns"]}
    assert list(units) == list(frame.columns)
    assert units["wall_time"] == "s" and units["writhe"] == "turns"


@pytest.mark.parametrize("args, line", [
    (["plot", "missing.h5", "-o", "x.png"],
     "error: Invalid value for 'OUT.h5': File 'missing.h5' does not exist. "
     "(see rodphase plot --help)"),
    (["run", "twist_under_load", "--bogus"],
     "error: No such option '--bogus'. (see rodphase run --help)"),
    (["sweep"], "error: Missing argument 'SWEEP.yaml'. (see rodphase sweep --help)"),
])
def test_clicks_own_refusals_are_one_error_line_too(tmp_path, args, line):
    # a file that does not exist, an unknown option, a missing argument: the same contract
    # as every other bad input (one line on stderr, exit 2), not click's usage block
    result = subprocess.run([sys.executable, "-m", "rodphase.cli", *args], cwd=tmp_path,
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 2
    assert result.stderr.strip() == line, result.stderr
    assert list(tmp_path.iterdir()) == []
