#!/usr/bin/env python
"""The paper's Fig 3 as it ships, measured and written into the current figures: the sweep of
`make fig3` (configs/fig3_paper.yaml, --jobs JOBS, into a fresh store), its wall time and
steps, its labels, the critical-twist fit, and the map drawn to docs/img/fig3_paper.png.

    python benchmarks/current_fig3.py [--jobs 2] [--out out/current] [--keep-time]

Writes the rows fig3_time, fig3_labels and fig3_critical_twist of docs/current.json (and so
docs/current.md). The time row is written only when the 1-minute load average at the start
is below 0.5 per core and the cache is warm (a first call compiles: run it twice); otherwise,
or with --keep-time, the labels, the fit and the map are written and the time row is left.
"""

from __future__ import annotations

import os

for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse
import hashlib
import subprocess
import sys
from pathlib import Path

from rodphase.studytools import record_current, timed_sweep

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "configs" / "fig3_paper.yaml"
FIGURE = ROOT / "docs" / "img" / "fig3_paper.png"
PHASES = ("straight", "plectoneme", "solenoid", "mixed", "failed")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--out", type=Path, default=ROOT / "out" / "current")
    parser.add_argument("--keep-time", action="store_true",
                        help="write the labels, the fit and the map, not the time")
    args = parser.parse_args(argv)

    import pandas as pd

    from rodphase.api import table
    from rodphase.tabulate import critical_twist

    args.out.mkdir(parents=True, exist_ok=True)
    store = args.out / "fig3_paper.h5"
    store.unlink(missing_ok=True)
    idle = os.getloadavg()[0] < 0.5 * (os.cpu_count() or 1)
    wall, cpu = timed_sweep(str(CONFIG), store, [], args.jobs)
    runs = table(store)
    counts = runs["phase"].value_counts()
    status = runs["status"].value_counts()
    labels = ", ".join(f"{p} {int(counts.get(p, 0))}" for p in PHASES)
    labels += " (" + ", ".join(f"{int(n)} `{s}`" for s, n in status.items() if s != "unstable") + ")"
    steps = runs["steps"].sum() / 1e6 if "steps" in runs else float("nan")
    rodphase = str(Path(sys.executable).with_name("rodphase"))
    subprocess.run([rodphase, "plot", str(store), "--kind", "phase", "-o", str(FIGURE)],
                   check=True)
    digest = hashlib.sha256(FIGURE.read_bytes()).hexdigest()

    source = "`make current-fig3`"
    print(f"Fig 3: {wall:.1f} s wall, {cpu:.1f} CPU-s, {steps:.2f} M steps; {labels}")
    if idle and not args.keep_time:
        record_current("fig3_time", f"{wall:.1f} s wall; {cpu:.1f} CPU-s; {steps:.2f} M steps",
                       source=source)
    else:
        print("time not recorded: the machine was busy at the start (or --keep-time)")
    record_current("fig3_labels", labels, source=source,
                   extra={"figure": {"path": "img/fig3_paper.png", "sha256": digest}})
    points = critical_twist(pd.DataFrame(runs), "phi_a_rest", 10, 1.1)
    if points.attrs["fit"] is not None:
        slope, intercept, r2, used, _ = points.attrs["fit"]
        sign = "−" if intercept < 0 else "+"
        record_current("fig3_critical_twist", f"Φa_c = {slope:.2f}·(L/L0) {sign} "
                       f"{abs(intercept):.2f}, R² = {r2:.3f} ({used} bins)", source=source)


if __name__ == "__main__":
    main()
