"""HDF5 store: round trip, resume semantics, config mismatch, crash safety, tables."""

import errno
import pickle
import signal
import subprocess
import sys
from pathlib import Path

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


def test_temporary_files_of_a_killed_writer_are_not_runs_and_are_removed(tmp_path):
    path = tmp_path / "s.h5"
    with open_(path) as store:
        store.write_run("a", {}, fake_result(), {})
    # what a writer killed mid-write leaves: a half-written run file and a half-written copy
    # of the main file, both under temporary names
    folder = st.parts_folder(path)
    folder.mkdir()
    (folder / ".b.h5.999.tmp").write_bytes(b"\x89HDF\r\n\x1a\n half a run")
    (tmp_path / ".s.h5.999.tmp").write_bytes(path.read_bytes()[:1000])
    with st.read_store(path) as store:  # a reader ignores them
        assert store.run_ids() == ["a"]
    with open_(path) as store:
        assert store.done_ids(include_failed=True) == {"a"}
        store.write_run("b", {"x": 1.0}, fake_result(seed=4), {})
        assert store.done_ids() == {"a", "b"}
        np.testing.assert_array_equal(store.read_run("b").positions,
                                      fake_result(seed=4).positions)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.h5"]  # merged, nothing left over


def test_a_finished_run_is_durable_before_it_is_merged(tmp_path):
    """A run is kept from the moment write_run returns: a writer killed before merging
    leaves it in OUT.h5.parts, readers see it, and the next writer merges it."""
    path = tmp_path / "s.h5"
    code = (f"import os, signal, sys; sys.path.insert(0, {str(Path(__file__).parent)!r})\n"
            "from test_store import open_, fake_result\n"
            f"store = open_({str(path)!r})\n"
            "store.write_run('a', {'x': 1.0}, fake_result(), {})\n"
            "os.kill(os.getpid(), signal.SIGKILL)\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == -signal.SIGKILL, done.stderr
    assert (st.parts_folder(path) / "a.h5").exists()
    with st.read_store(path) as store:
        assert store.done_ids() == {"a"}
        np.testing.assert_array_equal(store.read_run("a").positions, fake_result().positions)
    with open_(path) as store:  # the killed writer's lock died with it
        assert store.run_ids() == ["a"]
    with h5py.File(path, "r") as f:  # merged into the one file, readable with h5py alone
        assert list(f["runs"]) == ["a"] and f["runs/a"].attrs["param_x"] == 1.0
    assert not st.parts_folder(path).exists() and not st.lock_path(path).exists()


def test_one_writer_at_a_time_while_readers_follow(tmp_path):
    path = tmp_path / "s.h5"
    with open_(path) as store:
        store.write_run("a", {}, fake_result(), {})
        with pytest.raises(st.StoreBusy, match="being written by another rodphase process"):
            open_(path)
        with pytest.raises(st.StoreBusy):
            st.edit_store(path)
        assert st.read_table(path)["run_id"].tolist() == ["a"]  # a reader sees the part
        store.write_run("b", {}, fake_result(), {})
        assert st.read_table(path)["run_id"].tolist() == ["a", "b"]
    open_(path).close()  # free again once the writer closed


def test_merges_replace_the_file_whole(tmp_path, monkeypatch):
    """The main file is replaced by rename, never modified in place: a reader holding it
    open keeps reading the version it opened."""
    monkeypatch.setattr(st, "MERGE_EVERY", 2)
    path = tmp_path / "s.h5"
    with open_(path) as store:
        store.write_run("a", {}, fake_result(), {})
        inode = path.stat().st_ino
        reader = st.read_store(path)
        store.write_run("b", {}, fake_result(), {})  # the second part triggers a merge
        assert path.stat().st_ino != inode and not st.parts_folder(path).exists()
        assert reader.run_ids() == ["a"] and reader.read_run("a").status == "ok"
        reader.close()


def test_a_full_disk_leaves_everything_stored_intact(tmp_path, monkeypatch):
    path = tmp_path / "s.h5"
    with open_(path) as store:
        store.write_run("a", {}, fake_result(), {})
        real_fsync = st._fsync

        def full(target):
            if target.name.endswith(".tmp"):
                raise OSError(errno.ENOSPC, "No space left on device")
            real_fsync(target)

        monkeypatch.setattr(st, "_fsync", full)
        with pytest.raises(st.StoreFull, match="disk is full"):
            store.write_run("b", {}, fake_result(), {})
        with pytest.raises(st.StoreFull):
            store.merge()
        monkeypatch.setattr(st, "_fsync", real_fsync)
        assert store.run_ids() == ["a"]
    assert st.read_table(path)["run_id"].tolist() == ["a"]
    leftovers = [p.name for p in tmp_path.rglob("*") if p.name.endswith(".tmp")]
    assert leftovers == []


def test_replacing_another_config_waits_for_the_first_new_run(tmp_path):
    path = tmp_path / "s.h5"
    with open_(path) as store:
        store.write_run("old", {}, fake_result(), {})
    store = st.open_store(path, config_text=CONFIG, config_hash="ffff99", version="0.1.0",
                          kind="sweep", replace=True)
    with st.read_store(path) as reader:  # nothing deleted yet
        assert reader.attrs["config_hash"] == HASH and reader.run_ids() == ["old"]
    assert store.run_ids() == []
    store.write_run("new", {}, fake_result(), {})
    store.close()
    with st.read_store(path) as reader:
        assert reader.attrs["config_hash"] == "ffff99" and reader.run_ids() == ["new"]
    with open_(path, config_hash="ffff99", ) as store:  # the same config: nothing replaced
        assert store.run_ids() == ["new"]


def test_a_retried_run_drops_its_stale_classification_row(tmp_path):
    path = tmp_path / "s.h5"
    with open_(path) as store:
        store.write_run("a", {}, fake_result("unstable"), {})
        store.write_run("b", {}, fake_result(), {})
        store.write_classification(pd.DataFrame({"run_id": ["a", "b"],
                                                 "phase": ["failed", "straight"]}))
    with open_(path) as store:
        store.write_run("a", {}, fake_result(), {})
    table = st.read_table(path)
    assert pd.isna(table["phase"][0]) and table["phase"][1] == "straight"


def _foreign(path, how):
    with open_(path) as store:
        store.write_run("a", {}, fake_result(), {})
    with h5py.File(path, "a") as f:
        if how == "external link":
            f["runs/b"] = h5py.ExternalLink("/etc/elsewhere.h5", "/runs/a")
        elif how == "soft link":
            f["runs/b"] = h5py.SoftLink("/runs/a")
        elif how == "external storage":
            raw = path.parent / "raw.bin"
            raw.write_bytes(np.zeros(8).tobytes())
            f["runs/a"].create_dataset("extra", shape=(8,), dtype="f8",
                                       external=[(str(raw), 0, h5py.h5f.UNLIMITED)])
        elif how == "pickled attribute":
            f["runs/a"].attrs["message"] = np.void(pickle.dumps({"a": 1}))


@pytest.mark.parametrize("how", ["external link", "soft link", "external storage",
                                 "pickled attribute"])
def test_layouts_rodphase_never_writes_are_refused(tmp_path, how):
    path = tmp_path / "s.h5"
    _foreign(path, how)
    with pytest.raises(st.NotAStore, match="rodphase"):
        st.read_table(path)
    if how == "pickled attribute":  # attributes are checked as they are read
        with st.read_store(path) as store, pytest.raises(st.NotAStore, match="opaque"):
            store.read_run("a")
    else:  # links and storage as the file is opened, by writers too
        with pytest.raises(st.NotAStore):
            open_(path).close()


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


def test_without_flock_or_fallocate_the_fallbacks_hold(tmp_path, monkeypatch):
    """macOS has no posix_fallocate and Windows no fcntl: the store still locks and merges."""
    monkeypatch.setattr(st, "fcntl", None)
    monkeypatch.delattr(st.os, "posix_fallocate", raising=False)
    monkeypatch.setattr(st, "MERGE_EVERY", 1)
    path = tmp_path / "s.h5"
    with open_(path) as store:
        with pytest.raises(st.StoreBusy, match="if that process no longer runs, delete"):
            open_(path)
        store.write_run("a", {}, fake_result(), {})  # merged at once (MERGE_EVERY = 1)
        assert not st.parts_folder(path).exists()
    assert not st.lock_path(path).exists()
    with open_(path) as store:
        np.testing.assert_array_equal(store.read_run("a").positions, fake_result().positions)


def _demo_like_store(path):
    """A store shaped like the demo's: four runs with Lk/Tw/Wr histories, classified."""
    with open_(path) as store:
        for i in range(4):
            result = fake_result(seed=i)
            result.history["twist"] = result.history["link"] - 0.1
            result.history["writhe"] = np.full_like(result.history["link"], 0.1)
            result.history["time"] = np.arange(len(result.history["time"])) * 5.0
            result.diagnostics["dt"] = 1e-4
            store.write_run(f"run-{i:05d}", {"twist_density": 0.4 * i, "extension": 1.1},
                            result, {"wall_time": 1.0})
        store.write_classification(pd.DataFrame({"run_id": [f"run-{i:05d}" for i in range(4)],
                                                 "phase": ["straight"] * 4,
                                                 "alignment": [np.nan] * 4}))


def test_the_reading_examples_of_the_data_format_page_run_as_written(tmp_path, monkeypatch):
    import re

    page = (Path(__file__).parent.parent / "docs" / "reference" / "data-format.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", page[page.index("## Reading without"):], re.S)
    assert len(blocks) == 3
    monkeypatch.chdir(tmp_path)
    (tmp_path / "out").mkdir()
    _demo_like_store(tmp_path / "out" / "quick.h5")
    for block in blocks:
        exec(compile(block, "data-format.md", "exec"), {})


def test_arrays_have_units_and_named_dimensions_and_the_file_its_provenance(tmp_path):
    import json

    import xarray as xr

    path = tmp_path / "s.h5"
    _demo_like_store(path)
    rod = xr.open_dataset(path, group="runs/run-00001", engine="h5netcdf")
    assert rod.positions.dims == ("node", "xyz") and rod.positions.attrs["units"] == "m"
    assert rod.directors.dims == ("element", "director", "xyz")
    assert rod.radii.dims == ("element",) and rod.radii.attrs["units"] == "m"
    history = xr.open_dataset(path, group="runs/run-00001/history", engine="h5netcdf")
    assert history.end_force.dims == ("time",) and history.end_force.attrs["units"] == "N"
    assert history.writhe.attrs["units"] == "turns" and history.time.attrs["units"] == "s"
    snapshots = xr.open_dataset(path, group="runs/run-00001/snapshots", engine="h5netcdf")
    assert snapshots.positions.dims == ("time", "node", "xyz")
    np.testing.assert_array_equal(snapshots.positions, fake_result(seed=1).snapshot_positions)
    table = xr.open_dataset(path, group="classification", engine="h5netcdf")
    assert table.phase.dims == ("run_id",)
    every = set()
    with h5py.File(path, "r") as f:
        f.visititems(lambda name, obj: every.add(name) if isinstance(obj, h5py.Dataset)
                     and "units" not in obj.attrs and not name.startswith("classification")
                     else None)
        info = json.loads(f.attrs["provenance"])
    assert every == set()  # every array of every run says its unit
    assert {"python", "numpy", "numba", "h5py", "hdf5", "git_commit"} <= set(info)


def test_long_histories_and_a_table_without_repeated_columns(tmp_path):
    path = tmp_path / "s.h5"
    _demo_like_store(path)
    with open_(path) as store:  # a classification that repeats status and a parameter
        store.write_classification(pd.DataFrame({
            "run_id": [f"run-{i:05d}" for i in range(4)], "status": ["ok"] * 4,
            "twist_density": [0.4 * i for i in range(4)], "phase": ["mixed"] * 4}))
    table = st.read_table(path)
    assert not [c for c in table.columns if c.endswith("_classified")]
    assert list(table["phase"]) == ["mixed"] * 4
    long = st.read_histories(path, columns=["time", "writhe"])
    assert len(long) == 4 * 5 and list(long.columns[:3]) == ["run_id", "row", "status"]
    assert set(long.columns) == {"run_id", "row", "status", "time", "writhe", "twist_density",
                                 "extension"}
    assert long.groupby("run_id")["twist_density"].first().tolist() == [0.0, 0.4, 0.8,
                                                                         0.4 * 3]


def test_a_store_that_xarray_holds_open_can_still_be_read_and_written(tmp_path):
    # xarray keeps the files it opened open with HDF5's default locking, and HDF5 refuses to
    # open the same file again in the process with other flags (seen in the tutorial)
    import xarray as xr

    path = tmp_path / "s.h5"
    _demo_like_store(path)
    held = xr.open_dataset(path, group="runs/run-00000", engine="h5netcdf")
    held.positions.load()
    assert len(st.read_table(path)) == 4
    with open_(path) as store:
        store.write_run("run-00004", {}, fake_result(), {})
    assert len(st.read_table(path)) == 5
    held.close()


def test_a_snapshot_policy_keeps_the_rows_it_says_and_the_store_knows_which(tmp_path):
    from rodphase.runner import keep_snapshots

    full = fake_result(rows=7)
    assert len(keep_snapshots(fake_result(rows=7), "all").snapshot_positions) == 7
    final = keep_snapshots(fake_result(rows=7), "final")
    np.testing.assert_array_equal(final.snapshot_positions, full.snapshot_positions[[6]])
    every = keep_snapshots(fake_result(rows=7), 3)
    assert list(every.snapshot_history_rows) == [0, 3, 6]
    np.testing.assert_array_equal(every.snapshot_d1, full.snapshot_d1[[0, 3, 6]])
    with open_(tmp_path / "s.h5") as store:
        store.write_run("a", {}, every, {})
    with st.read_store(tmp_path / "s.h5") as store:
        back = store.read_run("a")
    assert list(back.snapshot_history_rows) == [0, 3, 6]
    assert len(back.history["time"]) == 7  # the history keeps every row
    with h5py.File(tmp_path / "s.h5", "r") as f:
        np.testing.assert_array_equal(f["runs/a/snapshots/time"][()], full.history["time"][[0, 3, 6]])


def test_a_phase_map_of_a_single_run_file_is_one_error_line(tmp_path):
    from click.testing import CliRunner

    from rodphase.cli import main

    path = tmp_path / "run.h5"
    result = fake_result()
    result.diagnostics.update(rest_length=1.0, youngs_modulus=1e6)
    with st.open_store(path, config_text="scene: x\n", config_hash="h", version="0.1.0",
                       kind="run") as store:
        store.write_run("run", {}, result, {})
    runner = CliRunner()
    assert runner.invoke(main, ["classify", str(path)]).exit_code == 0
    out = runner.invoke(main, ["plot", str(path), "--kind", "phase", "-o", str(tmp_path / "p.png")])
    assert out.exit_code == 2 and out.output.startswith("error: --kind phase")
    assert "extension" in out.output and "Traceback" not in out.output


def test_a_stored_config_with_an_alias_bomb_is_not_expanded():
    from rodphase import config as C

    bomb = "a: &a [x, x, x, x, x, x, x, x, x]\n" + "".join(
        f"{c}: &{c} [*{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}]\n"
        for p, c in zip("abcdefgh", "bcdefghi"))
    assert C.stored_config(bomb) == {}  # the caption then says what it can, nothing hangs
    assert C.stored_config("scene: {scene: twist_under_load}")["scene"]["scene"] == "twist_under_load"


def test_a_part_built_elsewhere_reads_as_one_written_here(tmp_path):
    # a sweep's workers build each run's part (store.run_image) and the writer only writes
    # the bytes; the run reads back the same, before and after the merge names its dimensions
    result = fake_result("not_converged", seed=7)
    with open_(tmp_path / "a.h5") as a, open_(tmp_path / "b.h5") as b:
        a.write_run("r1", {"x": 1.5}, result, {"wall_time": 0.5})
        b.write_part("r1", st.run_image("r1", {"x": 1.5}, result, {"wall_time": 0.5}, HASH))
        for store in (a, b):
            back = store.read_run("r1")
            assert back.status == "not_converged" and store.run_params("r1") == {"x": 1.5}
            assert np.array_equal(back.positions, result.positions)
            assert np.array_equal(back.history["link"], result.history["link"])
    with h5py.File(tmp_path / "b.h5", "r") as f:
        run = f["runs/r1"]
        assert run["positions"].dims[0][0].name == "/runs/r1/node"
        assert run["history/link"].dims[0][0].name == "/runs/r1/history/time"
        assert run["snapshots/positions"].dims[0][0].name == "/runs/r1/snapshots/time"
    with pytest.raises(ValueError, match="run_id"):
        st.run_image("a/b", {}, result, {}, HASH)
