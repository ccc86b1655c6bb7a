"""The paths sampler (rodphase/paths.py): a column of the map as the straight branch up to its
static onset, then one dynamic run across the jump; its sampling, its refusals, and the
agreement of the dynamic path with the static onset on both sides of it."""

import dataclasses

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from rodphase import config as C
from rodphase import paths
from rodphase.cli import main
from rodphase.result import RunResult
from rodphase.runner import split_continuation
from rodphase.scenes import SCENES
from rodphase.sweep import plan, sample_points


def sweep_file(tmp_path, **sweep):
    data = {"sweep": {"scene": "twist_under_load",
                      "set": {"rod.elements": 24, "loading.quasi_static_below": 0.8},
                      "axes": {"twist_density": [0.0, 2.6], "extension": [1.0, 1.3]},
                      "sampler": "paths", "samples": 23, "columns": 5, "seed": 7}}
    data["sweep"].update(sweep)
    path = tmp_path / "paths.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_columns_hold_one_load_and_a_stratified_twist_each(tmp_path):
    sweep, _ = C.load_sweep(sweep_file(tmp_path), [], SCENES)
    points = sample_points(sweep)
    assert points == sample_points(sweep)  # the seed fixes them
    loads = sorted({p["extension"] for p in points})
    assert len(points) == 23 and len(loads) == 5
    assert all(1.0 <= e <= 1.3 for e in loads)
    for load in loads:
        twists = [p["twist_density"] for p in points if p["extension"] == load]
        # 23 over 5 columns: 5, 5, 5, 4, 4; one twist in each equal slice of [0, 2.6]
        assert len(twists) in (4, 5)
        slices = np.floor(np.array(twists) / 2.6 * len(twists))
        assert list(slices) == list(range(len(twists)))
    # the default count of columns is the square root of the samples
    sweep, _ = C.load_sweep(sweep_file(tmp_path, columns=None, samples=16), [], SCENES)
    assert len({p["extension"] for p in sample_points(sweep)}) == 4


def test_plan_makes_one_path_job_per_column(tmp_path):
    sweep, scene = C.load_sweep(sweep_file(tmp_path), [], SCENES)
    jobs = plan(sweep, scene)
    assert len(jobs) == 5 and sum(len(j.run_ids) for j in jobs) == 23
    for job in jobs:
        assert job.column is not None and job.column.targets == sorted(job.column.targets)
        assert len(job.column.scenes) == len(job.run_ids)


@pytest.mark.parametrize("sweep, set_, key", [
    ({"sampler": "sobol", "columns": 4}, {}, "sweep.columns"),
    ({"columns": 40}, {}, "sweep.columns"),
    ({"axes": {"twist_density": [0, 1], "extension": [1, 1.2], "force_multiple": [1, 2]}}, {},
     "sweep.axes"),
    ({"axes": {"extension": [1, 1.2]}}, {}, "sweep.axes"),
    ({}, {"loading.quasi_static_below": 0.0}, "loading.quasi_static_below"),
    ({}, {"physics.gravity": [0, 0, -9.81]}, "physics.gravity"),
    ({"scene": "solenoid_loss"}, {}, "scene"),
])
def test_what_a_path_cannot_follow_is_refused_by_name(tmp_path, sweep, set_, key):
    path = sweep_file(tmp_path, **sweep)
    if set_:
        data = yaml.safe_load(path.read_text())
        data["sweep"]["set"].update(set_)
        path.write_text(yaml.safe_dump(data))
    result = CliRunner().invoke(main, ["sweep", str(path), "-o", str(tmp_path / "o.h5")])
    assert result.exit_code == 2, result.output
    assert key in result.output and "Traceback" not in result.output
    assert not (tmp_path / "o.h5").exists()  # refused before anything was made


def _column(targets_of_onset, extra=()):
    overrides = [("rod.elements", 32), ("loading.force_multiple", None),
                 ("loading.extension", 1.05), ("loading.quasi_static_below", 0.8),
                 ("loading.twist_rate", 1.0), ("solver.hold_max_time", 4.0)]
    overrides += list(extra)
    base = C.load_scene("twist_under_load", overrides, SCENES)
    onset = paths.onset_of(base)
    scenes = [C.load_scene("twist_under_load", overrides + [
        ("loading.twist_density", None), ("loading.twist_turns", f * onset)], SCENES)
        for f in targets_of_onset]
    return paths.Column(3, scenes, [f * onset for f in targets_of_onset]), onset


def test_a_path_agrees_with_the_static_onset_on_both_sides():
    # 32 elements at L/L0 = 1.05 (onset 4.5 turns; at 24 the coarse contact let the loops
    # pass through each other at 1.6 of it: 5 link escapes). Below 0.8 of the onset a sample is its
    # own run, the very run an independent sweep makes (bit for bit); at 0.95 of it the
    # dynamic path, started at 0.8, holds the rod straight (the static test said stable:
    # writhe ~0, the frozen round-off); at 1.3 and 1.6 it has left the straight branch
    # (half a turn of writhe is a loop; a buckled rod here writhes by more than 1).
    from rodphase.runner import run_scene

    column, onset = _column([0.5, 0.95, 1.3, 1.6])
    results = paths.run_column(column)
    tags = [r.diagnostics["path"] for r in results]
    assert [t["reached"] for t in tags] == [paths.REACHED_ALONE] + [paths.REACHED_PATH] * 3
    assert all(t["column"] == 3 and t["onset_turns"] == onset for t in tags)
    assert [t["rank"] for t in tags] == [0, 1, 2, 3]
    alone = run_scene(column.scenes[0])
    np.testing.assert_array_equal(results[0].positions, alone.positions)
    # the straight ones are stable equilibria; a 4 s hold need not settle a buckled one
    assert [r.status for r in results[:2]] == ["ok", "ok"], [r.message for r in results]
    assert {r.status for r in results[2:]} <= {"ok", "not_converged"}
    writhe = [float(r.history["writhe"][-1]) for r in results]
    assert abs(writhe[0]) < 1e-3 and abs(writhe[1]) < 1e-3
    assert abs(writhe[2]) > 0.5 and abs(writhe[3]) > 0.5
    # each held sample keeps its own link: the turns put in (the runner's own check allows
    # 0.05 turns; a path must not lose one)
    for r, turns in zip(results, column.targets):
        assert r.history["link_escapes"][-1] == 0
        assert float(r.history["link"][-1]) == pytest.approx(turns, abs=0.05)
    # the path left the straight branch past the static onset (the dynamic overshoot at
    # 1 turn/s) and before the first buckled sample
    jump = tags[1]["jump_turns"]
    assert onset < jump <= column.targets[2]
    assert all(t["jump_turns"] == jump for t in tags[1:]) and tags[0]["jump_turns"] is None
    # the path's one run is shared: its wall time split evenly among its three samples
    shared = [r.diagnostics["wall_time"] for r in results[1:]]
    assert shared[0] == pytest.approx(tags[1]["run_wall_time"] / 3)
    assert shared == [shared[0]] * 3


def _fake(status, samples, guard=None, wall=1.0, elements=32):
    stages = [{"label": f"hold {k}", "sample": k, "equilibrium": True} for k in range(samples)]
    return RunResult(status=status, message=f"fake {status}", positions=np.zeros((3, 3)),
                     directors=np.zeros((2, 3, 3)), radii=np.zeros(2),
                     rest_lengths=np.ones(2), history={"time": np.zeros(1)},
                     snapshot_positions=np.zeros((0, 3, 3)), snapshot_d1=np.zeros((0, 2, 3)),
                     diagnostics={"stages": stages, "guard": guard, "wall_time": wall,
                                  "elements": elements, "notes": []})


def test_a_guard_in_a_hold_leaves_that_sample_unreached():
    # the run tripped in hold 2: samples 0 and 1 are done, sample 2 is not (it used to be
    # split off as a `not_converged` shape of the moment the guard stopped the rod)
    tripped = _fake("unstable", 3, guard="shear")
    tripped.diagnostics["stages"][-1]["equilibrium"] = False
    assert paths.reached_samples(tripped) == 2
    assert paths.reached_samples(_fake("ok", 3)) == 3


def test_a_stopped_path_refines_then_falls_back_to_the_samples_own_run(monkeypatch):
    # a path of 5 samples at 32 elements, refine_up_to 64: the first run stops in sample 2
    # (shear guard), the refined rest stops again in its first sample, which then runs alone,
    # and the path resumes above it at 64 elements. Every sample gets a result, and the work
    # of the run that finished nothing is charged to the sample after it.
    calls = []

    def fake_run_scene(cfg, twist_targets=None):
        calls.append((cfg.rod.elements, cfg.solver.refine_up_to, twist_targets))
        if twist_targets is None:
            return _fake("unstable", 0, guard="shear", wall=0.5)
        if len(calls) == 1:
            return _fake("unstable", 3, guard="shear", elements=cfg.rod.elements)
        if len(twist_targets) == 3:
            return _fake("unstable", 1, guard="shear", wall=2.0, elements=cfg.rod.elements)
        return _fake("ok", len(twist_targets), wall=4.0, elements=cfg.rod.elements)

    def fake_split(run, k, incompressible=True):
        return dataclasses.replace(run, diagnostics=dict(run.diagnostics, sample=k),
                                   status="ok")

    monkeypatch.setattr(paths, "run_scene", fake_run_scene)
    monkeypatch.setattr(paths, "split_continuation", fake_split)
    monkeypatch.setattr(paths, "onset_of", lambda cfg: 1.0)
    column, _ = _column([1.0] * 5, [("solver.refine_up_to", 64)])
    column.targets = [1.0, 1.1, 1.2, 1.3, 1.4]
    results = paths.run_column(column)
    reached = [r.diagnostics["path"]["reached"] for r in results]
    assert reached == [paths.REACHED_PATH] * 2 + [paths.REACHED_FALLBACK] + [paths.REACHED_PATH] * 2
    assert [c[:2] for c in calls] == [(32, 32), (64, 64), (32, 64), (64, 64)]
    assert calls[1][2] == [1.2, 1.3, 1.4] and calls[3][2] == [1.3, 1.4]
    assert calls[2][2] is None  # the sample's own run, with its own refinement
    fallback = results[2].diagnostics
    assert fallback["path"]["wall_time_carried"] == 2.0 and fallback["wall_time"] == 2.5
    assert results[2].status == "unstable" and results[3].diagnostics["path"]["elements"] == 64


def test_split_continuation_does_not_call_a_tripped_hold_converged():
    tripped = _fake("unstable", 2, guard="shear")
    unreached = split_continuation(tripped, 1)
    assert unreached.status == "unstable" and "stopped before sample 1" in unreached.message
