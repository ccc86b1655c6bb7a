#!/usr/bin/env python
"""Stability map: the largest time step explicit stepping survives, against the automatic bound.

    python studies/stability_map.py [--steps 4000] [--write docs/history/performance.md] [--quick]

For every (n, E, damping) the largest stable dt is found by bisection on f = dt / bound, where
bound = rodphase.rod.stable_time_step (rodphase steps at dt = safety × bound, safety 0.5 by
default). "Stable" means the engine's own guard did not stop the run: status "ok" after
--steps steps. A run whose dt is too large is stopped by the guard (non-finite state or a node
faster than the axial wave speed, checked every 50 steps) with status "unstable".

The rod is the paper's (L0 = 1 m, a = 25 mm, ρ = 1000 kg/m³, G = 2E/3), clamped at node 0 and
free at node n, started from a slightly perturbed straight state: node positions moved by
1e-3 of an element length, frames turned by 1e-3 rad, both random, seeded. The paper's
incompressible law is not hyperelastic, so with no damping large strains could grow for
physical reasons; at strains of ~1e-3 only the numerical instability can grow. Contact is off:
a straight rod has no contacts, and the bound is then the elastic one (with contact on, the
bound adds the pair springs and is smaller). A second family (--contact) starts from a
hairpin whose arms already overlap by 1 % of the diameter, so the contact springs are engaged
from the first step, with contact on in both the bound and the run.

Damping: "none" is damping 0, rotational damping 0, quadratic drag 0; "default" is the scene
defaults (20 /s, rotational auto = 40·√(G/ρ)/L0, quadratic drag 1000 /m); "linear" is the
default without the quadratic drag (the Solver dataclass's own default).

Two limits are measured, each by bisection on f = dt/bound to 0.5 %: the largest f that is
actually stable (status not "unstable" and no growing or sustained oscillation, see `trial`),
and the largest f the guard lets through (status not "unstable"). Where they differ, an
unstable dt would be stored as a result or end as not_converged instead of being caught.
A third family runs Fig 2a's scene (25 F_C, twisted to Φa = 1.0, held) at dt = f × bound and
asks whether the hold reaches equilibrium within 5 s: dense self-contact (40-100 touching
pairs), the case that matters for the phase diagram.

Writes docs/img/stability_map.png and out/perf/stability_map.json; prints a Markdown table.
"""

from __future__ import annotations

import os

for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse
import json
import math
import time
import warnings
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from rodphase.rod import (
    Contact,
    Ends,
    Problem,
    Rod,
    Solver,
    Stage,
    hairpin_state,
    simulate,
    stable_time_step,
    straight_state,
)
from rodphase.studytools import machine, write_block
from rodphase.units import paper_shear_modulus

ROOT = Path(__file__).resolve().parents[1]




def load_text() -> str:
    return "load {:.2f} {:.2f} {:.2f}".format(*os.getloadavg())


def rod_for(n: int, E: float) -> Rod:
    return Rod(length=1.0, radius=0.025, elements=n, density=1000.0, youngs_modulus=E,
               shear_modulus=paper_shear_modulus(E))


DAMPING = {
    "none": {"damping": 0.0, "rotational_damping": 0.0, "quadratic_drag": 0.0},
    "default": {"damping": 20.0, "rotational_damping": None, "quadratic_drag": 1000.0},
    "linear": {"damping": 20.0, "rotational_damping": None, "quadratic_drag": 0.0},
}


def perturbed_straight(rod: Rod, seed: int = 0, strain: float = 1e-3):
    rng = np.random.default_rng(seed)
    state = straight_state(rod)
    state.x[:, 1:] += strain * rod.element_length * rng.standard_normal((3, rod.elements))
    for i in range(rod.elements):
        turn = Rotation.from_rotvec(strain * rng.standard_normal(3)).as_matrix()
        state.Q[:, :, i] = turn @ state.Q[:, :, i]
    return state


def hairpin(rod: Rod, overlap: float = 0.01):
    """A hairpin whose straight arms overlap by `overlap` of the diameter, stress-free; both
    ends are clamped (see HAIRPIN_ENDS), so the contact springs stay engaged to equilibrium."""
    from rodphase.scenes import measured_curvature

    n, a = rod.elements, rod.radius
    state = hairpin_state(rod, a * (1.0 - overlap))
    kappa = measured_curvature(state.directors, np.full(n, rod.length / n))
    return state, kappa


HAIRPIN_ENDS = Ends(start_held=(True,) * 3, start_frame_held=True, end_held=(True,) * 3,
                    end_frame_held=True)
SETTLE_TIME = 0.5  # s: damped runs last at least this long, so a stable one visibly settles


PLECTONEME_HOLD = 5.0  # s: the hold's max time in the plectoneme trials (a stable one needs ~1 s)


def plectoneme_problem(n: int, factor: float):
    """Fig 2a's scene (25 F_C, twisted to Φa = 1.0 at 0.2 turns/s, held until equilibrium) at
    dt = factor × bound."""
    from rodphase import config as C
    from rodphase.scenes import SCENES, build

    cfg = C.load_scene("fig2a_plectoneme", [("rod.elements", n), ("loading.twist_density", 1.0),
                                            ("solver.dt", None), ("solver.safety", min(factor, 1.0)),
                                            ("solver.hold_max_time", PLECTONEME_HOLD)], SCENES)
    problem = build(cfg)
    if factor > 1.0:  # the config caps safety at 1; beyond, set dt itself
        from dataclasses import replace

        problem.solver = replace(problem.solver, dt=factor * stable_time_step(problem.rod, problem.contact))
    return problem


def trial(rod: Rod, factor: float, damping: str, steps: int, family: str, seed: int = 0):
    """One run at dt = factor × bound. Returns a dict: status, steps taken, message, bound,
    cpu seconds, and `quiet`: whether the run is free of a growing or sustained oscillation.

    straight and hairpin: damped runs are quiet if the kinetic energy at the end is below 1 %
    of its largest value; undamped ones if the largest total energy over the last quarter of
    the run is below 3x that over the first. plectoneme: quiet if the hold reaches equilibrium
    (the scene's test, tolerance 1e-3) within PLECTONEME_HOLD seconds."""
    damped = damping != "none"
    rows = 80
    if family == "plectoneme":
        if damping != "default":
            raise ValueError("the plectoneme family runs with the scene's own damping")
        problem = plectoneme_problem(rod.elements, factor)
        bound = stable_time_step(problem.rod, problem.contact)
        n_steps = None
    else:
        contact = family == "hairpin"
        c = Contact(enabled=contact)
        bound = stable_time_step(rod, c)
        dt = factor * bound
        if contact:
            (state, kappa), ends = hairpin(rod), HAIRPIN_ENDS
        else:
            (state, kappa), ends = (perturbed_straight(rod, seed), None), Ends()
        duration = max(steps * dt, SETTLE_TIME) if damped else steps * dt
        n_steps = math.ceil(duration / dt - 1e-9)
        problem = Problem(rod=rod, state=state, ends=ends, contact=c, rest_curvature=kappa,
                          solver=Solver(dt=dt, history_interval=n_steps * dt / rows,
                                        **DAMPING[damping]),
                          stages=(Stage(n_steps * dt * (1 - 1e-12)),))
    t0 = time.process_time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # dt above the bound warns, on purpose here
        result = simulate(problem)
    cpu = time.process_time() - t0
    h = result.history
    quiet = False
    if family == "plectoneme":
        quiet = result.status == "ok"  # the hold reached equilibrium (else not_converged)
        n_steps = int(result.diagnostics["steps"])
    elif result.status == "ok" and len(h["time"]) >= 8:
        kinetic = h["kinetic_energy"]
        total = h["stretch_energy"] + h["bend_energy"] + kinetic + h["contact_energy"]
        q = max(len(total) // 4, 1)
        if damped:
            quiet = bool(kinetic[-1] <= 0.01 * kinetic.max())
        else:
            quiet = bool(total[-q:].max() <= 3.0 * total[:q].max())
    return {"factor": factor, "status": result.status, "steps": int(result.diagnostics["steps"]),
            "planned": n_steps, "quiet": quiet, "message": result.message, "bound": bound,
            "cpu": cpu}


def bisect(test, rel: float = 0.005, cap: float = 64.0):
    """Largest f with test(f) true, by doubling/halving from 1 then bisection to relative
    width `rel`. Returns (f_pass, f_fail); f_fail is None if test passes up to `cap`."""
    lo, hi = None, None
    f = 1.0
    while lo is None or hi is None:
        if test(f):
            lo = f
            if hi is None:
                if f >= cap:
                    return lo, None
                f *= 2.0
        else:
            hi = f
            if lo is None:
                f *= 0.5
                if f < 1.0 / 16:
                    return None, hi
    while (hi - lo) / lo > rel:
        mid = 0.5 * (lo + hi)
        if test(mid):
            lo = mid
        else:
            hi = mid
    return lo, hi


def largest_stable(rod: Rod, damping: str, steps: int, family: str):
    """Two limits: the largest dt/bound the guard lets through (status ok), and the largest
    that is actually stable (status ok and quiet)."""
    runs = []

    def run_one(f):
        out = trial(rod, f, damping, steps, family)
        runs.append(out)
        if out["status"] not in ("ok", "unstable", "not_converged"):
            raise RuntimeError(f"unexpected status {out['status']}: {out['message']}")
        return out

    def stable_at(f):
        out = run_one(f)
        return out["status"] != "unstable" and out["quiet"]

    stable = bisect(stable_at)
    guard = bisect(lambda f: run_one(f)["status"] != "unstable")
    return stable, guard, runs


def run(args) -> dict:
    cases = []
    ns = [20, 50] if args.quick else [20, 50, 100, 200]
    Es = [1e6] if args.quick else [1e5, 1e6, 1e7]
    plan = [("straight", n, E, d) for n in ns for E in Es for d in ("none", "default")]
    # the default damping without its quadratic drag: is the drag what hides a bad dt?
    plan += [("straight", n, 1e6, "linear") for n in ns]
    if args.contact:
        plan += [("hairpin", n, 1e6, d) for n in ([50] if args.quick else [50, 100, 200])
                 for d in ("none", "default")]
        # the scene as the phase diagram runs it, with its own damping only
        plan += [("plectoneme", n, 1e6, "default") for n in ([50] if args.quick else [50, 100])]
    # compile once outside the timings
    trial(rod_for(10, 1e6), 0.5, "none", 100, "straight")
    trial(rod_for(10, 1e6), 0.5, "none", 100, "hairpin")
    for family, n, E, damping in plan:
        rod = rod_for(n, E)
        bound = stable_time_step(rod, Contact(enabled=family != "straight"))
        load = load_text()
        t0 = time.process_time()
        (lo, hi), (glo, ghi), runs = largest_stable(rod, damping, args.steps, family)
        lo = lo or 0.0  # None: not stable even at 1/16 of the bound
        glo = glo or 0.0
        cpu = time.process_time() - t0
        case = {"family": family, "contact": family != "straight", "n": n, "E": E,
                "damping": damping, "bound": bound, "f_stable": lo, "f_unstable": hi,
                "dt_max": lo * bound, "f_guard": glo, "f_guard_fails": ghi,
                "margin_vs_auto": lo / 0.5, "trials": len(runs), "cpu": cpu, "load": load,
                "runs": runs}
        cases.append(case)
        guard = f"{glo:.3f}..{ghi:.3f}" if ghi else f"never caught up to {glo:g}"
        print(f"{family:10s} n={n:4d} E={E:8.1e} damping={damping:7s} bound={bound:.3e} s "
              f"stable f<={lo:.3f} (fails {hi:.3f}); guard passes f<={guard}; margin over "
              f"auto dt {lo / 0.5:.2f}x ({len(runs)} runs, {cpu:.1f} s cpu, {load})", flush=True)
    return {"machine": machine(), "steps": args.steps, "cases": cases}


def table(data: dict) -> str:
    rows = [("| rod | n | E [Pa] | damping | bound [s] | largest stable dt / bound | "
            "margin over auto dt (0.5·bound) | guard stops runs from dt / bound | trials | CPU [s] |"),
            "|---|---|---|---|---|---|---|---|---|---|"]
    for c in data["cases"]:
        guard = (f"{c['f_guard_fails']:.3f}" if c["f_guard_fails"]
                 else f"never (ok up to {c['f_guard']:g})")
        rows.append(f"| {c['family']} | {c['n']} | {c['E']:.0e} | "
                    f"{c['damping']} | {c['bound']:.3g} | {c['f_stable']:.3f} | "
                    f"{c['margin_vs_auto']:.2f}× | {guard} | {c['trials']} | {c['cpu']:.1f} |")
    return "\n".join(rows)


def plot(data: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11.5, 4.6))
    colours = {1e5: "tab:blue", 1e6: "tab:green", 1e7: "tab:red"}
    ax = axes[0]
    plain = [c for c in data["cases"] if not c["contact"]]
    for E in sorted({c["E"] for c in plain}):
        sel = sorted((c for c in plain if c["E"] == E and c["damping"] == "none"), key=lambda c: c["n"])
        ns = np.array([c["n"] for c in sel])
        bound = np.array([c["bound"] for c in sel])
        ax.plot(ns, bound, "-", color=colours[E], lw=1, label=f"bound, E = {E:.0e} Pa")
        ax.plot(ns, 0.5 * bound, ":", color=colours[E], lw=1.8)
        for damping, marker in (("none", "o"), ("default", "x")):
            sel = sorted((c for c in plain if c["E"] == E and c["damping"] == damping),
                         key=lambda c: c["n"])
            ax.plot([c["n"] for c in sel], [c["dt_max"] for c in sel], marker, color=colours[E],
                    ms=6, mfc="none" if marker == "o" else None,
                    label=f"largest stable dt, damping {damping}" if E == 1e6 else None)
    ax.plot([], [], ":", color="k", label="automatic dt = 0.5 x bound")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("elements n")
    ax.set_ylabel("dt [s]")
    ax.set_title("Largest stable dt, straight rod, contact off", fontsize=10)
    # below the axes: inside, every corner of this plot holds data
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.16), ncols=2,
              frameon=False)
    ax = axes[1]
    for c in data["cases"]:
        marker = {"straight": {"none": "o", "default": "x", "linear": "+"}[c["damping"]], "hairpin": "s",
                  "plectoneme": "*"}[c["family"]]
        colour = {"straight": colours[c["E"]], "hairpin": "k", "plectoneme": "tab:purple"}[c["family"]]
        shift = {1e5: 0.94, 1e6: 1.0, 1e7: 1.06}[c["E"]] * {"none": 0.97, "default": 1.0, "linear": 1.03}[c["damping"]]
        ax.plot(c["n"] * shift, c["f_stable"], marker, color=colour,
                mfc="none" if c["damping"] == "none" else colour, ms=9 if marker == "*" else 6)
        guard = c["f_guard_fails"]
        if guard is None or guard > c["f_stable"] * 1.05:
            top = min(guard or 4.0, 4.0)
            ax.annotate("", xy=(c["n"] * shift, top), xytext=(c["n"] * shift, c["f_stable"]),
                        arrowprops={"arrowstyle": "->", "color": colour, "lw": 0.8, "ls": "--"})
    ax.axhline(1.0, color="0.3", lw=1)
    ax.axhline(0.5, color="0.3", lw=1.8, ls=":")
    ax.axhspan(0.0, 0.5, color="tab:green", alpha=0.08)
    ax.text(17, 0.53, "automatic dt = 0.5 x bound", fontsize=8)
    ax.text(17, 1.03, "bound (stable_time_step)", fontsize=8)
    ax.set_xscale("log")
    ax.set_ylim(0, 4.1)
    ax.set_xlabel("elements n")
    ax.set_ylabel("largest stable dt / bound")
    ax.set_title("o/x: straight rod, undamped/default damping; +: linear drag only;\n"
                 "open/filled square: hairpin in contact; *: plectoneme in contact;\n"
                 "dashed arrow: up to the dt the guard still lets through (4 shown)", fontsize=8)
    m = data["machine"]
    fig.suptitle(f"Stability map ({data['steps']} steps per trial, damped trials >= {SETTLE_TIME} s); "
                 f"{m['cpu']}, {m['nproc']} cores", fontsize=9)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=130)
    print(f"wrote {path}")




def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=4000)
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--no-contact", dest="contact", action="store_false")
    parser.add_argument("--write", type=Path, default=None, help="Markdown file to update")
    parser.add_argument("--replot", action="store_true", help="redraw and retabulate from --json")
    parser.add_argument("--json", type=Path, default=ROOT / "out" / "perf" / "stability_map.json")
    parser.add_argument("--png", type=Path, default=ROOT / "docs" / "img" / "stability_map.png")
    args = parser.parse_args(argv)
    if args.replot:
        data = json.loads(args.json.read_text())
    else:
        start = load_text()
        print(f"start: {start}")
        data = run(args)
        data["load_start"] = start
        data["load_end"] = load_text()
        print(f"end: {data['load_end']}")
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(data, indent=1))
    text = table(data)
    print(text)
    plot(data, args.png)
    if args.write:
        m = data["machine"]
        note = (f"{m['cpu']}, {m['nproc']} cores; one process; {data['steps']} steps per trial; "
                f"{data.get('load_start', '')} at the start, {data['load_end']} at the end.")
        write_block(args.write, "stability_map", text + "\n\n" + note)


if __name__ == "__main__":
    main()
