"""Issue #47 item 5: what a newcomer tripped on (tried as a new user would, 2026-12-07), each
reproduced as met."""


import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from rodphase import store as S
from rodphase.cli import main


def cli(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def one_error(out, *words) -> str:
    """Exit 2, stderr exactly one 'error:' line naming every word."""
    assert out.exit_code == 2, (out.output, out.exception)
    lines = out.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), out.stderr
    for word in words:
        assert word in lines[0], lines[0]
    return lines[0]


# ---------------------------------------------------------------- --force on a file not a store

@pytest.mark.parametrize("force", [False, True])
@pytest.mark.parametrize("what", ["yaml", "foreign hdf5"])
def test_force_never_replaces_a_file_that_is_not_a_store(tmp_path, force, what):
    """`-o typo.yaml` was refused with advice to use --force; following it replaced the
    YAML with an HDF5 store."""
    target = tmp_path / ("typo.yaml" if what == "yaml" else "other.h5")
    if what == "yaml":
        target.write_text("scene: twist_under_load\nrod: {elements: 20}\n")
    else:
        with h5py.File(target, "w") as f:
            f["data"] = np.arange(3)
    before = target.read_bytes()
    out = cli("run", "twist_under_load", "-o", target, *(["--force"] if force else []))
    line = one_error(out, str(target), "--force replaces only a rodphase store",
                     "nothing was changed")
    assert "or --force to replace it" not in line
    assert target.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == [target.name]


def test_force_still_replaces_a_store_of_another_config_or_an_empty_file(tmp_path):
    target = tmp_path / "old.h5"
    with S.open_store(target, config_text="a: 1\n", config_hash="other", version="0",
                      kind="run"):
        pass
    with pytest.raises(S.StoreMismatch, match="or --force to replace it"):
        S.open_store(target, config_text="b: 1\n", config_hash="mine", version="0", kind="run")
    before = target.read_bytes()
    with S.open_store(target, config_text="b: 1\n", config_hash="mine", version="0", kind="run",
                      replace=True):
        pass  # no run: nothing replaced (as --help says, the first new run replaces it)
    assert target.read_bytes() == before
    empty = tmp_path / "empty.h5"
    empty.touch()
    for path in (target, empty):
        with S.open_store(path, config_text="b: 1\n", config_hash="mine", version="0",
                          kind="run", replace=True) as store:
            store.write_run("run", {}, _stored_run(), {})
        with S.read_store(path) as store:
            assert store.attrs["config_hash"] == "mine" and store.run_ids() == ["run"]


# ---------------------------------------------------------------- Ctrl-C during `rodphase run`

def _interrupted_run(monkeypatch, signum):
    """`run_scene` that receives `signum` halfway, as Ctrl-C (or a batch system) sends it."""
    import os
    import time

    from rodphase import runner

    def run_scene(cfg):
        os.kill(os.getpid(), signum)
        time.sleep(5)  # the handler raises here, as between two stages of a real run
        raise AssertionError("the signal did not stop the run")

    monkeypatch.setattr(runner, "compile_kernel", lambda: 0.0)
    monkeypatch.setattr(runner, "run_scene", run_scene)


@pytest.mark.parametrize("signame, code", [("SIGINT", 130), ("SIGTERM", 143)])
def test_a_stopped_run_says_what_was_kept_exits_like_a_sweep_and_leaves_no_empty_store(
        tmp_path, monkeypatch, signame, code):
    """Ctrl-C printed "Aborted!", exited 1 and left an empty 6.6 kB store."""
    import signal

    _interrupted_run(monkeypatch, getattr(signal, signame))
    out = cli("run", "twist_under_load", "-o", tmp_path / "run.h5", "--set", "rod.elements=20")
    assert out.exit_code == code, (out.output, out.exception)
    assert "Aborted!" not in out.output
    assert f"stopped by {signame} after" in out.stderr
    assert "nothing was stored" in out.stderr and "was removed" in out.stderr
    assert "run the same command to start it again" in out.stderr
    assert list(tmp_path.iterdir()) == []
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # put back


def test_a_stopped_run_leaves_a_store_it_did_not_make_as_it_was(tmp_path, monkeypatch):
    import signal

    target = tmp_path / "old.h5"
    with S.open_store(target, config_text="a: 1\n", config_hash="other", version="0",
                      kind="run") as store:
        store.write_run("run", {}, _stored_run(), {})
    before = target.read_bytes()
    _interrupted_run(monkeypatch, signal.SIGINT)
    out = cli("run", "twist_under_load", "-o", target, "--force", "--set", "rod.elements=20")
    assert out.exit_code == 130, out.output
    assert f"{target} is as it was" in out.stderr
    assert target.read_bytes() == before


def _stored_run(status="ok", n=8, rows=4):
    from fakes import fake_run  # tests/fakes.py

    return fake_run(status, n=n, rows=rows)


# ---------------------------------------------------------------- progress without a terminal

def test_without_a_terminal_a_sweep_prints_progress_lines_at_a_steady_pace(tmp_path,
                                                                          monkeypatch):
    """Under nohup or in CI nothing was printed for minutes."""
    import re

    from test_sweep import _FakePool

    from rodphase import sweep as sw

    monkeypatch.setattr(sw, "PROGRESS_EVERY", 0.0)  # a line at every look at the workers
    jobs = [sw.Job([f"run-{i:05d}"], [{"twist_density": i / 100}], {"rod": {"elements": 6}})
            for i in range(12)]
    report = sw.SweepReport(12, 0, 0, 0, 0.0, [])
    said = []
    with S.open_store(tmp_path / "o.h5", config_text="x", config_hash="h" * 16, version="t",
                      kind="sweep") as store:
        sw._run_jobs(store, jobs, _FakePool(), False, report, said.append)
    assert said, "no progress line"
    pattern = r"(\d+) of 12 runs finished \(0 failed\), \d+ s elapsed(, about \d+ s left)?"
    for line in said:
        assert re.fullmatch(pattern, line), line
    assert re.fullmatch(pattern, said[-1]).group(1) == "12"
    monkeypatch.setattr(sw, "PROGRESS_EVERY", 3600.0)
    quiet = []
    sw._run_jobs(store, [], _FakePool(), False, sw.SweepReport(0, 0, 0, 0, 0.0, []),
                 quiet.append)
    assert quiet == []
    assert sw._duration(59.6) == "1 min 0 s" and sw._duration(3725) == "1 h 2 min"


@pytest.mark.parametrize("quiet", [False, True])
def test_the_cli_asks_for_lines_only_without_a_terminal_and_without_quiet(tmp_path, monkeypatch,
                                                                         quiet):
    from rodphase import sweep as sw

    seen = {}

    def run_sweep(*args, **kwargs):
        seen.update(kwargs)
        return sw.SweepReport(1, 0, 1, 0, 0.1, [])

    monkeypatch.setattr(sw, "run_sweep", run_sweep)
    out = cli("sweep", "quick", "-o", tmp_path / "q.h5", *(["--quiet"] if quiet else []))
    assert out.exit_code == 0, out.output
    assert seen["progress"] is False  # CliRunner's stderr is no terminal
    assert (seen["lines"] is None) == quiet


# ---------------------------------------------------------------- a resumed sweep's summary

def test_a_resumed_sweep_summarises_the_whole_store(tmp_path, monkeypatch):
    """A resumed sweep reported "38 ok, 0 failed, 2 skipped" although the store held an
    unstable run."""
    from rodphase import sweep as sw

    out_path = tmp_path / "q.h5"

    def run_sweep(sweep, scene, out, **kwargs):
        with S.open_store(out, config_text="x", config_hash="h" * 16, version="t",
                          kind="sweep") as store:
            for i, status in enumerate(["ok", "unstable", "ok", "ok"]):
                store.write_run(f"run-{i:05d}", {}, _stored_run(status), {})
        return sw.SweepReport(4, 2, 2, 0, 0.1, [])  # the two of this time: ok

    monkeypatch.setattr(sw, "run_sweep", run_sweep)
    out = cli("sweep", "quick", "-o", out_path)
    assert "this time: 2 ok, 0 failed, 2 skipped of 4" in out.stdout
    assert f"{out_path} holds 4 runs: 3 ok, 1 unstable" in out.stdout
    assert "  run-00001: unstable: unstable at t = 1 s" in out.stdout
    assert "--retry-failed runs them again" in out.stdout
    assert out.exit_code == 1  # some runs of the sweep failed, this time or before


def test_a_fresh_sweep_summary_is_as_before(tmp_path, monkeypatch):
    from rodphase import sweep as sw

    monkeypatch.setattr(sw, "run_sweep", lambda *a, **k: sw.SweepReport(4, 0, 4, 0, 0.1, []))
    out = cli("sweep", "quick", "-o", tmp_path / "q.h5")
    assert out.exit_code == 0 and "this time" not in out.stdout and " holds " not in out.stdout
    assert "4 ok, 0 failed, 0 skipped of 4 in 0.1 s" in out.stdout


# ---------------------------------------------------------------- the value in force, once

def test_config_shows_a_value_set_twice_once_and_where_it_came_from(tmp_path):
    """`rodphase config fig3_paper --set rod.elements=160` printed rod.elements: 80 under
    sweep.set and elements: 160 in the scene (fig3_paper's sweep.set had rod.elements: 80
    then; the same sweep file here)."""
    import yaml

    sweep = tmp_path / "fig3_like.yaml"
    sweep.write_text("sweep:\n  scene: scenes/twist_under_load.yaml\n  set: {rod.elements: 80, "
                     "solver.slow_down_to: 0.25}\n  axes: {twist_density: [0.0, 2.6], "
                     "extension: [1.0, 1.3]}\n")
    out = cli("config", sweep, "--set", "rod.elements=160")
    assert out.exit_code == 0, out.output
    printed = yaml.safe_load(out.stdout)
    assert "rod.elements" not in printed["sweep"]["set"]
    assert printed["sweep"]["set"]["solver.slow_down_to"] == 0.25  # the others stay
    assert printed["scene"]["rod"]["elements"] == 160
    assert "#   rod.elements: 160 from --set (replacing sweep.set's 80)" in out.stdout
    assert "#   solver.slow_down_to: 0.25 from sweep.set" in out.stdout
    assert [ln for ln in out.stdout.splitlines() if ln.strip().startswith("elements:")] == [
        "    elements: 160"]
    shipped = cli("config", "fig3_paper", "--set", "solver.slow_down_to=0.5")
    assert "#   solver.slow_down_to: 0.5 from --set (replacing sweep.set's 0.25)" in shipped.stdout
    assert "slow_down_to" not in str(yaml.safe_load(shipped.stdout)["sweep"]["set"])
    scene = cli("config", "twist_under_load", "--set", "rod.elements=60")
    assert "#   rod.elements: 60 from --set" in scene.stdout
    assert yaml.safe_load(scene.stdout)["scene"]["rod"]["elements"] == 60
    plain = cli("config", "twist_under_load")
    assert not plain.stdout.startswith("#")


# ---------------------------------------------------------------- a run's final values by name

def test_a_runs_final_topology_and_end_loads_are_named_properties():
    """They were reached by indexing history[...][-1]."""
    import math

    result = _stored_run(rows=5)
    h = result.history
    h["link"], h["twist"], h["writhe"] = (np.arange(5.0), 0.6 * np.arange(5.0),
                                          0.4 * np.arange(5.0))
    h["end_force"], h["end_torque"] = np.linspace(0, 2.5, 5), np.linspace(0, -1e-3, 5)
    assert (result.link, result.twist, result.writhe) == (4.0, 2.4, 1.6)
    assert result.end_force == 2.5 and result.end_torque == -1e-3
    assert all(isinstance(v, float) for v in (result.link, result.end_force))
    del h["link"]  # output.topology: false
    assert math.isnan(result.link)
    for name in ("link", "twist", "writhe", "end_force", "end_torque"):
        doc = getattr(type(result), name).__doc__
        assert ("[turns]" if name in ("link", "twist", "writhe") else "[N") in doc, name


# ---------------------------------------------------------------- item 4: the axes agree

def _sweep_file(tmp_path, axes: str):
    path = tmp_path / "sweep.yaml"
    path.write_text(f"sweep:\n  scene: twist_under_load\n  axes: {axes}\n  samples: 4\n")
    return path


def test_an_extension_axis_past_what_the_twist_range_can_buckle_is_refused_saying_why(
        tmp_path):
    """The extension axis took L/L0 up to 2 while the twist density stops at 3, which the
    straight rod's onset passes near L/L0 = 1.48: above it a sweep reached no buckled state
    and said nothing about why."""
    from rodphase import config as C
    from rodphase.rod.model import Rod
    from rodphase.scenes import SCENES
    from rodphase.theory import sheared_greenhill_turns

    line = one_error(cli("sweep", _sweep_file(tmp_path, "{twist_density: [0, 3], extension: "
                                                        "[1.0, 2.0]}"), "-o", tmp_path / "o.h5"),
                     "sweep.axes.extension: [1.0, 2.0]", "at most L/L0 = 1.48",
                     "passes Phi*a = 3, the largest twist density allowed",
                     "5.61 at L/L0 = 2", "no sample there could buckle",
                     "past the onset above L/L0 ~ 1.4", "stops unstable")
    assert not (tmp_path / "o.h5").exists(), line
    # the bound is where the sheared clamped Greenhill twist of this rod is Phi*a = 3
    rod = Rod(length=1.0, radius=0.025, elements=100, youngs_modulus=1e6)

    def phi_c(e):
        tension = rod.axial_stiffness * (1 - 1 / e)
        turns = sheared_greenhill_turns(tension, e, rod.length, rod.bending_stiffness,
                                        rod.twist_stiffness, rod.shear_stiffness)
        return turns * 2 * np.pi * rod.radius / rod.length

    assert phi_c(1.475) < 3.0 < phi_c(1.485)
    C.load_sweep(_sweep_file(tmp_path, "{twist_density: [0, 3], extension: [1.0, 1.475]}"), [],
                 SCENES)
    with pytest.raises(C.ConfigError, match="at most L/L0 = 1.48"):
        C.load_sweep(_sweep_file(tmp_path, "{twist_density: [0, 0.5], extension: [1.0, 1.49]}"),
                     [], SCENES)  # whatever the twist axis: the range cannot reach it
    # the stretched rod's own twist density reaches its onset (< 2) along the whole axis
    C.load_sweep(_sweep_file(tmp_path, "{twist_density_current: [0, 3], extension: [1, 2]}"),
                 [], SCENES)
    assert phi_c(2.0) / 2.0**1.5 < 2.0
