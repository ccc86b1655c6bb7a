"""Same input, same answer: a run and a sweep are functions of their config alone.

The case that broke it (issue #46): a point just below the model's onset, where a hold's
equilibrium is pushed along its most unstable mode. The push's direction came from ARPACK,
which starts from a random vector, so the same config ended straight in one call and a
solenoid in the next. Here the point is Φa = 0.9997 × the onset of a 40-element rod at
L/L0 = 1.2: its holds are pushed twice (checked below), so the eigen-solver is on the path.
Bit for bit, because nothing in a run is random but what the config seeds."""

import hashlib
import math
import os
import subprocess
import sys

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

import rodphase
from rodphase import config as C
from rodphase.cli import main
from rodphase.rod.onset import straight_onset_turns
from rodphase.scenes import rod_from
from rodphase.store import read_store

NEAR = {"rod.elements": 40, "loading.quasi_static_below": 0.8, "loading.force_multiple": None,
        "loading.extension": 1.2, "loading.twist_rate": 1.0, "output.topology": False}


def onset_twist_density(settings: dict) -> float:
    cfg = rodphase.load("twist_under_load", dict(settings, **{"loading.twist_density": 1.0}))
    turns = straight_onset_turns(rod_from(cfg), C.straight_extension(cfg))
    return turns * 2 * math.pi * cfg.rod.radius / cfg.rod.length


def fingerprint(positions: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(positions, dtype=np.float64).tobytes()).hexdigest()


RUN_ELSEWHERE = """
import hashlib, sys, numpy as np, rodphase, yaml
settings = yaml.safe_load(sys.stdin.read())
result = rodphase.run(rodphase.load("twist_under_load", settings))
print(hashlib.sha256(np.ascontiguousarray(result.positions, dtype=np.float64).tobytes()).hexdigest())
"""


def test_a_run_pushed_near_its_onset_is_bit_identical_in_this_process_and_another():
    settings = dict(NEAR, **{"loading.twist_density": 0.9997 * onset_twist_density(NEAR)})
    results = [rodphase.run(rodphase.load("twist_under_load", settings)) for _ in range(3)]
    pushes = [sum("pushed" in note for note in r.diagnostics["notes"]) for r in results]
    assert pushes[0] >= 1, "the point must exercise the stability push"
    assert len({fingerprint(r.positions) for r in results}) == 1, pushes
    assert len({tuple(r.history["time"]) for r in results}) == 1
    elsewhere = subprocess.run([sys.executable, "-c", RUN_ELSEWHERE], input=yaml.safe_dump(settings),
                               capture_output=True, text=True, timeout=600, check=True)
    assert elsewhere.stdout.split()[-1] == fingerprint(results[0].positions)


def near_onset_sweep(tmp_path) -> "os.PathLike":
    # four points astride the onset at two loads: pushed holds on both sides of it
    onset = onset_twist_density(NEAR)
    data = {"sweep": {"scene": "twist_under_load",
                      "set": {k: v for k, v in NEAR.items()
                              if k not in ("loading.extension", "loading.force_multiple")},
                      "axes": {"twist_density": [0.999 * onset, 1.0005 * onset],
                               "extension": [1.195, 1.2]},
                      "sampler": "grid", "samples": 4, "seed": 5}}
    path = tmp_path / "near.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def stored_positions(path) -> dict:
    with read_store(path) as store:
        return {rid: fingerprint(store.read_run(rid).positions) for rid in store.run_ids()}


@pytest.mark.slow  # long: 29 s of CPU, three sweeps and a kill (67 s wall at load 4)
def test_a_near_onset_sweep_is_the_same_on_one_or_two_jobs_and_killed_and_resumed(tmp_path):
    sweep = near_onset_sweep(tmp_path)
    one, two, killed = tmp_path / "one.h5", tmp_path / "two.h5", tmp_path / "killed.h5"

    def cli(*args):
        return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)

    assert cli("sweep", sweep, "-o", one, "--jobs", 1, "--quiet").exit_code in (0, 1)
    assert cli("sweep", sweep, "-o", two, "--jobs", 2, "--quiet").exit_code in (0, 1)
    reference = stored_positions(one)
    assert len(reference) == 4
    assert stored_positions(two) == reference
    # killed with SIGKILL once a run is in the file, then the same command again
    from killing import kill_after_runs  # tests/killing.py

    finished = kill_after_runs(["sweep", sweep, "-o", killed, "--jobs", 1, "--quiet"], killed, 1)
    if len(finished) == 4:
        pytest.skip("the sweep finished before it could be killed")
    result = cli("sweep", sweep, "-o", killed, "--quiet")
    assert result.exit_code in (0, 1), result.output
    assert stored_positions(killed) == reference


def test_the_label_near_the_onset_follows_the_static_test_outside_a_flagged_band():
    # The quick sweep's rod (64 elements, refined to 128) at L/L0 = 1.2: at twice the band
    # below the model's onset it ends straight and at twice the band above it buckles, as
    # the straight rod's static stability says; within the band (3e-4 below, where the push
    # decided the label in #46) the table flags it instead of trusting the label.
    from rodphase.classify import ONSET_BAND
    from rodphase.rod.onset import StraightBranch
    from rodphase.tabulate import onset_columns, summarize

    settings = dict(NEAR, **{"rod.elements": 64, "solver.refine_up_to": 128})
    onset = onset_twist_density(settings)
    cfg = rodphase.load("twist_under_load", dict(settings, **{"loading.twist_density": onset}))
    branch = StraightBranch(rod_from(cfg), C.straight_extension(cfg))
    to_turns = cfg.rod.length / (2 * math.pi * cfg.rod.radius)
    rows = []
    for factor in (1 - 2 * ONSET_BAND, 1 - 3e-4, 1 + 2 * ONSET_BAND):
        run_cfg = rodphase.load("twist_under_load",
                                dict(settings, **{"loading.twist_density": factor * onset}))
        result = rodphase.run(run_cfg)
        assert result.status == "ok", result.message
        rows.append(summarize(result) | {"static_stable": branch.stable(factor * onset * to_turns)})
    table = onset_columns(__import__("pandas").DataFrame(rows), cfg.plain())
    below, inside, above = table.to_dict("records")
    assert below["static_stable"] and below["phase"] == "straight" and not below["near_onset"]
    assert not above["static_stable"] and above["phase"] != "straight"
    assert not above["near_onset"]
    assert inside["near_onset"] and inside["onset_ratio"] == pytest.approx(1 - 3e-4, abs=1e-5)
    assert below["onset_ratio"] == pytest.approx(1 - 2 * ONSET_BAND, abs=1e-5)
