"""The Python API: what a notebook calls (rodphase.load, run, sweep, open, ...)."""

import numpy as np
import pytest
import yaml

import rodphase
from rodphase import config as C
from rodphase import scenes

TINY = {"rod.elements": 16, "solver.hold_max_time": 0.3, "loading.twist_rate": 4.0,
        "loading.force_ramp_time": 0.1, "output.history_interval": 0.1}


def test_overrides_as_a_dict_strings_pairs_and_keywords_mean_the_same():
    by_dict = rodphase.load("twist_under_load", {"rod.elements": 40, "loading.twist_density": 1.2})
    by_text = rodphase.load("twist_under_load", ["rod.elements=40", "loading.twist_density=1.2"])
    by_pair = rodphase.load("twist_under_load", [("rod.elements", 40),
                                                 ("loading.twist_density", 1.2)])
    by_word = rodphase.load("twist_under_load", rod__elements=40, loading__twist_density=1.2)
    assert by_dict == by_text == by_pair == by_word
    assert by_dict.rod.elements == 40
    again = rodphase.load(by_dict, rod__elements=20)  # a loaded config takes overrides too
    assert again.rod.elements == 20 and again.loading.twist_density == 1.2
    with pytest.raises(C.ConfigError, match="rod.elements"):
        rodphase.load("twist_under_load", rod__elements=-1)
    with pytest.raises(C.ConfigError, match="key=value"):
        rodphase.load("twist_under_load", [3])


def test_run_returns_the_result_and_equals_the_cli_path():
    from rodphase.runner import run_scene

    result = rodphase.run("twist_under_load", TINY, loading__twist_density=0.3)
    same = run_scene(rodphase.load("twist_under_load", TINY, loading__twist_density=0.3).plain())
    assert result.positions.shape == (17, 3)
    np.testing.assert_array_equal(result.positions, same.positions)


def _twice_the_load(cfg):
    """A scene defined by a user at run time: twist_under_load at twice the load."""
    doubled = C.validate_scene(C.apply_overrides(
        cfg.plain() | {"scene": "twist_under_load"},
        [("loading.force_multiple", 2 * cfg.loading.force_multiple)]), scenes.SCENES)
    return scenes.twist_under_load(doubled)


def test_a_user_scene_runs_in_parallel_sweep_workers(tmp_path, monkeypatch):
    monkeypatch.setitem(scenes.SCENES, "twice_the_load", _twice_the_load)
    scene = yaml.safe_load((C.PACKAGE_CONFIGS / "scenes" / "twist_under_load.yaml").read_text())
    scene["scene"] = "twice_the_load"
    (tmp_path / "mine.yaml").write_text(yaml.safe_dump(scene))
    (tmp_path / "sweep.yaml").write_text(yaml.safe_dump({"sweep": {
        "scene": "mine.yaml", "set": TINY, "axes": {"twist_density": [0.2, 0.4]},
        "sampler": "grid", "samples": 2}}))
    table = rodphase.run_sweep(tmp_path / "sweep.yaml", tmp_path / "out.h5", jobs=2)
    assert len(table) == 2 and set(table["status"]) <= {"ok", "not_converged"}, table.message
    assert "phase" in table and "twist_density" in table
    with rodphase.open(tmp_path / "out.h5") as store:
        result = store.read_run("run-00000")
    # the doubled load stretched the rod more than the scene file's load alone would
    alone = rodphase.run("twist_under_load", TINY, loading__twist_density=0.2)
    assert result.history["end_displacement"][-1] > 1.5 * alone.history["end_displacement"][-1]
    long = rodphase.histories(tmp_path / "out.h5", columns=["time", "end_force"])
    assert set(long["run_id"]) == {"run-00000", "run-00001"}
