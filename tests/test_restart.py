"""Starting a run from a stored state (config key initial_state, rodphase/restart.py)."""

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

import rodphase
from rodphase import config as C
from rodphase.cli import main
from rodphase.restart import continue_from, read_state
from rodphase.runner import run_scene
from rodphase.scenes import build
from rodphase.store import open_store, read_store

# A short loaded, twisted rod without contact or probe, on a fixed step that divides every
# stage: load 0.5 s, 2 turns in 1 s, then a timed hold (no equilibrium stop, so that a hold
# split in two lasts as long as the whole one).
BASE = {"rod.elements": 24, "loading.force_multiple": 5, "loading.force_ramp_time": 0.5,
        "loading.twist_density": None, "loading.twist_turns": 2, "loading.twist_rate": 2.0,
        "physics.self_contact": False, "solver.stability_probe": False,
        "solver.hold_until": "time", "solver.dt": 2e-4, "output.history_interval": 0.05}
# The split run matches the whole one to round-off, not bit for bit: each kernel call ends
# with a half drift (positions from t - dt/2 to t) and the next begins with one, where the
# whole run takes one full drift; the rounding of that split step, carried for 0.25 s of
# damped motion, was measured at 2e-15 m in positions, 2e-14 in directors and 1e-12 m/s in
# velocities. The bounds leave a factor ~500-1000 for other machines and BLAS.
POSITION_TOL = 1e-12  # m (L0 = 1 m)
DIRECTOR_TOL = 1e-11
VELOCITY_TOL = 1e-9  # m/s


def store_run(cfg, result, path):
    with open_store(path, config_text=C.to_yaml(scene=cfg), config_hash=C.config_hash(cfg),
                    version="test", kind="run") as store:
        store.write_run("run", {}, result, {})
    return f"{path}#run"


@pytest.fixture(scope="module")
def first_half(tmp_path_factory):
    """(whole run, address of its first half in a store): load, twist, hold 0.5 s as one run;
    the same with a hold of 0.25 s, stored."""
    whole = run_scene(rodphase.load("twist_under_load", BASE, solver__hold_max_time=0.5))
    cfg = rodphase.load("twist_under_load", BASE, solver__hold_max_time=0.25)
    path = tmp_path_factory.mktemp("restart") / "first.h5"
    return whole, store_run(cfg, run_scene(cfg), path)


def second_half(address, **settings):
    """The rest of the protocol from a stored state: no load ramp, no twist, hold 0.25 s."""
    values = dict(solver__hold_max_time=0.25, loading__twist_turns=0,
                  loading__force_ramp_time=0, initial_state=address)
    return rodphase.load("twist_under_load", BASE, **{**values, **settings})


def test_a_run_split_in_two_ends_where_the_whole_run_ends(first_half):
    whole, address = first_half
    second = run_scene(second_half(address))
    assert second.status == "ok"
    np.testing.assert_allclose(second.positions, whole.positions, rtol=0, atol=POSITION_TOL)
    np.testing.assert_allclose(second.directors, whole.directors, rtol=0, atol=DIRECTOR_TOL)
    np.testing.assert_allclose(second.velocities, whole.velocities, rtol=0, atol=VELOCITY_TOL)
    # the clock and the bookkeeping go on from the stored run
    assert second.history["time"][0] == pytest.approx(1.8, abs=1e-9)
    assert second.history["time"][-1] == pytest.approx(whole.history["time"][-1], abs=1e-9)
    for column in ("end_rotation", "end_displacement", "applied_force"):
        assert second.history[column][-1] == pytest.approx(whole.history[column][-1],
                                                           rel=1e-9, abs=1e-12), column


def test_link_goes_on_from_the_stored_link(first_half):
    _, address = first_half
    with read_store(address.split("#")[0]) as store:
        stored_link = store.read_run("run").history["link"][-1]
    added = 0.5
    result = run_scene(second_half(address, loading__twist_turns=added))
    assert result.status == "ok", result.message
    assert result.history["end_rotation"][-1] / (2 * np.pi) == pytest.approx(2.0 + added)
    # the rod was straight and twisted by 2 turns: Lk = turns put in, to the closure's accuracy
    assert result.history["link"][-1] == pytest.approx(stored_link + added, abs=1e-3)
    # the twist ramp turned on from the stored rotation: no jump at the first row
    assert abs(result.history["end_rotation"][0] / (2 * np.pi) - 2.0) < 0.2


def test_the_key_is_in_the_config_only_when_given(first_half):
    _, address = first_half
    plain = rodphase.load("twist_under_load", BASE)
    assert "initial_state" not in plain
    assert rodphase.load(plain, initial_state=address).initial_state == address
    # the Python API takes it as an override too
    assert rodphase.load("twist_under_load", [*BASE.items(), ("initial_state", address)])


@pytest.mark.parametrize("value, words", [
    ("#run", "empty"),  # YAML reads it as a comment
    ("out.h5", "FILE.h5#RUN_ID"),
    ("out.h5#", "FILE.h5#RUN_ID"),
    ("missing.h5#run", "no file missing.h5"),
    ("{first}#nosuch", "no run 'nosuch'"),
    ("{first}#run", "rod.elements = 24"),  # with rod.elements 20: another rod
])
def test_bad_initial_state_is_one_error_line_and_exit_2(first_half, tmp_path, value, words):
    _, address = first_half
    value = value.format(first=address.split("#")[0])
    result = CliRunner().invoke(main, ["run", "twist_under_load", "-o", str(tmp_path / "o.h5"),
                                       "--set", "rod.elements=20", "--set",
                                       f"initial_state={value}"], catch_exceptions=False)
    assert result.exit_code == 2
    assert "Traceback" not in result.output
    # one error line (the tiny rod's resolution warning is not an error)
    lines = [line for line in result.output.strip().splitlines()
             if not line.startswith("warning: rod.elements")]
    assert len(lines) == 1 and lines[0].startswith("error: initial_state"), result.output
    assert words in lines[0]
    assert not (tmp_path / "o.h5").exists()  # refused before a store was made


def test_a_store_without_rates_starts_at_rest(first_half, tmp_path):
    _, address = first_half
    path = tmp_path / "old.h5"
    path.write_bytes(open(address.split("#")[0], "rb").read())
    with h5py.File(path, "r+") as f:  # as written before the rates and clamp frames were
        for name in ("velocities", "angular_velocities", "clamp_frames"):
            del f["runs/run"][name]
    stored = read_state(f"{path}#run")
    assert stored.at_rest and not stored.velocities.any() and not stored.angular_velocities.any()
    problem = continue_from(build(second_half(address)), stored)
    assert not problem.state.v.any() and not problem.state.w.any()
    # its clamps are taken from the end elements; the rod was nearly straight and at rest in
    # its hold, so they sit where the stored clamps were
    fresh = read_state(address)
    for ours, theirs in zip(problem.clamp_reference, fresh.clamp_frames):
        np.testing.assert_allclose(ours, theirs, atol=1e-3)
    result = run_scene(second_half(f"{path}#run"))
    assert result.status == "ok"
    np.testing.assert_allclose(result.positions, stored.positions, atol=1e-4)


def test_another_rod_is_refused_with_the_key_named(first_half):
    _, address = first_half
    for key, value in (("rod.elements", 20), ("rod.length", 1.5), ("rod.radius", 0.02)):
        with pytest.raises(C.ConfigError, match="initial_state") as info:
            second_half(address, **{key.replace(".", "__"): value})
        assert key in info.value.allowed


def test_a_compressible_rod_can_be_stored_and_continued(tmp_path):
    """helical_buckling's rod is compressible: its radii were once a scalar, which the store
    could not label as one per element."""
    settings = {"rod.elements": 10, "loading.twist_turns": 0.05, "compress.slack": 0.1,
                "compress.time": 1.0, "solver.hold_until": "time",
                "solver.hold_max_time": 0.1, "output.history_interval": 0.05}
    cfg = rodphase.load("helical_buckling", settings)
    result = run_scene(cfg)
    assert result.radii.shape == (10,)
    address = store_run(cfg, result, tmp_path / "helix.h5")
    with read_store(tmp_path / "helix.h5") as store:
        assert store.read_run("run").radii.shape == (10,)
    more = run_scene(rodphase.load("helical_buckling", settings, initial_state=address))
    assert result.status == more.status == "ok", (result.message, more.message)
    # both clamps turned on from the stored rotations: 2 × 0.05 turns put in
    put_in = (more.history["end_rotation"] - more.history["start_rotation"]) / (2 * np.pi)
    assert put_in[-1] == pytest.approx(0.1)


def test_the_load_ramps_from_the_stored_load_to_the_new_one(first_half):
    whole, address = first_half
    stored = read_state(address).end_force
    new = 2 * stored
    result = run_scene(second_half(address, loading__force_multiple=10,
                                   loading__force_ramp_time=0.2))
    force, time = result.history["applied_force"], result.history["time"]
    start = time[0] - 0.05  # the first row is one history interval in
    expected = stored + (new - stored) * (time[time < start + 0.2] - start) / 0.2
    np.testing.assert_allclose(force[time < start + 0.2], expected, rtol=2e-3)
    assert force[-1] == pytest.approx(new)


@pytest.mark.parametrize("sampler", ["grid", "continuation"])
def test_a_sweep_starts_every_sample_from_the_stored_state(first_half, tmp_path, sampler):
    import yaml

    _, address = first_half
    scene_set = {k: v for k, v in BASE.items() if not k.startswith("loading.twist")}
    scene_set.update({"solver.hold_max_time": 0.1, "loading.force_ramp_time": 0,
                      "initial_state": address})
    path = tmp_path / "sweep.yaml"
    path.write_text(yaml.safe_dump({"sweep": {
        "scene": "twist_under_load", "set": scene_set, "sampler": sampler, "samples": 2,
        "axes": {"twist_density": [0.0, 0.05]}}}))
    out = tmp_path / "sweep.h5"
    result = CliRunner().invoke(main, ["sweep", str(path), "-o", str(out), "--jobs", "1",
                                       "--quiet"], catch_exceptions=False)
    # a continuation's sample is `ok` only at an equilibrium, which a timed hold never claims
    assert result.exit_code == (0 if sampler == "grid" else 1), result.output
    with read_store(out) as store:
        runs = [store.read_run(rid) for rid in store.run_ids()]
    added = sorted(r.history["end_rotation"][-1] / (2 * np.pi) - 2.0 for r in runs)
    assert added == pytest.approx([0.0, 0.05 / 0.025 / (2 * np.pi)])
    for r in runs:
        assert r.status == ("ok" if sampler == "grid" else "not_converged")
        assert r.history["link"][-1] == pytest.approx(r.history["end_rotation"][-1] / (2 * np.pi),
                                                      abs=1e-3)
