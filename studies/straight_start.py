#!/usr/bin/env python
"""Fig 3 with and without the quasi-static straight start: cost, and how much the results move.

    python studies/straight_start.py [--samples 200] [--rounds 2] [--variants 0,0.8]
        [--set KEY=VALUE ...] [--reference out/perf/fig3_ref.h5] [--write docs/history/performance.md]
        [--out out/straight]

Each variant is `rodphase sweep configs/fig3_paper.yaml --set loading.quasi_static_below=S`
(S = 0 is the paper's protocol step by step: load ramp, twist ramp from rest, hold). The
variants run one after the other in each round, the rounds repeat the sequence, so that a
machine's changing load falls on all of them alike; every sweep writes a fresh store. Per
variant: steps summed over the runs (the load-free measure of work), sweep wall time (each
round), statuses, and, point by point against S = 0, the labels and the largest differences
of writhe, link and final extension; against the fine reference sweep (n = 140, safety 0.25,
whole protocol: `benchmarks/phase_timing.py reference`), the labels of the points it has.
Stores go to --out (out/straight/).
"""

from __future__ import annotations

import os

for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

from rodphase.studytools import classified_sweep, machine, same_points, sweep_table, write_block

ROOT = Path(__file__).resolve().parents[1]
CONFIG = "fig3_paper"


def fresh_sweep(path: Path, sets: list[str], jobs: int) -> float:
    """One sweep into a new store, classified; its wall time [s] (compiling excluded: the
    kernel is compiled before the first round)."""
    for old in (path, Path(f"{path}.parts"), Path(f"{path}.lock")):
        if old.is_dir():
            shutil.rmtree(old)
        elif old.exists():
            old.unlink()
    return classified_sweep(CONFIG, path, sets, jobs)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=200)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--variants", default="0,0.8", help="fractions, comma-separated; the "
                        "first is the one the others are compared with")
    parser.add_argument("--set", dest="sets", action="append", default=[],
                        help="KEY=VALUE for every variant (e.g. solver.safety=0.6)")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--reference", type=Path, default=ROOT / "out" / "perf" / "fig3_ref.h5")
    parser.add_argument("--write", type=Path, action="append", default=[])
    parser.add_argument("--out", type=Path, default=ROOT / "out" / "straight",
                        help="folder of the stores")
    args = parser.parse_args(argv)
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    variants = [float(v) for v in args.variants.split(",")]
    common = [f"sweep.samples={args.samples}"] + args.sets
    subprocess.run([sys.executable, "-c", "from rodphase.runner import compile_kernel; "
                    "compile_kernel()"], check=True)
    load_before = machine()["load"]

    walls: dict[float, list[float]] = {v: [] for v in variants}
    for _ in range(args.rounds):
        for v in variants:
            sets = common + [f"loading.quasi_static_below={v:g}"]
            walls[v].append(fresh_sweep(out / f"fig3_{v:g}.h5", sets, args.jobs))

    base = sweep_table(out / f"fig3_{variants[0]:g}.h5")
    ref = sweep_table(args.reference) if args.reference.exists() else None
    if ref is not None and not same_points(base, ref):
        raise SystemExit(f"{args.reference}: its points are not this sweep's")
    rows = ["| quasi_static_below | runs | steps [M] | sweep wall [s] | statuses | labels as "
            f"S = {variants[0]:g} | max \\|ΔWr\\| [turns] | max \\|ΔLk\\| [turns] | max \\|Δ L/L0\\| | "
            "labels as the n = 140 reference |", "|---|---|---|---|---|---|---|---|---|---|"]
    for v in variants:
        t = sweep_table(out / f"fig3_{v:g}.h5")
        if not same_points(t, base):
            raise SystemExit(f"variant {v}: its points are not the first variant's")
        statuses = ", ".join(f"{k} {c}" for k, c in t["status"].value_counts().sort_index().items())
        agree = int((t["phase"].to_numpy() == base["phase"].to_numpy()).sum())
        diff = {k: float(np.nanmax(np.abs(t[k] - base[k]))) for k in ("writhe", "link",
                                                                       "final_extension")}
        against = "—"
        if ref is not None:
            k = len(ref)
            hits = t["phase"].to_numpy()[:k] == ref["phase"].to_numpy()
            missed = "; ".join(f"Φa {a['twist_density']:.2f}, L/L0 {a['extension']:.3f}: "
                               f"{a['phase']} → {b['phase']}"
                               for (_, a), (_, b), ok in zip(t[:k].iterrows(), ref.iterrows(), hits)
                               if not ok)
            against = f"{int(hits.sum())}/{k}" + (f" ({missed})" if missed else "")
        rows.append(f"| {v:g} | {len(t)} | {t['steps'].sum() / 1e6:.2f} | "
                    + ", ".join(f"{w:.0f}" for w in walls[v]) + f" | {statuses} | {agree}/{len(t)} | "
                    f"{diff['writhe']:.2g} | {diff['link']:.2g} | {diff['final_extension']:.2g} | "
                    f"{against} |")
    m = machine()
    text = "\n".join(rows) + (
        f"\n\n`{CONFIG}` with `--set " + " --set ".join(common) + f"`, `--jobs {args.jobs}`, "
        f"{args.rounds} round(s), the variants one after the other in each (sweep wall per "
        f"round, compiling excluded). Machine: {m['cpu']}, {m['nproc']} CPUs, load "
        + " ".join(f"{x:.2f}" for x in load_before) + " before, "
        + " ".join(f"{x:.2f}" for x in m["load"]) + " after.")
    print(text)
    for target in args.write:
        write_block(target, "straight_start", text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
