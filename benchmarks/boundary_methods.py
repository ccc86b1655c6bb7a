#!/usr/bin/env python
r"""The boundaries of Fig 3 against its maps of dots (issue #45): wall time, work and precision.

    python benchmarks/boundary_methods.py timing [--pairs 2]     # rodphase boundaries vs sweep
    python benchmarks/boundary_methods.py reference              # fine runs near the lines
    python benchmarks/boundary_methods.py reference --reference half_rate
    python benchmarks/boundary_methods.py compare [--write]      # work-precision, interleaved
    python benchmarks/boundary_methods.py errors [--write]       # compare's errors again, no runs
    python benchmarks/boundary_methods.py protocols [--write]    # what moves the missed labels

`timing` runs `rodphase boundaries fig3_paper` and `rodphase sweep fig3_paper` (today's
200-point map), both `--jobs 2`, each into a fresh store, alternating (B S S B ...), and
prints the wall times and their ratio with the machine and its load before and after. The
numba cache is warm (a first untimed `rodphase run`).

`reference [--reference paper_rate|half_rate]` places runs near the lines a default trace
found (timing's first store, or a new trace): on both sides of the plectoneme–solenoid
boundary at six twists from the triple point to 2.4 (± 0.003, 0.008, 0.02 in L/L0), on both
sides of the onset at seven extensions (± 3 % in Φa) and a 3 × 3 patch around the triple
point (± 0.01 L/L0, ± 0.05 Φa); it runs them with the paper's protocol step by step from rest
(loading.quasi_static_below = 0), n = 140 (auto resolution off) and a quarter of the stable
step, at the scene's twist rate (paper_rate) or at half of it (half_rate): finer and free of
every shortcut the methods take. Placed by one method's lines, so it favours no sampler of
dots, and it asks every method the question the lines answer.

`protocols` runs the half-rate reference's points whose label the default lines miss with
the map's protocol and with each of the reference's departures from it alone (from rest;
n = 140 and a quarter step; 0.25 turns/s): which one moves the label.

`compare` runs, interleaved in one process: random and Sobol maps of 50, 100 and 200 points
(fig3_paper with sampler random/sobol), the adaptive sampler's 120 and 200
(fig3_paper_adaptive) and the boundaries at tolerance 0.02, 0.01 (default) and 0.005; each
into a fresh store, CPU time (user + system of the command and its workers, the compile
excluded by a warm cache). The error of each, against every reference built, is the share
of the reference's runs (mixed, failed and unconverged ones left out and counted) whose
label it gets wrong: a map of dots
answers with its nearest run's label (studytools.boundary_error), the boundaries with the
label their lines predict (boundaries.predict_phase). Writes out/perf/boundary_methods.json,
docs/img/work_precision_maps.png and, with --write, the block boundary_methods of
docs/explanation/performance.md.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

from rodphase.studytools import boundary_error, machine, sweep_table, timed_rodphase, write_block

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "out" / "perf"
RODPHASE = str(Path(sys.executable).with_name("rodphase"))
AXES = ("twist_density", "extension")
BOX = (np.array([0.0, 1.0]), np.array([2.6, 0.3]))  # Fig 3's box: lo, span of (Φa, L/L0)
# the references: finer in space and time and free of the shortcuts (n = 140, a quarter of
# the stable step, from rest), at the scene's own twist rate (the paper's 0.5 turns/s) or at
# half of it (which moves the plectoneme-solenoid boundary: docs/explanation/performance.md)
FINE = ["rod.elements=140", "solver.safety=0.25", "loading.quasi_static_below=0",
        "solver.refinements=1"]
REFERENCES = {"paper_rate": FINE, "half_rate": FINE + ["loading.twist_rate=0.25"]}
# name: (command, config, --set items)
METHODS = {
    **{f"random {n}": ("sweep", "configs/fig3_paper.yaml", ["sweep.sampler=random",
                                                             f"sweep.samples={n}"])
       for n in (50, 100, 200)},
    **{f"sobol {n}": ("sweep", "configs/fig3_paper.yaml", [f"sweep.samples={n}"])
       for n in (50, 100, 200)},
    **{f"adaptive {n}": ("sweep", "configs/fig3_paper_adaptive.yaml", [f"sweep.samples={n}"])
       for n in (120, 200)},
    **{f"boundaries {t}": ("boundaries", "configs/fig3_paper.yaml", ["--tolerance", str(t)])
       for t in (0.02, 0.01, 0.005)},
    # the reference's resolution (n = 140) with everything else the map's: how much of the
    # error is the resolution's
    "boundaries 0.01, n = 140": ("boundaries", "configs/fig3_paper.yaml",
                                 ["--set", f"rod.element_length={1 / (140 * 0.025)!r}"]),
}


def timed(command: str, config: str, store: Path, extra: list[str], jobs: int = 2):
    """(wall [s], CPU [s]) of one rodphase command into a fresh store (timed_rodphase):
    a sweep's `extra` are --set items, the boundaries' options."""
    store.unlink(missing_ok=True)
    args = [a for item in extra for a in ("--set", item)] if command == "sweep" else extra
    return timed_rodphase(command, config, store, args, jobs)


def warm() -> None:
    """numba's cache filled before anything is timed: the compile is measured apart
    (benchmarks/compile_time.py)."""
    (OUT / "warm.h5").unlink(missing_ok=True)
    subprocess.run([RODPHASE, "sweep", "quick", "-o", str(OUT / "warm.h5"), "--jobs", "2",
                    "--quiet"], check=True, capture_output=True)


def load_text(m: dict) -> str:
    return " ".join(f"{x:.2f}" for x in m["load"])


def timing(pairs: int, record: bool = False) -> None:
    warm()
    before = machine()
    rows = []
    for k in range(pairs):
        order = ("boundaries", "sweep") if k % 2 == 0 else ("sweep", "boundaries")
        for command in order:
            wall, cpu = timed(command, "fig3_paper", OUT / f"timing_{command}_{k}.h5", [])
            rows.append({"command": command, "pair": k, "wall": wall, "cpu": cpu})
            print(rows[-1], flush=True)
    after = machine()
    frame = pd.DataFrame(rows)
    mean = frame.groupby("command")[["wall", "cpu"]].mean()
    ratio = mean.loc["boundaries", "wall"] / mean.loc["sweep", "wall"]
    info = {"rows": rows, "machine_before": before, "machine_after": after,
            "wall_ratio": ratio,
            "cpu_ratio": mean.loc["boundaries", "cpu"] / mean.loc["sweep", "cpu"]}
    (OUT / "boundary_timing.json").write_text(json.dumps(info, indent=1))
    print(f"on {before['cpu']}, {before['nproc']} cores, load {load_text(before)} before, "
          f"{load_text(after)} after")
    print(frame.to_string(index=False))
    text = (f"{mean.loc['boundaries', 'wall']:.1f} s wall against "
            f"{mean.loc['sweep', 'wall']:.1f} s for the 200-point map (`rodphase sweep "
            f"fig3_paper`), ratio {ratio:.3f}; CPU ratio {info['cpu_ratio']:.3f} "
            f"({pairs} pairs interleaved, both --jobs 2, numba cache warm)")
    print(text)
    if record:
        from rodphase.studytools import record_current

        record_current("fig3_lines_time", text,
                       source="`python benchmarks/boundary_methods.py timing --record`",
                       machine=f"{before['cpu']}, {before['nproc']} cores, load "
                               f"{load_text(before)} before, {load_text(after)} after")


# ---------------------------------------------------------------- the fine reference

def traced_lines() -> pd.DataFrame:
    """The lines of a default trace: the first `timing` store, or a new trace."""
    from rodphase.api import open as open_store

    store = OUT / "timing_boundaries_0.h5"
    if not store.exists():
        timed("boundaries", "fig3_paper", store, [])
    with open_store(store) as s:
        return s.boundaries()


def reference_points(lines: pd.DataFrame) -> list[dict]:
    from rodphase.boundaries import onset_extension

    onset = lines[lines["kind"] == "onset"]
    ps = lines[lines["kind"] == "plectoneme_solenoid"].sort_values("twist_density")
    triple = lines[lines["kind"] == "triple_point"].iloc[0]
    points = []
    for twist in np.linspace(triple["twist_density_high"], 2.4, 6):
        boundary = float(np.interp(twist, ps["twist_density"], ps["extension"]))
        ceiling = onset_extension(onset, twist) - 0.003  # stay buckled
        for d in (-0.02, -0.008, -0.003, 0.003, 0.008, 0.02):
            if boundary + d < ceiling:
                points.append({"twist_density": float(twist), "extension": boundary + d,
                               "near": "plectoneme_solenoid"})
    for extension in np.linspace(1.03, 1.27, 7):
        critical = float(np.interp(extension, onset["extension"], onset["twist_density"]))
        for f in (-0.03, 0.03):
            points.append({"twist_density": critical * (1 + f), "extension": float(extension),
                           "near": "onset"})
    for dt in (-0.05, 0.0, 0.05):
        for de in (-0.01, 0.0, 0.01):
            points.append({"twist_density": float(triple["twist_density"]) + dt,
                           "extension": float(triple["extension"]) + de,
                           "near": "triple_point"})
    return points


def reference(jobs: int, which: str) -> None:
    from rodphase import config
    from rodphase.scenes import SCENES
    from rodphase.sweep import Job, run_sweep, scene_for

    points = reference_points(traced_lines())
    sweep, scene = config.load_sweep("configs/fig3_paper.yaml", [
        tuple(item.split("=", 1)) for item in REFERENCES[which]], SCENES)
    jobs_ = [Job([f"ref{k:03d}"], [{"twist_density": p["twist_density"],
                                   "extension": p["extension"]}],
                 scene_for(scene, {"twist_density": p["twist_density"],
                                   "extension": p["extension"]}))
             for k, p in enumerate(points)]
    store = OUT / f"boundary_reference_{which}.h5"
    before, cpu0, t0 = machine(), time.process_time(), time.perf_counter()
    run_sweep(sweep, scene, str(store), jobs=jobs, progress=False,
              rounds_of=lambda _store: iter([jobs_]))
    wall = time.perf_counter() - t0
    subprocess.run([RODPHASE, "classify", str(store)], check=True, capture_output=True)
    table = sweep_table(store)
    table["near"] = [p["near"] for p in points]
    table.to_csv(OUT / f"boundary_reference_{which}.csv", index=False)
    info = {"points": len(points), "wall": wall, "sets": REFERENCES[which],
            "phases": table["phase"].value_counts().to_dict(), "machine": before,
            "parent_cpu": time.process_time() - cpu0}
    (OUT / f"boundary_reference_{which}.json").write_text(json.dumps(info, indent=1))
    print(json.dumps(info, indent=1))


# ---------------------------------------------------------------- which part of a protocol

# the map's protocol, and each way the half-rate reference departs from it, one at a time
PROTOCOLS = {"the map's": [], "from rest": ["loading.quasi_static_below=0"],
             "n = 140, a quarter step": ["rod.elements=140", "solver.safety=0.25"],
             "0.25 turns/s": ["loading.twist_rate=0.25"]}


def _label(sets: list[str], point: dict) -> str:
    from rodphase import config
    from rodphase.runner import run_scene
    from rodphase.scenes import SCENES
    from rodphase.sweep import scene_for
    from rodphase.tabulate import summarize

    _, scene = config.load_sweep("configs/fig3_paper.yaml",
                                 [tuple(item.split("=", 1)) for item in sets], SCENES)
    return summarize(run_scene(scene_for(scene, point)))["phase"]


def protocols(jobs: int, write: bool) -> None:
    """The reference points (half rate) whose label the default lines miss, run with the
    map's protocol and with each of the reference's departures from it alone: which one
    moves the label."""
    from joblib import Parallel, delayed

    from rodphase.boundaries import predict_phase

    ref, _ = usable_reference("half_rate")
    guessed = predict_phase(traced_lines(), ref["twist_density"].to_numpy(),
                            ref["extension"].to_numpy())
    missed = ref[guessed != ref["phase"].to_numpy()]
    points = [{"twist_density": float(r.twist_density), "extension": float(r.extension)}
              for r in missed.itertuples()]
    labels = Parallel(n_jobs=jobs)(delayed(_label)(sets, point)
                                   for sets in PROTOCOLS.values() for point in points)
    when, where = time.strftime("%Y-%m-%d", time.gmtime()), machine()
    from rodphase.studytools import git_commit

    lines = [f"Measured {when} at {git_commit()} on {where['cpu']}, {where['nproc']} cores "
             "(`python benchmarks/boundary_methods.py protocols`).", "",
             "| Φa | L/L0 | reference, 0.25 turns/s from rest, n = 140 | "
             + " | ".join(PROTOCOLS) + " |", "|---|---|---|" + "---|" * len(PROTOCOLS)]
    for k, (point, r) in enumerate(zip(points, missed.itertuples())):
        row = [labels[v * len(points) + k] for v in range(len(PROTOCOLS))]
        lines.append(f"| {point['twist_density']:.4f} | {point['extension']:.4f} | {r.phase} | "
                     + " | ".join(row) + " |")
    text = "\n".join(lines)
    print(text)
    if write:
        write_block(ROOT / "docs" / "explanation" / "performance.md", "boundary_protocols", text)


# ---------------------------------------------------------------- work against precision

def usable_reference(which: str) -> tuple[pd.DataFrame, dict]:
    """(the reference's runs with a clear label, the counts of the others by label)."""
    ref = pd.read_csv(OUT / f"boundary_reference_{which}.csv")
    left_out = ref[~ref["phase"].isin(["straight", "plectoneme", "solenoid"])]
    return (ref[ref["phase"].isin(["straight", "plectoneme", "solenoid"])],
            left_out["phase"].value_counts().to_dict())


def references() -> dict[str, tuple[pd.DataFrame, dict]]:
    """Every reference built so far, the scene's own rate first (the chart's)."""
    return {w: usable_reference(w) for w in REFERENCES
            if (OUT / f"boundary_reference_{w}.csv").exists()}


def error_of(command: str, store: Path, ref: pd.DataFrame) -> float:
    """The share of `ref`'s labels the method's answer in `store` gets wrong (the store is
    classified first, untimed): a map's nearest run's label, the lines' predicted label."""
    if command != "boundaries":
        return boundary_error(ref, sweep_table(store), AXES, *BOX)
    from rodphase.api import open as open_store
    from rodphase.boundaries import predict_phase

    with open_store(store) as s:
        lines = s.boundaries()
    guessed = predict_phase(lines, ref["twist_density"].to_numpy(), ref["extension"].to_numpy())
    return float(np.mean(guessed != ref["phase"].to_numpy()))


def measured(command: str, store: Path) -> dict:
    """The store's runs and failed runs, and its errors against every reference."""
    subprocess.run([RODPHASE, "classify", str(store)], check=True, capture_output=True)
    table = sweep_table(store)
    return {"runs": len(table), "failed": int((table["phase"] == "failed").sum()),
            "errors": {w: error_of(command, store, ref) for w, (ref, _) in references().items()}}


def compare(rounds: int, write: bool, methods: list[str]) -> None:
    warm()
    before = machine()
    rows = []
    for r in range(rounds):
        for name in (methods if r % 2 == 0 else methods[::-1]):
            command, config, extra = METHODS[name]
            store = OUT / f"wp_{name.replace(' ', '_')}_{r}.h5"
            wall, cpu = timed(command, config, store, extra)
            rows.append({"method": name, "round": r, "wall": wall, "cpu": cpu,
                         **measured(command, store)})
            print(rows[-1], flush=True)
    after = machine()
    report(rows, before, after, write)


def errors(write: bool) -> None:
    """The errors of the last compare's stores again (against a new reference, or after a
    change in how lines predict labels), with the times it measured: no run is made."""
    data = json.loads((OUT / "boundary_methods.json").read_text())
    for row in data["rows"]:
        command = METHODS[row["method"]][0]
        store = OUT / f"wp_{row['method'].replace(' ', '_')}_{row['round']}.h5"
        row.update(measured(command, store))
        row.pop("error", None)
    report(data["rows"], data["machine_before"], data["machine_after"], write)


def report(rows: list[dict], before: dict, after: dict, write: bool) -> None:
    refs = references()
    rounds = max(row["round"] for row in rows) + 1
    (OUT / "boundary_methods.json").write_text(json.dumps(
        {"rows": rows, "machine_before": before, "machine_after": after,
         "references": {w: {"runs": len(ref), "left_out": out}
                        for w, (ref, out) in refs.items()}}, indent=1))
    frame = pd.DataFrame(rows)
    for w in refs:
        frame[w] = [row["errors"][w] for row in rows]
    chart(frame, next(iter(refs)))
    mean = frame.groupby("method", sort=False)[["runs", "failed", "wall", "cpu", *refs]].mean()
    rates = {"paper_rate": "0.5 turns/s (the scene's)", "half_rate": "0.25 turns/s"}
    from rodphase.studytools import git_commit

    when = time.strftime("%Y-%m-%d", time.gmtime())
    lines = [f"Measured {when} (errors) at {git_commit()} on {before['cpu']}, "
             f"{before['nproc']} cores, load {load_text(before)} "
             f"before and {load_text(after)} after, {rounds} round(s) interleaved. References: "
             + "; ".join(f"twisted at {rates[w]}, {len(ref)} runs ({out or 'none'} left out)"
                         for w, (ref, out) in refs.items()) + ".", "",
             "| method | runs | failed | wall [s] | CPU [s] | "
             + " | ".join(f"wrong near the lines, reference at {rates[w].split(' (')[0]}"
                          for w in refs) + " |",
             "|---|---|---|---|---|" + "---|" * len(refs)]
    for name, m in mean.iterrows():
        lines.append(f"| {name} | {m['runs']:.0f} | {m['failed']:.0f} | {m['wall']:.1f} | "
                     f"{m['cpu']:.1f} | " + " | ".join(f"{m[w]:.3f}" for w in refs) + " |")
    text = "\n".join(lines)
    print(text)
    if write:
        write_block(ROOT / "docs" / "explanation" / "performance.md", "boundary_methods", text)


def chart(frame: pd.DataFrame, which: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    mean = frame.groupby("method", sort=False)[["cpu", which]].mean()
    mean = mean.rename(columns={which: "error"})
    families = {}
    for name, m in mean.iterrows():
        # "sobol 200" -> family sobol, point "200"; "boundaries 0.01, n = 140" its own family
        family, point = name.split(" ", 1)
        if "," in point:
            point, extra = point.split(",", 1)
            family += "," + extra
        families.setdefault(family, []).append((m["cpu"], m["error"], point))
    for family, items in families.items():
        items.sort()
        ax.plot([i[0] for i in items], [i[1] for i in items], "o-", label=family)
        for cpu, error, point in items:
            ax.annotate(point, (cpu, error), fontsize=7, xytext=(3, 3),
                        textcoords="offset points")
    ax.set_xscale("log")
    ax.set_ylim(bottom=-0.01)  # an error of 0 is a point of the chart (linear axis)
    ax.set_xlabel("CPU time [s] (2 workers, warm cache)")
    rate = {"paper_rate": "0.5", "half_rate": "0.25"}[which]
    ax.set_ylabel(f"share of reference labels wrong (reference at {rate} turns/s)")
    ax.set_title("Fig 3: work against precision near the boundaries")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(ROOT / "docs" / "img" / "work_precision_maps.png", dpi=120)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("step", choices=["timing", "reference", "compare", "errors",
                                         "protocols"])
    parser.add_argument("--pairs", type=int, default=2, help="timing: pairs")
    parser.add_argument("--rounds", type=int, default=1, help="compare: rounds")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--reference", choices=list(REFERENCES), default="paper_rate",
                        help="reference: which one to build")
    parser.add_argument("--methods", default=";".join(METHODS),
                        help=f"compare: methods separated by ';' (known: {'; '.join(METHODS)})")
    parser.add_argument("--write", action="store_true",
                        help="compare: update docs/explanation/performance.md")
    parser.add_argument("--record", action="store_true",
                        help="timing: make it the current figure (docs/current.json)")
    args = parser.parse_args()
    OUT.mkdir(parents=True, exist_ok=True)
    os.chdir(ROOT)
    if args.step == "timing":
        timing(args.pairs, args.record)
    elif args.step == "reference":
        reference(args.jobs, args.reference)
    elif args.step == "errors":
        errors(args.write)
    elif args.step == "protocols":
        protocols(args.jobs, args.write)
    else:
        methods = [m.strip() for m in args.methods.split(";") if m.strip()]
        unknown = [m for m in methods if m not in METHODS]
        if unknown:
            parser.error(f"--methods: unknown {unknown} (known: {list(METHODS)})")
        compare(args.rounds, args.write, methods)


if __name__ == "__main__":
    main()
