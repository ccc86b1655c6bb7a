"""numba's disk cache of the kernel: it follows every kernel module, and cached machine code
gives the same bits as a fresh compile.

Each check runs a copy of the package in fresh subprocesses with its own NUMBA_CACHE_DIR,
so the copies compile the kernel from scratch (about a minute of CPU each time).
"""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import rodphase

pytestmark = pytest.mark.slow

# A coil whose neighbouring turns overlap by a tenth of the radius: contact acts from the
# first step, while the coil (straight at rest, with a rest twist) springs open and thickens
# (radius growth). Rest twist and growth are what made a cached kernel differ from a fresh
# one before the fix (the muscle scene has both): they run through internal_loads' terms.
RUN = r"""
import json, sys
import numpy as np
from rodphase.rod import Contact, Controls, Problem, Rod, Solver, Stage, ramp, simulate, state_from
from rodphase.rod import kernel

n, a, R, turns = 40, 0.02, 0.1, 2.0
pitch = 1.9 * a
s = np.linspace(0.0, 2 * np.pi * turns, n + 1)
x = np.stack([R * np.cos(s), R * np.sin(s), pitch * s / (2 * np.pi)], axis=1)
tangent = np.diff(x, axis=0)
length = np.linalg.norm(tangent, axis=1).sum()
d3 = tangent / np.linalg.norm(tangent, axis=1)[:, None]
mid = 0.5 * (x[1:] + x[:-1])
inward = -mid * np.array([1.0, 1.0, 0.0])
d1 = inward - np.sum(inward * d3, axis=1)[:, None] * d3
d1 /= np.linalg.norm(d1, axis=1)[:, None]
d2 = np.cross(d3, d1)
rod = Rod(length=length, radius=a, elements=n, rest_curvature=(0.0, 0.0, 5.0))
problem = Problem(rod=rod, state=state_from(x, np.stack([d1, d2, d3], axis=1)),
                  contact=Contact(enabled=True), solver=Solver(history_interval=1e-4),
                  controls=Controls(radius=ramp(0.0, 0.15, 1.0, 1.1)), stages=(Stage(0.15),))
r = simulate(problem)

# A hold that ends at a probed equilibrium, without contact: it runs the pieces advance calls
# at check steps only (guards, history rows and snapshots, settle windows, the stability
# probe), which are compiled on their own rather than inlined (kernel's module docstring).
from rodphase import config as C
from rodphase.scenes import SCENES, build
cfg = C.load_scene("twist_under_load", [("rod.elements", 20), ("loading.twist_density", 0.3),
                                        ("solver.hold_max_time", 3.0),
                                        ("output.history_interval", 0.01)], SCENES)
held = simulate(build(cfg))

def table(history):
    return np.stack([np.asarray(history[k], float) for k in sorted(history)])

np.savez(sys.argv[1], positions=r.positions, directors=r.directors, history=table(r.history),
         snapshots=r.snapshot_positions, held_positions=held.positions,
         held_directors=held.directors, held_history=table(held.history),
         held_snapshots=held.snapshot_positions, held_d1=held.snapshot_d1)
stats = kernel.advance.stats
print(json.dumps({"status": r.status, "message": r.message,
                  "contacts": float(r.history["contacts"].max()),
                  "held_status": held.status,
                  "held_probes": held.diagnostics["stages"][-1]["probes"],
                  "hits": sum(stats.cache_hits.values()),
                  "misses": sum(stats.cache_misses.values())}))
"""


def _copy_package(where: Path) -> Path:
    source = Path(rodphase.__file__).parent
    shutil.copytree(source, where / "rodphase", ignore=shutil.ignore_patterns("__pycache__"))
    return where / "rodphase"


def _run(root: Path, cache: Path, out: Path):
    env = dict(os.environ, PYTHONPATH=str(root), NUMBA_CACHE_DIR=str(cache))
    # the timeout only catches a hang: a cold compile is about a minute of CPU, but on two
    # cores shared with other work it took over 600 s of wall time (load 12, 2026-12-07)
    done = subprocess.run([sys.executable, "-c", RUN, str(out)], env=env, cwd=str(root),
                          capture_output=True, text=True, timeout=3600)
    assert done.returncode == 0, done.stderr[-3000:]
    report = json.loads(done.stdout.strip().splitlines()[-1])
    assert report["status"] == "ok", report["message"]
    assert report["contacts"] > 0
    assert report["held_status"] == "ok" and report["held_probes"] > 0
    with np.load(out) as arrays:
        return dict(arrays), report


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """The tiny run three times on a copy of the package sharing one cache directory: compiled
    fresh, loaded from the cache, and after an edit of contact.py alone (twice the spring)."""
    root = tmp_path_factory.mktemp("kernel_cache")
    package = _copy_package(root)
    cache = root / "numba_cache"
    out = {"fresh": _run(root, cache, root / "fresh.npz"),
           "cached": _run(root, cache, root / "cached.npz")}
    contact = package / "rod" / "contact.py"
    text = contact.read_text()
    spring = "spring = scale * stiffness[i] * overlap"
    assert spring in text
    contact.write_text(text.replace(spring, "spring = 2.0 * scale * stiffness[i] * overlap"))
    out["edited"] = _run(root, cache, root / "edited.npz")
    return out


def test_a_kernel_from_the_disk_cache_gives_the_bits_of_a_fresh_compile(runs):
    fresh, first = runs["fresh"]
    cached, second = runs["cached"]
    assert first["misses"] == 1 and first["hits"] == 0  # compiled there
    assert second["hits"] == 1 and second["misses"] == 0  # loaded from the cache
    # The same machine code, so the same bits. (Before the kernel's callees were inlined, a
    # compiling process ran the callees' own copies and a loading process the copies linked
    # into advance, optimised apart: up to 1e-12 m on the reference scenes.) Every array: the
    # final states, the history rows and the snapshots of both runs.
    assert fresh.keys() == cached.keys()
    for name in fresh:
        assert np.array_equal(fresh[name], cached[name], equal_nan=True), name


def test_an_edit_of_contact_py_alone_reaches_the_cached_kernel(runs):
    fresh, _ = runs["fresh"]
    edited, third = runs["edited"]
    assert third["misses"] == 1 and third["hits"] == 0  # compiled again, not the stale code
    assert not np.allclose(edited["positions"], fresh["positions"], rtol=0.0, atol=1e-9)
