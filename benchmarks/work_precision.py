#!/usr/bin/env python
"""Work-precision: error against CPU time over the number of elements n and the time step.

    python benchmarks/work_precision.py [--only stretch,cantilever,greenhill,writhe] [--quick]
                                     [--write docs/history/performance.md]

Reference problems (the setups of tests/test_rod.py):

1. stretch: the paper's rod (L0 = 1 m, a = 25 mm) under an end force 0.3 E A0, relaxed to
   equilibrium; exact L/L0 = 1/(1 − F/(E A0)). The discrete rod is uniformly stretched at any
   n, so the error is the equilibrium tolerance's; a tolerance sweep at n = 20 shows that.
2. cantilever: a = 10 mm, tip load giving a deflection of 1e-3 L; Timoshenko's tip deflection
   with the rod's own shear stiffness 4GA/3.
3. greenhill: a = 10 mm, T L²/B = 100 between two clamps (the loaded end slides axially); the
   end moment at which a 1e-6 m/s kick grows, found by bisection on M/M_c to 0.2 %, against the
   analytic M_c (with B/e² and L = e L0 of the stretched rod). CPU time is the whole bisection.
4. writhe: the writhe (turns) at the end of the hold of Fig 2a's scene at Φa = 1.0 (25 F_C,
   plectoneme) and of Fig 2b's at Φa = 1.6 (90 F_C, solenoid), twisted at 0.2 turns/s,
   against a fine run (n = 200, safety 0.25). One run each.

The time step is dt = safety × stable_time_step (rodphase's default safety is 0.5); each
configuration is run with safety 0.5 and 0.25. CPU time is time.process_time() around
`simulate` in this single process (numba compiled and cached before timing; NUMBA_NUM_THREADS
= 1). µs/step is CPU time over steps.

Writes docs/img/work_precision.png and out/perf/work_precision.json and prints Markdown tables
(--write puts them into docs/history/performance.md between markers).
"""

from __future__ import annotations

import os

for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

from rodphase.rod import (
    Controls,
    Ends,
    Problem,
    Rod,
    Solver,
    Stage,
    constant,
    ramp,
    simulate,
    straight_state,
)
from rodphase.studytools import machine, write_block

ROOT = Path(__file__).resolve().parents[1]
from rodphase.theory import greenhill_clamped_moment

SAFETIES = (0.5, 0.25)


def load_text() -> str:
    return "{:.2f} {:.2f} {:.2f}".format(*os.getloadavg())




def timed(problem: Problem, **kwargs):
    t0 = time.process_time()
    result = simulate(problem, **kwargs)
    cpu = time.process_time() - t0
    steps = int(result.diagnostics["steps"])
    return result, cpu, steps


def record(problem_name, n, safety, error, cpu, steps, status, load, **extra) -> dict:
    row = {"problem": problem_name, "n": n, "safety": safety, "error": float(error), "cpu": cpu,
           "steps": steps, "us_per_step": 1e6 * cpu / max(steps, 1), "status": status, "load": load}
    row.update(extra)
    print(f"{problem_name:11s} n={n:4d} safety={safety:<5g} error={error:.3e} cpu={cpu:7.2f} s "
          f"steps={steps:8d} {row['us_per_step']:6.2f} us/step {status} "
          + " ".join(f"{k}={v}" for k, v in extra.items()) + f" (load {load})", flush=True)
    return row


# ---------------------------------------------------------------- 1. static stretch

def stretch(n: int, safety: float, tolerance: float = 1e-6, fraction: float = 0.3) -> dict:
    rod = Rod(length=1.0, radius=0.025, elements=n)
    force = fraction * rod.youngs_modulus * rod.area
    problem = Problem(rod=rod, state=straight_state(rod),
                      controls=Controls(end_force=ramp(0, 0.2, 0, force)),
                      solver=Solver(damping=40.0, hold_tolerance=tolerance, safety=safety,
                                    history_interval=1.0),
                      stages=(Stage(10.0, until_equilibrium=True),))
    load = load_text()
    result, cpu, steps = timed(problem)
    exact = 1.0 / (1.0 - fraction)
    error = abs(result.positions[-1, 2] / rod.length / exact - 1.0)
    return record("stretch", n, safety, error, cpu, steps, result.status, load, tolerance=tolerance)


# ---------------------------------------------------------------- 2. cantilever

def cantilever(n: int, safety: float) -> dict:
    rod = Rod(length=1.0, radius=0.01, elements=n)
    bending = rod.bending_stiffness
    load_n = 3e-3 * bending
    problem = Problem(rod=rod, state=straight_state(rod),
                      controls=Controls(end_force=constant(load_n), force_direction=(1, 0, 0)),
                      solver=Solver(damping=1.2, hold_tolerance=1e-7, safety=safety,
                                    history_interval=10.0),
                      stages=(Stage(100.0, until_equilibrium=True),))
    load = load_text()
    result, cpu, steps = timed(problem)
    shear = 4 * rod.shear_modulus * rod.area / 3
    exact = load_n / (3 * bending) + load_n / shear
    error = abs(result.positions[-1, 0] / exact - 1.0)
    return record("cantilever", n, safety, error, cpu, steps, result.status, load)


# ---------------------------------------------------------------- 3. Greenhill onset

def greenhill_grows(rod: Rod, fraction: float, m_c: float, stretch_e: float, tension: float,
                    safety: float):
    """Does a kick grow at M = fraction × M_c? (lateral excursion beyond 1e-5 m, 70x the kick's
    ~1.5e-7 m, or still larger over the second half of 12 s than over the first quarter)."""
    theta = fraction * m_c * rod.length / rod.twist_stiffness * stretch_e**3
    state = straight_state(rod, twist_turns=theta / (2 * math.pi))
    state.x[2] *= stretch_e
    s = np.linspace(0.0, 1.0, rod.elements + 1)
    state.v[0] = 1e-6 * np.sin(np.pi * s)
    state.v[1] = 1e-6 * np.sin(2 * np.pi * s)
    problem = Problem(rod=rod, state=state,
                      ends=Ends(end_held=(True, True, False), end_frame_held=True),
                      controls=Controls(end_force=constant(tension)),
                      solver=Solver(damping=0.1, history_interval=0.05, safety=safety),
                      stages=(Stage(12.0),))
    result, cpu, steps = timed(problem)
    lateral = np.linalg.norm(result.snapshot_positions[:, :, :2], axis=2).max(axis=1)
    q = len(lateral) // 4
    grows = lateral.max() > 1e-5 or lateral[2 * q:].max() > lateral[:q].max()
    return bool(grows), cpu, steps, result.status


def greenhill(n: int, safety: float, resolution: float = 0.002) -> dict:
    rod = Rod(length=1.0, radius=0.01, elements=n)
    bending = rod.bending_stiffness
    tension = 100 * bending / rod.length**2
    e = 1.0 / (1.0 - tension / (rod.youngs_modulus * rod.area))
    m_c = greenhill_clamped_moment(tension, e * rod.length, bending / e**2)
    load = load_text()
    cpu_total, steps_total, trials = 0.0, 0, 0

    def grows(f):
        nonlocal cpu_total, steps_total, trials
        g, cpu, steps, status = greenhill_grows(rod, f, m_c, e, tension, safety)
        if status != "ok":
            raise RuntimeError(f"Greenhill trial n={n} f={f}: {status}")
        cpu_total += cpu
        steps_total += steps
        trials += 1
        return g

    lo, hi = 0.9, 1.1
    while grows(lo):
        lo -= 0.1
    while not grows(hi):
        hi += 0.1
    while hi - lo > resolution:
        mid = 0.5 * (lo + hi)
        if grows(mid):
            hi = mid
        else:
            lo = mid
    onset = 0.5 * (lo + hi)
    return record("greenhill", n, safety, abs(onset - 1.0), cpu_total, steps_total, "ok", load,
                  onset=round(onset, 5), trials=trials)


# ---------------------------------------------------------------- 4. writhe

WRITHE_SCENES = {"plectoneme": ("fig2a_plectoneme", 1.0), "solenoid": ("fig2b_solenoid", 1.6)}


def writhe_run(kind: str, n: int, safety: float) -> tuple[float, float, int, str, dict]:
    from rodphase import config as C
    from rodphase.scenes import SCENES, build
    from rodphase.topology import writhe

    scene, phi_a = WRITHE_SCENES[kind]
    cfg = C.load_scene(scene, [("rod.elements", n), ("solver.safety", safety),
                               ("loading.twist_density", phi_a)], SCENES)
    problem = build(cfg)
    result, cpu, steps = timed(problem)
    wr = float(writhe(result.positions))
    hold = result.diagnostics["stages"][-1]
    extra = {"hold_steps": hold["steps"], "hold_equilibrium": hold["equilibrium"],
             "max_penetration": round(float(result.diagnostics["max_penetration"]), 4)}
    return wr, cpu, steps, result.status, extra


def writhe_family(kind: str, ns, reference_n: int, reference_safety: float) -> list[dict]:
    load = load_text()
    wr_ref, cpu, steps, status, extra = writhe_run(kind, reference_n, reference_safety)
    rows = [record(f"{kind}", reference_n, reference_safety, 0.0, cpu, steps, status, load,
                   writhe=round(wr_ref, 4), reference=True, **extra)]
    for n in ns:
        for safety in SAFETIES:
            load = load_text()
            wr, cpu, steps, status, extra = writhe_run(kind, n, safety)
            rows.append(record(f"{kind}", n, safety, abs(wr - wr_ref) / abs(wr_ref), cpu, steps,
                               status, load, writhe=round(wr, 4), reference=False, **extra))
    return rows


# ---------------------------------------------------------------- output

def pareto(rows: list[dict]) -> set[int]:
    """Indices of rows no other row beats in both error and CPU time."""
    front = set()
    for i, r in enumerate(rows):
        if not any(o["cpu"] <= r["cpu"] and o["error"] <= r["error"]
                   and (o["cpu"] < r["cpu"] or o["error"] < r["error"]) for o in rows):
            front.add(i)
    return front


def tables(data: dict) -> str:
    out = []
    for name, rows in data["problems"].items():
        pts = [r for r in rows if not r.get("reference")]
        front = pareto(pts)
        unit = "relative error of Wr" if name in ("plectoneme", "solenoid") else (
            "|M_onset/M_c − 1|" if name == "greenhill" else "relative error")
        extra_cols = {"stretch": ["tolerance"], "greenhill": ["onset", "trials"],
                      "plectoneme": ["writhe", "hold_steps", "hold_equilibrium"],
                      "solenoid": ["writhe", "hold_steps", "hold_equilibrium"]}.get(name, [])
        head = ["n", "safety", unit, "CPU [s]", "steps", "µs/step", "status"] + extra_cols + ["Pareto", "load"]
        out.append(f"**{name}**\n")
        out.append("| " + " | ".join(head) + " |")
        out.append("|" + "---|" * len(head))
        for r in rows:
            pareto_mark = "reference" if r.get("reference") else ("●" if pts.index(r) in front else "")
            cells = [str(r["n"]), f"{r['safety']:g}",
                     "—" if r.get("reference") else f"{r['error']:.2e}", f"{r['cpu']:.2f}",
                     str(r["steps"]), f"{r['us_per_step']:.2f}", r["status"]]
            cells += [str(r.get(c, "")) for c in extra_cols]
            cells += [pareto_mark, r["load"]]
            out.append("| " + " | ".join(cells) + " |")
        out.append("")
    return "\n".join(out)


def plot(data: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    names = list(data["problems"])
    cols = 3 if len(names) > 2 else len(names)
    rows_n = math.ceil(len(names) / cols)
    fig, axes = plt.subplots(rows_n, cols, figsize=(4.6 * cols, 3.9 * rows_n), squeeze=False)
    for ax, name in zip(axes.flat, names):
        rows = [r for r in data["problems"][name] if not r.get("reference")]
        front = pareto(rows)
        groups = {}
        for r in rows:
            key = (r["safety"], r.get("tolerance")) if name == "stretch" else (r["safety"], None)
            groups.setdefault(key, []).append(r)
        for (safety, tol), grp in sorted(groups.items(), key=lambda kv: (kv[0][0], kv[0][1] or 0)):
            grp = sorted(grp, key=lambda r: r["n"])
            label = f"safety {safety:g}" + (f", tol {tol:g}" if tol is not None else "")
            err = [max(r["error"], 1e-12) for r in grp]
            _line, = ax.plot([r["cpu"] for r in grp], err, "o-" if safety == 0.5 else "s--",
                            label=label, ms=4)
            for r, e in zip(grp, err):
                if r["status"] != "ok":
                    ax.plot(r["cpu"], e, "x", color="red", ms=9)
                ax.annotate(str(r["n"]), (r["cpu"], e), fontsize=6, xytext=(3, 3),
                            textcoords="offset points")
        fx = sorted((rows[i]["cpu"], max(rows[i]["error"], 1e-12)) for i in front)
        ax.plot([p[0] for p in fx], [p[1] for p in fx], "-", color="0.6", lw=4, alpha=0.35,
                zorder=0, label="Pareto front")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.set_xlabel("CPU time [s] (one core)")
        ax.set_ylabel("relative error")
        ax.set_title(name + (" (labels: n; red x: hold not converged)"
                             if name in ("plectoneme", "solenoid") else " (labels: n)"), fontsize=9)
        ax.legend(fontsize=6)
    for ax in list(axes.flat)[len(names):]:
        ax.axis("off")
    m = data["machine"]
    fig.suptitle(f"Work-precision, rodphase; {m['cpu']}, {m['nproc']} cores, one process", fontsize=9)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=130)
    print(f"wrote {path}")




def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", default="stretch,cantilever,greenhill,writhe")
    parser.add_argument("--quick", action="store_true", help="fewer n, no writhe reference run")
    parser.add_argument("--write", type=Path, default=None)
    parser.add_argument("--json", type=Path, default=ROOT / "out" / "perf" / "work_precision.json")
    parser.add_argument("--png", type=Path, default=ROOT / "docs" / "img" / "work_precision.png")
    parser.add_argument("--replot", action="store_true", help="redraw and retabulate from --json")
    args = parser.parse_args()
    only = args.only.split(",")

    if args.replot:
        data = json.loads(args.json.read_text())
    else:
        data = {"machine": machine(), "load_start": load_text(), "problems": {}}
        if args.json.exists():  # keep problems not rerun
            data["problems"] = json.loads(args.json.read_text()).get("problems", {})
        print(f"start: load {data['load_start']}")
        # compile (or load numba's cache) before any timing
        stretch(4, 0.5, tolerance=1e-3)
        if "stretch" in only:
            ns = (10, 40) if args.quick else (10, 20, 40, 80)
            rows = [stretch(n, s) for n in ns for s in SAFETIES]
            rows += [stretch(20, 0.5, tolerance=t) for t in (1e-3, 1e-4, 1e-5)]
            data["problems"]["stretch"] = rows
        if "cantilever" in only:
            ns = (5, 20) if args.quick else (5, 10, 20, 40, 80)
            data["problems"]["cantilever"] = [cantilever(n, s) for n in ns for s in SAFETIES]
        if "greenhill" in only:
            ns = (10, 40) if args.quick else (10, 20, 40, 80)
            data["problems"]["greenhill"] = [greenhill(n, s) for n in ns for s in SAFETIES]
        if "writhe" in only:
            ns = (40,) if args.quick else (40, 60, 80, 100, 140)
            ref = (60, 0.25) if args.quick else (200, 0.25)
            for kind in WRITHE_SCENES:
                data["problems"][kind] = writhe_family(kind, ns, *ref)
        data["load_end"] = load_text()
        print(f"end: load {data['load_end']}")
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(data, indent=1))
    text = tables(data)
    print(text)
    plot(data, args.png)
    if args.write:
        m = data["machine"]
        note = (f"{m['cpu']}, {m['nproc']} cores, one process; load (1/5/15 min) per row; "
                f"load at start {data.get('load_start')}, at end {data.get('load_end')}.")
        write_block(args.write, "work_precision", text + "\n" + note)


if __name__ == "__main__":
    main()
