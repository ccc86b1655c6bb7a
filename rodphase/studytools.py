"""What the scripts of benchmarks/ and studies/ share: the machine a number was measured on,
the named Markdown block of docs/ a script rewrites, a sweep run through the CLI, and sweep
stores read point by point.

Nothing in the package calls these; they live here, not in a scripts module, so that every
script imports them the same way (``from rodphase.studytools import write_block``) wherever
it is run from, and so that they are tested (tests/test_studytools.py).
"""

from __future__ import annotations

import os
from pathlib import Path


def machine() -> dict:
    """CPU model, core count and load average (1, 5, 15 min), to print next to every timing."""
    cpu = "unknown"
    try:
        lines = Path("/proc/cpuinfo").read_text().splitlines()
    except OSError:  # not Linux
        lines = []
    for line in lines:
        if line.startswith("model name"):
            cpu = line.split(":", 1)[1].strip()
            break
    return {"cpu": cpu, "nproc": os.cpu_count(), "load": os.getloadavg()}


def write_block(doc: Path, name: str, text: str) -> None:
    """Replace the text between ``<!-- name:begin -->`` and ``<!-- name:end -->`` in `doc`
    (appended at the end, with both markers, when the file has no such block)."""
    doc = Path(doc)
    begin, end = f"<!-- {name}:begin -->", f"<!-- {name}:end -->"
    body = doc.read_text() if doc.exists() else ""
    if begin in body and end in body:
        head, rest = body.split(begin, 1)
        _, tail = rest.split(end, 1)
        body = f"{head}{begin}\n{text}\n{end}{tail}"
    else:
        body += f"\n{begin}\n{text}\n{end}\n"
    doc.write_text(body)
    print(f"updated {doc} ({name})")


def classified_sweep(config: str, path: Path, sets: list[str], jobs: int) -> float:
    """`rodphase sweep CONFIG -o PATH --jobs JOBS --quiet --set ...` (a new store, or the
    stored one resumed), then `rodphase classify PATH`; the sweep's wall time [s]. A sweep
    whose runs partly failed (exit 1: they are recorded) is fine; any other exit stops."""
    return timed_sweep(config, path, sets, jobs)[0]


def timed_sweep(config: str, path: Path, sets: list[str], jobs: int) -> tuple[float, float]:
    """classified_sweep's sweep, and its cost: (wall [s], CPU [s]: user + system of the
    sweep process and the workers it waited for, the compile included)."""
    import resource
    import subprocess
    import sys
    import time

    rodphase = str(Path(sys.executable).with_name("rodphase"))
    args = [rodphase, "sweep", config, "-o", str(path), "--jobs", str(jobs), "--quiet"]
    for item in sets:
        args += ["--set", item]

    def children() -> float:
        usage = resource.getrusage(resource.RUSAGE_CHILDREN)
        return usage.ru_utime + usage.ru_stime

    cpu0, t0 = children(), time.perf_counter()
    done = subprocess.run(args)
    wall, cpu = time.perf_counter() - t0, children() - cpu0
    if done.returncode not in (0, 1):
        raise SystemExit(f"{' '.join(args)} exited {done.returncode}")
    subprocess.run([rodphase, "classify", str(path)], check=True, capture_output=True)
    return wall, cpu


def sweep_table(path: Path):
    """The classified table of a sweep store, in run order. Sweeps of one config with the same
    sampler and seed draw the same points in the same order, so the i-th rows of two such
    tables are the same point (check it with same_points)."""
    from .api import table

    return table(path).sort_values("run_id").reset_index(drop=True)


def same_points(a, b, axes=("twist_density", "extension")) -> bool:
    """Whether the first rows of two sweep tables are the same points, on the axes both have."""
    import numpy as np

    n = min(len(a), len(b))
    return all(np.allclose(a[k][:n], b[k][:n], rtol=1e-9) for k in axes if k in a and k in b)


def boundary_error(reference, samples, axes, lo, span) -> float:
    """The share of `reference` points (a table with a phase column) whose phase the nearest
    point of `samples` (failed ones left out) gets wrong, nearest in the `axes` coordinates
    scaled to the box (lo, span): the area of the box the boundaries `samples` imply
    misplace."""
    import numpy as np
    from scipy.spatial import cKDTree

    def scaled(table):
        return (table[list(axes)].to_numpy(float) - lo) / span

    usable = samples[samples["phase"] != "failed"]
    _, nearest = cKDTree(scaled(usable)).query(scaled(reference))
    guessed = usable["phase"].to_numpy()[nearest]
    return float(np.mean(guessed != reference["phase"].to_numpy()))
