"""HDF5 store: round trip, resume semantics, config mismatch, crash safety, tables."""

import h5py
import numpy as np
import pandas as pd
import pytest

from rodphase import store as st
from rodphase.result import HISTORY_COLUMNS, RunResult

CONFIG = "sweep:\n  samples: 4\n"
HASH = "a1b2c3"


def fake_result(status="ok", n=6, rows=5, seed=0) -> RunResult:
    rng = np.random.default_rng(seed)
    history = {name: rng.normal(size=rows) for name in HISTORY_COLUMNS}
    history["stage"] = np.arange(rows) // 3
    history["link"] = np.linspace(0, 2, rows)
    return RunResult(
        status=status,
        message="completed" if status == "ok" else "unstable at t = 1 s",
        positions=rng.normal(size=(n + 1, 3)),
        directors=rng.normal(size=(n, 3, 3)),
        radii=np.full(n, 0.025),
        rest_lengths=np.full(n, 1.0 / n),
        history=history,
        snapshot_positions=rng.normal(size=(rows, n + 1, 3)),
        snapshot_d1=rng.normal(size=(rows, n, 3)),
        diagnostics={"steps": np.int64(120), "wall_time": 0.5, "rest_radius": 0.025,
                     "stages": [{"label": "twist", "equilibrium": True}], "notes": []},
        stage_ends=[2, rows - 1],
    )


def open_(path, config_hash=HASH):
    return st.open_store(path, config_text=CONFIG, config_hash=config_hash, version="0.1.0",
                         kind="sweep")


def test_round_trip(tmp_path):
    result = fake_result()
    path = tmp_path / "s.h5"
    with open_(path) as store:
        store.write_run("r000", {"twist_density": 0.8, "extension": 1.1, "seed": 3,
                                 "sampler": "random"}, result, {"queue_time": 0.1})
    with st.read_store(path) as store:
        back = store.read_run("r000")
        params = store.run_params("r000")
        assert store.attrs["config_hash"] == HASH and store.attrs["config_yaml"] == CONFIG
        assert store.attrs["kind"] == "sweep" and store.attrs["rodphase_version"] == "0.1.0"
        assert store.run_timings("r000") == {"queue_time": 0.1}
    assert params == {"twist_density": 0.8, "extension": 1.1, "seed": 3, "sampler": "random"}
    assert (back.status, back.message) == (result.status, result.message)
    for name in ("positions", "directors", "radii", "rest_lengths", "snapshot_positions",
                 "snapshot_d1"):
        np.testing.assert_array_equal(getattr(back, name), getattr(result, name))
    assert list(back.history) == list(result.history)  # column order kept
    for name, column in result.history.items():
        np.testing.assert_array_equal(back.history[name], column)
    assert back.diagnostics["steps"] == 120 and back.diagnostics["stages"][0]["equilibrium"]
    assert back.stage_ends == result.stage_ends


def test_empty_history_round_trip(tmp_path):
    result = fake_result(rows=0)
    result.stage_ends = []
    with open_(tmp_path / "s.h5") as store:
        store.write_run("r0", {}, result, {})
        back = store.read_run("r0")
    assert back.snapshot_positions.shape == (0, 7, 3) and back.stage_ends == []


def test_resume_semantics(tmp_path):
    path = tmp_path / "s.h5"
    with open_(path) as store:
        store.write_run("a", {"x": 1.0}, fake_result("ok"), {})
        store.write_run("b", {"x": 2.0}, fake_result("unstable"), {})
        store.write_run("c", {"x": 3.0}, fake_result("not_converged"), {})
    with open_(path) as store:  # reopening with the same config resumes
        assert store.done_ids() == {"a"}
        assert store.done_ids(include_failed=True) == {"a", "b", "c"}
        store.write_run("b", {"x": 2.0}, fake_result("ok"), {})  # a retry replaces the run
        assert store.done_ids() == {"a", "b"}
        assert store.run_ids() == ["a", "b", "c"]


def test_config_mismatch_names_both_hashes(tmp_path):
    path = tmp_path / "s.h5"
    open_(path).close()
    with pytest.raises(st.StoreMismatch) as err:
        open_(path, config_hash="ffff99")
    text = str(err.value)
    assert HASH in text and "ffff99" in text and "different config" in text
    assert "--force" in text
    open_(path).close()  # the file was left usable


def test_bad_run_id(tmp_path):
    with open_(tmp_path / "s.h5") as store, pytest.raises(ValueError, match="run_id"):
        store.write_run("a/b", {}, fake_result(), {})


def test_crash_mid_write_is_not_done_and_is_overwritten(tmp_path):
    path = tmp_path / "s.h5"
    with open_(path) as store:
        store.write_run("a", {}, fake_result(), {})
    # what a writer killed mid-run leaves: a half-written group under the temporary name
    with h5py.File(path, "a") as f:
        half = f.create_group(f"{st.PARTIAL}/b")
        half.attrs["status"] = "ok"
        half.create_dataset("positions", data=np.zeros((3, 3)))
    with open_(path) as store:
        assert store.done_ids(include_failed=True) == {"a"}
        assert store.run_ids() == ["a"]
        store.write_run("b", {"x": 1.0}, fake_result(seed=4), {})
        assert store.done_ids() == {"a", "b"}
        np.testing.assert_array_equal(store.read_run("b").positions,
                                      fake_result(seed=4).positions)
    with h5py.File(path, "r") as f:
        assert st.PARTIAL not in f


def test_partial_group_in_open_store_is_replaced(tmp_path):
    with open_(tmp_path / "s.h5") as store:
        store.file.create_group(f"{st.PARTIAL}/b").attrs["status"] = "ok"
        assert store.done_ids() == set()
        store.write_run("b", {}, fake_result(), {})
        assert store.done_ids() == {"b"} and st.PARTIAL not in store.file


def test_classification_round_trip_through_table(tmp_path):
    path = tmp_path / "s.h5"
    with open_(path) as store:
        for i, status in enumerate(["ok", "ok", "unstable"]):
            store.write_run(f"r{i}", {"twist_density": 0.5 * i, "extension": 1.1},
                            fake_result(status), {"wall_time": 2.0 + i, "steps": 100 * i})
        first = pd.DataFrame({"run_id": ["r0", "r1"], "alignment": [np.nan, 0.9],
                              "phase": ["straight", "solenoid"], "contacts": [0, 12],
                              "extension": [1.09, 1.08]})
        store.write_classification(first.assign(phase="old"))
        store.write_classification(first)  # replaces the earlier table
        assert list(store.classification().columns) == list(first.columns)
    table = st.read_table(path)
    assert list(table["run_id"]) == ["r0", "r1", "r2"]
    assert list(table["status"]) == ["ok", "ok", "unstable"]
    assert list(table["wall_time"]) == [2.0, 3.0, 4.0] and list(table["steps"]) == [0, 100, 200]
    assert list(table["twist_density"]) == [0.0, 0.5, 1.0]
    assert list(table["phase"][:2]) == ["straight", "solenoid"] and pd.isna(table["phase"][2])
    assert np.isnan(table["alignment"][0]) and table["alignment"][1] == 0.9
    assert list(table["contacts"][:2]) == [0, 12]
    assert list(table["extension_classified"][:2]) == [1.09, 1.08]  # params keep their name

    csv = st.write_table_csv(path, tmp_path / "t.csv")
    assert pd.read_csv(csv)["phase"].tolist()[:2] == ["straight", "solenoid"]


def test_classification_readable_with_h5py_alone(tmp_path):
    path = tmp_path / "s.h5"
    with open_(path) as store:
        store.write_classification(pd.DataFrame({"run_id": ["a"], "phase": ["mixed"],
                                                 "alignment": [0.1]}))
    with h5py.File(path, "r") as f:
        g = f["classification"]
        assert g["run_id"].asstr()[0] == "a" and g["alignment"][0] == 0.1
        assert list(g.attrs["columns"]) == ["run_id", "phase", "alignment"]


def test_empty_table(tmp_path):
    with open_(tmp_path / "s.h5") as store:
        table = store.table()
    assert len(table) == 0 and "status" in table.columns
