"""The sweep tool end to end: sampling, parallel runs, resume after a kill, Dask, classify, plot."""

from pathlib import Path

import h5py
import numpy as np
import pandas as pd
import pytest
import yaml
from click.testing import CliRunner

from rodphase import config as C
from rodphase.cli import main
from rodphase.scenes import SCENES
from rodphase.store import read_store
from rodphase.sweep import plan, run_scene, sample_points

# coarse and short: 12 elements, a fast twist and brief holds; still a real run with contact
FAST = {"rod.elements": 32, "solver.hold_max_time": 0.5, "loading.twist_rate": 2.0,
        "loading.force_ramp_time": 0.2, "output.history_interval": 0.1}


def sweep_file(tmp_path, samples=4, sampler="random", seed=3, name="sweep.yaml", extra=None):
    data = {"sweep": {"scene": "twist_under_load", "set": dict(FAST, **(extra or {})),
                      "axes": {"twist_density": [0.2, 1.0], "extension": [1.0, 1.2]},
                      "sampler": sampler, "samples": samples, "seed": seed}}
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data))
    return path


def cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


def final_positions(path):
    # through the store: runs not yet merged into the file (a killed sweep's) included
    with read_store(path) as store:
        return {rid: store.read_run(rid).positions for rid in store.run_ids()}


def test_same_seed_same_samples_and_samplers_cover_the_box(tmp_path):
    sweep, scene = C.load_sweep(sweep_file(tmp_path, samples=9), [], SCENES)
    assert sample_points(sweep) == sample_points(sweep)
    for sampler in ("random", "lhs", "grid"):
        sw, _ = C.load_sweep(sweep_file(tmp_path, samples=9, sampler=sampler), [], SCENES)
        points = np.array([[p["twist_density"], p["extension"]] for p in sample_points(sw)])
        assert len(points) == 9
        assert points[:, 0].min() >= 0.2 and points[:, 0].max() <= 1.0
        assert points[:, 1].min() >= 1.0 and points[:, 1].max() <= 1.2
    other, _ = C.load_sweep(sweep_file(tmp_path, samples=9, seed=4), [], SCENES)
    assert sample_points(other) != sample_points(sweep)
    jobs = plan(sweep, scene)
    assert jobs[0].scene["loading"]["extension"] == pytest.approx(jobs[0].params[0]["extension"])


def test_sweep_classify_plot_end_to_end(tmp_path):
    out = tmp_path / "out.h5"
    result = cli("sweep", sweep_file(tmp_path), "-o", out, "--jobs", 1, "--quiet")
    assert result.exit_code in (0, 1), result.output
    assert "Launching 4 of 4 runs" in result.output
    sweep_output = result.output
    result = cli("classify", out, "--csv", tmp_path / "table.csv")
    assert result.exit_code == 0, result.output
    table = pd.read_csv(tmp_path / "table.csv")
    assert len(table) == 4
    assert {"twist_density", "extension", "alignment", "phase", "link", "twist", "writhe",
            "status"} <= set(table.columns)
    # the summary line counts every run by its status, as the table does
    summary = next(line for line in sweep_output.splitlines() if "skipped of 4" in line)
    counts = dict(table["status"].value_counts())
    said = {word: int(n) for n, word in
            (part.split() for part in summary.split(", 0 skipped")[0].split(", "))}
    said.pop("failed", None)  # "0 failed" when every run is ok
    assert said == {k: int(v) for k, v in counts.items()}, summary
    assert set(table["phase"]) <= {"straight", "plectoneme", "solenoid", "mixed", "failed"}
    ok = table[table["status"] == "ok"]
    # link = twist + writhe for every run, to the accuracy of the open-ribbon closure
    assert np.abs(ok["link"] - ok["twist"] - ok["writhe"]).max() < 1e-6
    result = cli("plot", out, "--kind", "phase", "-o", tmp_path / "phase.png")
    assert result.exit_code == 0, result.output
    assert (tmp_path / "phase.png").stat().st_size > 10_000
    for args in (["--kind", "phase", "--size", "column", "--twist", "current"],
                 ["--kind", "phase", "--size", "3,2.5", "--no-caption"], ["--kind", "shape"]):
        result = cli("plot", out, *args, "-o", tmp_path / "more.png")
        assert result.exit_code == 0, (args, result.output)
    result = cli("plot", out, "--kind", "phase", "--size", "big", "-o", tmp_path / "x.png")
    assert result.exit_code == 2 and "error: --size" in result.output
    result = cli("export", out, "--run", table["run_id"][0], "-o", tmp_path / "rod.vtk")
    assert result.exit_code == 0 and (tmp_path / "rod.vtk").read_text().startswith("# vtk")
    # a sweep keeps its runs' final shapes only (output.snapshots auto = final for sweeps);
    # the history, Lk/Tw/Wr included, keeps every row
    with read_store(out) as store:
        run = store.read_run(table["run_id"][0])
    assert len(run.snapshot_positions) == 1 and len(run.history["time"]) > 3
    assert list(run.snapshot_history_rows) == [len(run.history["time"]) - 1]
    # the file is readable without rodphase
    with h5py.File(out, "r") as f:
        assert "config_yaml" in f.attrs and "config_hash" in f.attrs
        first = sorted(f["runs"])[0]
        frame = pd.DataFrame({k: f["runs"][first]["history"][k][()] for k in ("time", "end_force")})
        assert len(frame) > 3


def test_jobs_one_and_two_give_identical_results(tmp_path):
    path = sweep_file(tmp_path, samples=3)
    a, b = tmp_path / "a.h5", tmp_path / "b.h5"
    assert cli("sweep", path, "-o", a, "--jobs", 1, "--quiet").exit_code in (0, 1)
    assert cli("sweep", path, "-o", b, "--jobs", 2, "--quiet").exit_code in (0, 1)
    pa, pb = final_positions(a), final_positions(b)
    assert pa.keys() == pb.keys()
    for rid in pa:
        assert np.array_equal(pa[rid], pb[rid])


def test_rerun_skips_finished_runs_and_other_config_is_refused(tmp_path):
    path = sweep_file(tmp_path, samples=2)
    out = tmp_path / "out.h5"
    cli("sweep", path, "-o", out, "--quiet")
    result = cli("sweep", path, "-o", out, "--quiet")
    assert "Launching 0 of 2 runs" in result.output
    result = cli("sweep", path, "-o", out, "--quiet", "--set", "rod.elements=34")
    assert result.exit_code == 2 and "different config" in result.output


def test_killed_sweep_resumes_and_keeps_finished_runs_identical(tmp_path):
    # A real kill: the sweep runs in its own process group, is SIGKILLed once two runs are in
    # the file, and the same command then completes only the missing runs. Each run holds its
    # whole 20 s (hold_until: time; about half a second of CPU): ended at equilibrium, the runs
    # became fast enough that all six could land between two polls, and the test skipped
    # instead of killing anything (CI, 2026-12-03).
    path = sweep_file(tmp_path, samples=6,
                      extra={"solver.hold_max_time": 20.0, "solver.hold_until": "time"})
    out = tmp_path / "out.h5"
    from killing import kill_after_runs  # tests/killing.py

    finished = kill_after_runs(["sweep", path, "-o", out, "--jobs", 1, "--quiet"], out, 2,
                               poll=0.2)
    if len(finished) >= 6:
        pytest.skip("the sweep finished before it could be killed")
    assert len(finished) >= 2
    before = final_positions(out)
    result = cli("sweep", path, "-o", out, "--quiet")
    assert result.exit_code in (0, 1), result.output
    assert f"Launching {6 - len(before)} of 6 runs" in result.output
    after = final_positions(out)
    assert len(after) == 6
    for rid, positions in before.items():
        assert np.array_equal(positions, after[rid])


@pytest.mark.slow  # a local Dask cluster: 13 s of CPU starting it
def test_dask_local_cluster_gives_the_local_results(tmp_path):
    pytest.importorskip("distributed")
    path = sweep_file(tmp_path, samples=2)
    local, remote = tmp_path / "local.h5", tmp_path / "dask.h5"
    assert cli("sweep", path, "-o", local, "--quiet").exit_code in (0, 1)
    result = cli("sweep", path, "-o", remote, "--quiet", "--backend", "dask", "--jobs", 2)
    assert result.exit_code in (0, 1), result.output
    assert "local Dask cluster (dashboard " in result.output  # a link, or how to get one
    a, b = final_positions(local), final_positions(remote)
    assert a.keys() == b.keys()
    for rid in a:
        assert np.array_equal(a[rid], b[rid])


def test_scenes_command_lists_the_shipped_configs():
    result = cli("scenes")
    assert result.exit_code == 0
    assert "twist_under_load" in result.output and "quick.yaml" in result.output


def test_continuation_shares_one_ramp_and_agrees_with_independent_runs(tmp_path):
    # 2 loads x 3 twist densities: 2 runs instead of 6. Below the buckling onset the
    # equilibrium is unique, so each sample's final rod must match the independent run's to
    # the equilibrium tolerance (1e-3 of the force scale: ~1e-4 m here).
    extra = {"solver.hold_max_time": 3.0}
    grid = sweep_file(tmp_path, samples=6, sampler="grid", name="g.yaml", extra=extra)
    data = yaml.safe_load(grid.read_text())
    data["sweep"]["axes"] = {"twist_density": [0.1, 0.4], "extension": [1.05, 1.2]}
    grid.write_text(yaml.safe_dump(data))
    cont = tmp_path / "c.yaml"
    data["sweep"]["sampler"] = "continuation"
    cont.write_text(yaml.safe_dump(data))
    sweep, scene = C.load_sweep(cont, [], SCENES)
    jobs = plan(sweep, scene)
    assert len(jobs) == 3 and all(len(j.run_ids) == 3 for j in jobs)  # 9 samples, 3 loads
    a, b = tmp_path / "grid.h5", tmp_path / "cont.h5"
    assert cli("sweep", grid, "-o", a, "--quiet", "--jobs", 2).exit_code in (0, 1)
    result = cli("sweep", cont, "-o", b, "--quiet", "--jobs", 2)
    assert "in 3 continuation run(s)" in result.output
    pa, pb = final_positions(a), final_positions(b)
    assert pa.keys() == pb.keys() and len(pa) == 9
    # the samples of one run share its wall time: the store's add up to the work done
    with read_store(b) as store:
        runs = [store.read_run(rid) for rid in store.run_ids()]
    for run in runs:
        d = run.diagnostics
        assert d["wall_time"] == pytest.approx(d["run_wall_time"] / 3)
    for rid in pa:
        assert np.abs(pa[rid] - pb[rid]).max() < 1e-3
    cli("classify", b, "--csv", tmp_path / "c.csv")
    table = pd.read_csv(tmp_path / "c.csv")
    ok = table[table["status"] == "ok"]
    assert len(ok) >= 8
    # Lk of these straight rods is the turns put in, up to the discrete topology's error,
    # which depends on dt: 4e-7 to 4e-6 turns measured (the runner's own check allows 0.05)
    assert np.abs(ok["link"] - ok["end_rotation_turns"]).max() < 1e-5


def test_adaptive_sampling_refines_where_phases_differ(tmp_path):
    # 10 samples: 4 on a Latin hypercube, then midpoints of edges joining different phases.
    # Straight runs below the onset and buckled ones above it make a boundary to refine.
    path = sweep_file(tmp_path, samples=10, sampler="adaptive", seed=1,
                      extra={"solver.hold_max_time": 1.0})
    data = yaml.safe_load(path.read_text())
    data["sweep"]["axes"] = {"twist_density": [0.2, 1.0], "extension": [1.02, 1.06]}
    path.write_text(yaml.safe_dump(data))
    out = tmp_path / "a.h5"
    result = cli("sweep", path, "-o", out, "--quiet", "--jobs", 2)
    assert result.exit_code in (0, 1), result.output
    assert result.output.count("Launching") >= 2  # at least one refinement round
    cli("classify", out, "--csv", tmp_path / "a.csv")
    table = pd.read_csv(tmp_path / "a.csv")
    assert 4 < len(table) <= 10
    # a rerun resumes the same rounds and launches nothing
    again = cli("sweep", path, "-o", out, "--quiet")
    assert "Launching 0 of" in again.output and again.output.count("Launching 0 of") == again.output.count("Launching")


def test_run_then_every_plot_kind_and_a_movie(tmp_path):
    out = tmp_path / "run.h5"
    sets = [f"--set={k}={v}" for k, v in FAST.items()] + ["--set=loading.twist_density=0.5"]
    result = cli("run", "twist_under_load", "-o", out, *sets)
    assert result.exit_code == 0, result.output
    assert "phase straight" in result.output and "link" in result.output
    for kind in ("topology", "force", "shape"):
        png = tmp_path / f"{kind}.png"
        result = cli("plot", out, "--kind", kind, "-o", png)
        assert result.exit_code == 0, result.output
        assert png.stat().st_size > 5_000
    result = cli("movie", out, "--run", "run", "-o", tmp_path / "run.gif", "--fps", 5)
    assert result.exit_code == 0, result.output
    written = result.output.split("written ")[-1].strip()
    assert Path(written).stat().st_size > 5_000
    # a phase map needs a classified sweep; a bad run id is a clear error
    result = cli("movie", out, "--run", "nope", "-o", tmp_path / "x.gif")
    assert result.exit_code == 2 and "nope" in result.output


def test_curves_default_to_a_run_with_a_history_and_a_one_frame_movie_is_refused(tmp_path):
    # a sweep's straight runs started on their equilibrium may settle at their first history
    # row, and a sweep keeps one snapshot a run: `plot --kind topology` of the store drew
    # empty axes from run-00000, and `movie` wrote a one-frame GIF (issue #30's newcomer)
    import dataclasses

    from rodphase.store import open_store

    cfg = C.load_scene("twist_under_load", list(FAST.items()), SCENES)
    full = run_scene(cfg.plain())
    one_row = dataclasses.replace(full, history={k: v[:1] for k, v in full.history.items()},
                                  snapshot_positions=full.snapshot_positions[-1:],
                                  snapshot_d1=full.snapshot_d1[-1:])
    out = tmp_path / "two.h5"
    with open_store(out, config_text="x", config_hash="h" * 16, version="t",
                    kind="sweep") as store:
        store.write_run("run-00000", {"twist_density": 0.1}, one_row, {})
        store.write_run("run-00001", {"twist_density": 0.5}, full, {})
    from rodphase.cli import _run_with_history

    with read_store(out) as store:
        assert _run_with_history(store, store.run_ids()) == "run-00001"
    for kind in ("topology", "force"):
        result = cli("plot", out, "--kind", kind, "-o", tmp_path / f"{kind}.png")
        assert result.exit_code == 0, result.output
        result = cli("plot", out, "--kind", kind, "--run", "run-00000", "-o", tmp_path / "x.png")
        assert result.exit_code == 2, result.output
        assert result.output.startswith("error: --run: 'run-00000' (allowed: a run with a "
                                        "history of two rows or more"), result.output
    result = cli("movie", out, "--run", "run-00000", "-o", tmp_path / "movie" / "m.gif")
    assert result.exit_code == 2 and "output.snapshots=all" in result.output, result.output
    assert not (tmp_path / "movie").exists()  # nothing made by a command that refused


def test_an_mp4_without_ffmpeg_is_an_error_not_a_gif(tmp_path, monkeypatch):
    import shutil

    monkeypatch.setattr(shutil, "which", lambda name: None)
    store = tmp_path / "any.h5"
    store.write_bytes(b"checked after the output")
    result = CliRunner().invoke(main, ["movie", str(store), "--run", "run", "-o",
                                       str(tmp_path / "rod.mp4")])
    assert result.exit_code == 2 and "error: --output" in result.output
    assert "ffmpeg" in result.output and sorted(p.name for p in tmp_path.iterdir()) == ["any.h5"]


def test_an_under_resolved_run_is_run_again_with_more_elements():
    # Φa = 1.2 on 12 elements is 4 rad of twist per element: the resolution guard stops it.
    # With solver.refine_up_to the same point is rerun at 24, then 48 elements, where it
    # completes; the result says so. Without it the run stays a recorded failure.
    overrides = [("rod.elements", 12), ("loading.twist_density", 1.2), ("loading.twist_rate", 4.0),
                 ("solver.hold_until", "time"), ("solver.hold_max_time", 0.5),
                 ("output.topology", False)]
    coarse = run_scene(C.load_scene("twist_under_load", overrides, SCENES).plain())
    assert coarse.status == "unstable" and coarse.diagnostics["guard"] == "resolution"
    assert "refined_from" not in coarse.diagnostics
    cfg = C.load_scene("twist_under_load", overrides + [("solver.refine_up_to", 48)], SCENES)
    refined = run_scene(cfg.plain())
    assert refined.status == "ok", refined.message
    assert refined.diagnostics["elements"] == 48 and refined.positions.shape == (49, 3)
    assert refined.diagnostics["refined_from"] == [12, 24]
    assert "under-resolved at 12, 24 elements" in refined.diagnostics["notes"][-1]
    # the run's cost is every attempt's: 12 elements from the start, then 24 and 48, each
    # from a second before the coarser one's trip (solver.refine_from: trip)
    attempts = refined.diagnostics["attempts"]
    assert [a["elements"] for a in attempts] == [12, 24, 48]
    assert attempts[0]["start"] == "start"
    assert all(a["start"].startswith("t = ") for a in attempts[1:])
    assert [a["guard"] for a in attempts] == ["resolution", "resolution", None]
    assert refined.diagnostics["steps"] == sum(a["steps"] for a in attempts)
    assert refined.diagnostics["wall_time"] == pytest.approx(sum(a["wall_time"] for a in attempts))
    assert all(a["steps"] > 0 and a["wall_time"] > 0 for a in attempts)
    # the same protocol: all the twist asked for (Φa·L0/a of end rotation) went in
    assert refined.history["end_rotation"][-1] == pytest.approx(1.2 * cfg.rod.length / cfg.rod.radius)
    # the limit as doublings of the scene's count: two of 12 are 48, and no more
    doubled = run_scene(C.load_scene("twist_under_load", overrides + [("solver.refinements", 2)],
                                     SCENES).plain())
    assert doubled.diagnostics["elements"] == 48
    assert [a["elements"] for a in doubled.diagnostics["attempts"]] == [12, 24, 48]


def test_outputs_may_go_into_folders_that_do_not_exist_yet(tmp_path):
    # `-o out/x.h5` on a fresh checkout: the commands make the folder instead of failing
    store = tmp_path / "new" / "deeper" / "sweep.h5"
    result = cli("sweep", sweep_file(tmp_path, samples=1), "-o", store, "--quiet")
    assert result.exit_code in (0, 1), result.output
    assert store.exists()
    table = tmp_path / "tables" / "sweep.csv"
    assert cli("classify", store, "--csv", table).exit_code == 0 and table.exists()
    figure = tmp_path / "figures" / "phase.png"
    assert cli("plot", store, "--kind", "phase", "-o", figure).exit_code == 0 and figure.exists()


def test_jobs_start_longest_first_and_equal_ones_in_sampling_order(tmp_path):
    # the twist ramp is most of a run's work: the most twisted sample starts first, so the
    # sweep does not end on one long run while the other workers idle
    from rodphase.sweep import longest_first

    sweep, scene = C.load_sweep(sweep_file(tmp_path, samples=6), [], SCENES)
    jobs = plan(sweep, scene)
    ordered = longest_first(jobs)
    twists = [job.params[0]["twist_density"] for job in ordered]
    assert twists == sorted(twists, reverse=True)
    same = [jobs[0]] * 3
    assert longest_first(same) == same
    # a job whose problem cannot be built goes first: its worker records why at once
    broken = plan(sweep, scene)[0]
    broken.scene = {"scene": "no such scene"}
    assert longest_first(jobs + [broken])[0] is broken


class _FakePool:
    """A pool that runs tasks in this process and can lose its scheduler or its workers."""

    def __init__(self, outages=0, die_on_batches=0):
        from concurrent.futures import Future

        self.Future = Future
        self.workers, self.window = 2, 4
        self.outages, self.die_on_batches = outages, die_on_batches
        self.submitted, self.recovered = [], 0

    def submit(self, task, config_hash=None):
        from concurrent.futures.process import BrokenProcessPool

        from test_store import fake_result

        from rodphase.store import run_image
        from rodphase.sweep import Prepared

        self.submitted.append([rid for job in task for rid in job.run_ids])
        future = self.Future()
        if len(task) > 1 and self.die_on_batches:
            self.die_on_batches -= 1
            future.set_exception(BrokenProcessPool("a worker died"))
            return future
        out = []
        for job in task:
            result = fake_result(seed=len(self.submitted))
            result.diagnostics["wall_time"] = 0.001
            out.append((job.run_ids[0], job.params[0],
                        Prepared("ok", "completed", 0.001,
                                 run_image(job.run_ids[0], job.params[0], result, {},
                                           config_hash)), ""))
        future.set_result(out)
        return future

    def finished(self, futures):
        from rodphase.sweep import Outage

        if self.outages:
            self.outages -= 1
            raise Outage("lost the Dask scheduler at tcp://127.0.0.1:1")
        return set(futures)

    def result(self, future):
        return future.result()

    def outage(self, exc):
        return None

    def worker_died(self, exc):
        return "a worker died" if "worker died" in str(exc) else ""

    def recover(self, outage, in_flight):
        self.recovered += 1


@pytest.mark.parametrize("outages, die_on_batches", [(0, 0), (2, 0), (0, 2)])
def test_runs_in_flight_at_an_outage_or_a_death_are_sent_again_and_counted_once(
        tmp_path, outages, die_on_batches):
    from rodphase.store import open_store
    from rodphase.sweep import Job, SweepReport, _run_jobs

    jobs = [Job([f"run-{i:05d}"], [{"twist_density": i / 100}], {"rod": {"elements": 6}})
            for i in range(60)]
    pool = _FakePool(outages, die_on_batches)
    report = SweepReport(60, 0, 0, 0, 0.0, [])
    with open_store(tmp_path / "o.h5", config_text="x", config_hash="h" * 16, version="t",
                    kind="sweep") as store:
        _run_jobs(store, jobs, pool, False, report)
        assert sorted(store.run_ids()) == [j.run_ids[0] for j in jobs]
    assert report.done == 60 and report.failed == 0 and pool.recovered == outages
    sizes = [len(task) for task in pool.submitted]
    assert max(sizes) > 1  # fast runs went several to a task once seen to be fast
    sent = [rid for task in pool.submitted for rid in task]
    assert len(sent) > 60 if (outages or die_on_batches) else len(sent) == 60


def test_the_sobol_sampler_leaves_no_part_of_fig3s_box_empty_and_keeps_its_prefix():
    # Fig 3's sweep with its seed: the random sampler left the corner L/L0 < 1.055,
    # Φa < 0.6 without a sample (issue #29); the scrambled Sobol points fill every cell of a
    # 10 × 10 grid of the box, and their centred L2 discrepancy (scipy's, an independent
    # measure of evenness) is below both the random and the Latin hypercube draws'
    from scipy.stats import qmc

    from rodphase.sweep import SAMPLERS

    axes = {"twist_density": [0.0, 2.6], "extension": [1.0, 1.3]}
    unit = {name: SAMPLERS[name](axes, 200, 2020) for name in ("random", "lhs", "sobol")}
    cells, _, _ = np.histogram2d(unit["sobol"][:, 0], unit["sobol"][:, 1], bins=10,
                                 range=[[0, 1], [0, 1]])
    assert cells.min() >= 1
    corner = (unit["sobol"][:, 0] < 0.6 / 2.6) & (unit["sobol"][:, 1] < 0.055 / 0.3)
    assert corner.sum() >= 1
    discrepancy = {name: qmc.discrepancy(u) for name, u in unit.items()}
    assert discrepancy["sobol"] < discrepancy["lhs"] < discrepancy["random"]
    # the same seed draws the same points, and a shorter sweep is the longer one's start
    # (studies that run the first k points of Fig 3 rely on it)
    assert np.array_equal(SAMPLERS["sobol"](axes, 50, 2020), unit["sobol"][:50])


def test_a_run_stopped_while_its_end_turns_too_fast_is_run_again_slower():
    # Φa = 1.0 on 48 elements twisted at 32 turns/s: the end frame falls more than 135°
    # behind its clamp (clamp_lag); at 16 turns/s the twist piles up at the turning end
    # faster than it spreads (the resolution guard); at 8 turns/s the run completes. With
    # solver.slow_down_to = 8 the same point is run at 32, 16 and 8 turns/s and ends `ok`,
    # with all its twist in; with 16 it stops at 16, still failed.
    overrides = [("rod.elements", 48), ("loading.twist_density", 1.0),
                 ("loading.twist_rate", 32.0), ("solver.hold_until", "time"),
                 ("solver.hold_max_time", 0.5), ("output.topology", False)]
    fast = run_scene(C.load_scene("twist_under_load", overrides, SCENES).plain())
    assert fast.status == "unstable" and fast.diagnostics["guard"] == "clamp_lag"
    assert "twist_rates_tried" not in fast.diagnostics
    cfg = C.load_scene("twist_under_load", overrides + [("solver.slow_down_to", 8.0)], SCENES)
    slowed = run_scene(cfg.plain())
    assert slowed.status == "ok", slowed.message
    assert slowed.diagnostics["twist_rates_tried"] == [32.0, 16.0, 8.0]
    assert [a["twist_rate"] for a in slowed.diagnostics["attempts"]] == [32.0, 16.0, 8.0]
    assert slowed.diagnostics["steps"] == sum(a["steps"] for a in slowed.diagnostics["attempts"])
    assert "resolution guard stopped it at 48 elements while an end turned at 16 turns/s" \
        in slowed.diagnostics["notes"][-1]
    assert slowed.history["end_rotation"][-1] == pytest.approx(1.0 * cfg.rod.length / cfg.rod.radius)
    # the twist of the slower run takes twice as long: 40/2π turns at 8 turns/s
    twist = slowed.diagnostics["stages"][1]
    assert twist["label"].startswith("twist") and twist["end_time"] > 0.7
    floor = run_scene(C.load_scene("twist_under_load",
                                   overrides + [("solver.slow_down_to", 16.0)], SCENES).plain())
    assert floor.status == "unstable" and floor.diagnostics["twist_rates_tried"] == [32.0, 16.0]
    assert floor.diagnostics["guard"] == "resolution"
    # its advice names what is left, not the slower twist it already had
    assert "lower loading.twist_rate" not in floor.message
    assert "Already tried: 2 attempts" in floor.message and "down to 16 turns/s" in floor.message
    assert floor.diagnostics["wall_time"] == pytest.approx(
        sum(a["wall_time"] for a in floor.diagnostics["attempts"]))
