#!/usr/bin/env python
"""Phase-diagram timing: the paper's Fig 3 sweep (200 random points) on this machine, its phase
labels against a finer reference sweep, and the saving of each "model no more than a scene
needs" switch.

    python benchmarks/phase_timing.py savings            # per-scene savings (one process)
    python benchmarks/phase_timing.py reference [--samples 40]   # fine sweep, --jobs 2
    python benchmarks/phase_timing.py timing             # configs/fig3_paper.yaml, --jobs 2
    python benchmarks/phase_timing.py compare [--write docs/history/performance.md]

`--config configs/fig3_phase.yaml` times the DESIGN's rest-Φa box instead of the paper's
axes (give it to reference, timing and compare alike).
`timing` runs `rodphase sweep configs/fig3_paper.yaml -o out/perf/fig3.h5 --jobs 2` as a user
would (a fresh store each time unless --resume), stops it after --limit minutes (rerunning
the same command with --resume finishes it: the store resumes), then `rodphase classify`.
`reference` runs the same sweep with rod.elements = 140 and solver.safety = 0.25 (and
sweep.samples = --samples: the random sampler with the same seed draws the same first points,
checked in `compare`). `compare` tabulates wall time, runs/min, failures, phase counts and the
label agreement on the common points, and draws both maps side by side.

Every step notes the load average (uptime) before and after: the machine has 2 cores shared
with other users, and the sweeps use both.
"""

from __future__ import annotations

import os

for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse
import json
import signal
import subprocess
import sys
import time
from pathlib import Path

from rodphase.studytools import machine, write_block

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "out" / "perf"
RODPHASE = str(Path(sys.executable).with_name("rodphase"))
CONFIG = ROOT / "configs" / "fig3_paper.yaml"  # --config replaces it
REFERENCE_SET = ["rod.elements=140", "solver.safety=0.25", "loading.quasi_static_below=0"]


def load_text() -> str:
    return "{:.2f} {:.2f} {:.2f}".format(*os.getloadavg())




def other_processes() -> list[str]:
    """Busy processes that are not ours: the contention a timing ran under."""
    out = subprocess.run(["ps", "-eo", "pid,ppid,pcpu,etime,comm", "--sort=-pcpu"],
                         capture_output=True, text=True, check=False).stdout.splitlines()[1:]
    mine = {os.getpid()}
    busy = []
    for line in out:
        parts = line.split(None, 4)
        if len(parts) == 5 and float(parts[2]) > 20 and int(parts[0]) not in mine \
                and int(parts[1]) not in mine:
            busy.append(line.strip())
    return busy[:5]


def _state_path(name: str) -> Path:
    return OUT / f"{name}.json"


def _save(name: str, data: dict) -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    path = _state_path(name)
    old = json.loads(path.read_text()) if path.exists() else {}
    old.update(data)
    path.write_text(json.dumps(old, indent=1))


def run_sweep(name: str, store: Path, sets: list[str], limit_min: float, resume: bool) -> dict:
    OUT.mkdir(parents=True, exist_ok=True)
    if store.exists() and not resume:
        store.unlink()
    cmd = [RODPHASE, "sweep", str(CONFIG), "-o", str(store), "--jobs", "2", "--quiet"]
    for s in sets:
        cmd += ["--set", s]
    info = {"command": " ".join(cmd[0:1] + ["sweep"] + cmd[2:]), "load_before": load_text(),
            "others_before": other_processes()}
    print(f"[{name}] {info['command']}\n  load before {info['load_before']}; busy: "
          f"{info['others_before']}", flush=True)
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True, start_new_session=True)
    loads = []
    stopped = False
    last_sample = t0
    while proc.poll() is None:
        time.sleep(0.2)
        if time.perf_counter() - last_sample >= 10:
            loads.append(os.getloadavg()[0])
            last_sample = time.perf_counter()
        if time.perf_counter() - t0 > 60 * limit_min:
            os.killpg(proc.pid, signal.SIGINT)  # our own sweep's process group, nothing else
            try:
                proc.wait(60)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
            stopped = True
    wall = time.perf_counter() - t0
    output = proc.stdout.read()
    (OUT / f"{name}.log").write_text(output)
    summary = [line for line in output.splitlines() if "written to" in line]
    info.update(wall=wall, summary=summary[-1] if summary else "", returncode=proc.returncode, stopped_at_limit=stopped,
                output=output[-4000:], load_after=load_text(), others_after=other_processes(),
                load_1min_mean_during=sum(loads) / len(loads) if loads else None)
    print(output[-1500:])
    print(f"[{name}] wall {wall:.1f} s, exit {proc.returncode}, stopped {stopped}, load after "
          f"{info['load_after']}", flush=True)
    csv = store.with_suffix(".csv")
    cls = subprocess.run([RODPHASE, "classify", str(store), "--csv", str(csv)], cwd=ROOT,
                         capture_output=True, text=True, check=False)
    print(cls.stdout, cls.stderr)
    info["classify"] = cls.stdout.strip()
    info["csv"] = str(csv.relative_to(ROOT))
    return info


# ---------------------------------------------------------------- savings

def savings() -> dict:
    """Per-scene savings of the "model no more than a scene needs" switches, one process."""
    from rodphase import config as C
    from rodphase.rod import simulate
    from rodphase.scenes import SCENES, build

    def run(point, extra=()):
        over = [("rod.elements", 80), ("loading.force_multiple", None),
                ("loading.extension", point[1]), ("loading.twist_density", point[0]),
                ("output.topology", False)] + list(extra)
        problem = build(C.load_scene("twist_under_load", over, SCENES))
        t0 = time.process_time()
        result = simulate(problem)
        cpu = time.process_time() - t0
        d = result.diagnostics
        return {"status": result.status, "cpu": cpu, "steps": d["steps"], "dt": _steps_taken(d),
                "us_per_step": 1e6 * cpu / d["steps"], "max_pairs": d["max_pairs"],
                "contacts_end": float(result.history["contacts"][-1]),
                "stages": [{k: s[k] for k in ("label", "steps", "equilibrium")} for s in d["stages"]],
                "load": load_text()}

    run((0.2, 1.1))  # compile / load the cache
    out = {"machine": machine()}
    straight = (0.5, 1.2)  # Φa, L/L0: stays straight, never touches itself
    out["contact_straight"] = {"on": run(straight), "off": run(straight, [("physics.self_contact", False)])}
    # before the rod touches itself: the load stage and the twist up to the first contact are
    # the same problem with contact on or off; compare per step and the dt each gets
    plect = (1.2, 1.03)
    out["friction_plectoneme"] = {"off": run(plect), "on": run(plect, [("physics.friction", 0.3)])}
    out["friction_same_state"] = friction_cost(plect)
    out["hold_straight"] = {"equilibrium": run(straight),
                            "time": run(straight, [("solver.hold_until", "time")])}
    out["hold_plectoneme"] = {"equilibrium": out["friction_plectoneme"]["off"],
                              "time": run(plect, [("solver.hold_until", "time")])}
    out["safety_plectoneme"] = {"0.5": out["friction_plectoneme"]["off"],
                                "0.35": run(plect, [("solver.safety", 0.35)]),
                                "0.25": run(plect, [("solver.safety", 0.25)])}
    for key, value in out.items():
        if key != "machine":
            for variant, r in value.items():
                print(f"{key:22s} {variant:12s} {r['status']:13s} cpu {r['cpu']:6.2f} s steps "
                      f"{r['steps']:7d} dt {r['dt']} {r['us_per_step']:6.2f} us/step stages "
                      + ", ".join(f"{s['label']}:{s['steps']}{'(eq)' if s['equilibrium'] else ''}"
                                  for s in r["stages"]) + f" (load {r['load']})", flush=True)
    return out


def friction_cost(point, seconds=1.0) -> dict:
    """µs/step with friction 0 and 0.3 from the same plectoneme (the friction_plectoneme run
    ends in different shapes, so its cost is not comparable): the frictionless run's final
    shape, restarted at rest for `seconds` with each friction."""
    from dataclasses import replace

    from rodphase import config as C
    from rodphase.rod import Stage, simulate, state_from
    from rodphase.scenes import SCENES, build

    over = [("rod.elements", 80), ("loading.force_multiple", None), ("loading.extension", point[1]),
            ("loading.twist_density", point[0]), ("output.topology", False), ("solver.safety", 0.35)]
    problem = build(C.load_scene("twist_under_load", over, SCENES))
    shape = simulate(problem)
    state = state_from(shape.positions, shape.directors)
    last = problem.stages[-1]
    out = {}
    for friction in (0.0, 0.3):
        # end rotation 0: the restart's clamp frames are taken from the twisted shape itself
        controls = replace(last.controls, end_rotation=((0.0,), (0.0,)))
        q = replace(problem, state=state, contact=replace(problem.contact, friction=friction),
                    stages=(Stage(seconds, controls=controls),))
        t0 = time.process_time()
        r = simulate(q)
        cpu = time.process_time() - t0
        d = r.diagnostics
        out[f"friction {friction:g}"] = {
            "status": r.status, "cpu": cpu, "steps": d["steps"], "dt": _steps_taken(d),
            "us_per_step": 1e6 * cpu / d["steps"], "max_pairs": d["max_pairs"],
            "contacts_end": float(r.history["contacts"][-1]) if len(r.history["time"]) else None,
            "message": r.message[:200],
            "stages": [{k: st[k] for k in ("label", "steps", "equilibrium")} for st in d["stages"]],
            "load": load_text()}
    return out


def _steps_taken(d: dict) -> str:
    """The step(s) a run took: with sleeping contact the one before the first touch, then (→)
    the one after it if contact woke."""
    if d.get("dt_asleep") is None:
        return f"{d['dt']:.3g}"
    if d.get("contact_woke_at") is None:
        return f"{d['dt_asleep']:.3g} (contact asleep)"
    return f"{d['dt_asleep']:.3g} → {d['dt']:.3g}"


def savings_table(data: dict) -> str:
    what = {
        "contact_straight": "self-contact on vs off, a run that never touches itself (Φa 0.5, L/L0 1.2)",
        "friction_plectoneme": "friction 0 vs 0.3, whole run (Φa 1.2, L/L0 1.03)",
        "friction_same_state": "friction 0 vs 0.3, 1 s restarted from the same plectoneme (safety 0.35)",
        "hold_straight": "hold until equilibrium vs fixed 20 s (Φa 0.5, L/L0 1.2)",
        "hold_plectoneme": "hold until equilibrium vs fixed 20 s (Φa 1.2, L/L0 1.03)",
        "safety_plectoneme": "safety 0.5 / 0.35 / 0.25 (Φa 1.2, L/L0 1.03)",
    }
    rows = [("| switch (twist_under_load, n = 80) | variant | status | CPU [s] | steps | dt [s] | "
            "µs/step | steps per stage | most pairs listed | load |"),
            "|---|---|---|---|---|---|---|---|---|---|"]
    for key, label in what.items():
        for variant, r in data.get(key, {}).items():
            stages = ", ".join(f"{s['label']} {s['steps']}{' (eq)' if s['equilibrium'] else ''}"
                               for s in r["stages"])
            rows.append(f"| {label} | {variant} | {r['status']} | {r['cpu']:.2f} | {r['steps']} | "
                        f"{r['dt']} | {r['us_per_step']:.1f} | {stages} | {r['max_pairs']} | "
                        f"{r['load']} |")
    return "\n".join(rows)


# ---------------------------------------------------------------- compare

def compare(write: list[Path]) -> str:
    import numpy as np
    import pandas as pd

    state = json.loads(_state_path("phase_timing").read_text())
    fast = pd.read_csv(ROOT / state["timing"]["csv"])
    ref = pd.read_csv(ROOT / state["reference"]["csv"])
    common = fast.merge(ref, on="run_id", suffixes=("", "_ref"))
    axes = twist_axis(fast), "extension"
    same_point = all(np.allclose(common[a], common[f"{a}_ref"]) for a in axes)
    if not same_point:
        raise SystemExit("the reference points are not the timing sweep's points")
    agree = (common["phase"] == common["phase_ref"])
    both_ok = common[(common["phase"] != "failed") & (common["phase_ref"] != "failed")]
    agree_ok = (both_ok["phase"] == both_ok["phase_ref"])
    lines = []
    for name in ("timing", "reference"):
        s = state[name]
        table = fast if name == "timing" else ref
        n = len(table)
        counts = table["phase"].value_counts().to_dict()
        status = table["status"].value_counts().to_dict()
        command = s["command"].split("sweep ", 1)[1].replace(str(ROOT) + "/", "")
        lines.append(f"| {name} | `rodphase sweep {command}` | {n} | {s['wall']:.0f} "
                     f"({s['wall'] / 60:.1f} min{', stopped at limit' if s['stopped_at_limit'] else ''}) | "
                     f"{60 * n / s['wall']:.1f} | "
                     + ", ".join(f"{k} {v}" for k, v in sorted(status.items())) + " | "
                     + ", ".join(f"{k} {v}" for k, v in sorted(counts.items())) + " | "
                     f"{s['load_before']} → {s['load_after']} (mean 1-min load during "
                     f"{s['load_1min_mean_during']:.2f}) |")
        if s.get("summary"):
            lines[-1] += f" {s['summary'].split(';')[0]} |"
        else:
            lines[-1] += " |"
    head = ("| sweep | command | runs | wall [s] | runs/min | status | phases | load before → after | "
            "rodphase's own report |\n|---|---|---|---|---|---|---|---|---|")
    confusion = pd.crosstab(common["phase"], common["phase_ref"], rownames=["timing"],
                            colnames=["reference"])
    text = (head + "\n" + "\n".join(lines) + "\n\n"
            f"Agreement on the {len(common)} common points: {agree.mean():.1%} "
            f"({int(agree.sum())}/{len(common)}); where neither run failed: "
            f"{agree_ok.mean():.1%} ({int(agree_ok.sum())}/{len(both_ok)}).\n\n"
            "Labels, timing sweep (rows) against the reference (columns):\n\n"
            + markdown(confusion) + "\n")
    print(text)
    plot_maps(fast, ref, state)
    if write:
        m = machine()
        busy = state["timing"].get("others_before") or []
        note = (f"{m['cpu']}, {m['nproc']} cores. Busy processes not ours at the start of the "
                f"timing: {len(busy)}" + (f" ({'; '.join(busy)})" if busy else "") + ".")
        for doc in write:
            write_block(doc, "phase_timing", text + "\n" + note)
    return text


def twist_axis(table) -> str:
    return "twist_density_current" if "twist_density_current" in table.columns else "twist_density"


def markdown(frame) -> str:
    cols = [str(c) for c in frame.columns]
    rows = [f"| {frame.index.name} \\ {frame.columns.name} | " + " | ".join(cols) + " |",
            "|---|" + "---|" * len(cols)]
    for idx, row in frame.iterrows():
        rows.append(f"| {idx} | " + " | ".join(str(v) for v in row.values) + " |")
    return "\n".join(rows)


def plot_maps(fast, ref, state) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    colours = {"straight": "tab:gray", "plectoneme": "tab:blue", "solenoid": "tab:red",
               "mixed": "tab:purple", "failed": "black"}
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.2), sharex=True, sharey=True)
    for ax, table, name in ((axes[0], fast, "timing"), (axes[1], ref, "reference")):
        for phase, grp in table.groupby("phase"):
            ax.scatter(grp[twist_axis(table)], grp["extension"], s=18, c=colours.get(phase, "k"),
                       marker="x" if phase == "failed" else "o", label=f"{phase} ({len(grp)})")
        crept = table[table["status"] == "not_converged"]
        ax.scatter(crept[twist_axis(table)], crept["extension"], s=55, facecolors="none",
                   edgecolors="k", lw=0.7, label=f"hold not converged ({len(crept)})")
        s = state[name]
        what = (f"{CONFIG.relative_to(ROOT)}: n = 80, safety 0.5" if name == "timing" else
                "same, n = 140, safety 0.25, first 40 points")
        ax.set_title(f"{name}: {what}\n{len(table)} runs, {s['wall'] / 60:.1f} min wall "
                     f"on 2 cores (--jobs 2)", fontsize=8)
        ax.set_xlabel("Φa (stretched rod)" if twist_axis(table).endswith("current") else "Φa (rest)")
        ax.legend(fontsize=7)
    axes[0].set_ylabel("L/L0")
    fig.tight_layout()
    path = ROOT / "docs" / "img" / "phase_timing.png"
    fig.savefig(path, dpi=130)
    print(f"wrote {path}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("step", choices=["savings", "reference", "timing", "compare"])
    parser.add_argument("--samples", type=int, default=40, help="reference: points (first of the 200)")
    parser.add_argument("--limit", type=float, default=25.0, help="minutes before a sweep is stopped")
    parser.add_argument("--resume", action="store_true", help="keep an existing store (resume)")
    parser.add_argument("--write", type=Path, action="append", default=[],
                        help="Markdown file to update (repeatable)")
    parser.add_argument("--config", type=Path, default=None,
                        help="the sweep to time (default configs/fig3_paper.yaml)")
    args = parser.parse_args()
    if args.config is not None:
        global CONFIG
        CONFIG = args.config.resolve()
    if args.step == "savings":
        if not args.resume:  # --resume: retabulate the stored measurements
            _save("savings", savings())
        text = savings_table(json.loads(_state_path("savings").read_text()))
        print(text)
        for doc in args.write:
            write_block(doc, "savings", text)
    elif args.step == "reference":
        info = run_sweep("reference", OUT / "fig3_ref.h5",
                         REFERENCE_SET + [f"sweep.samples={args.samples}"], args.limit, args.resume)
        _save("phase_timing", {"reference": info, "machine": machine()})
    elif args.step == "timing":
        info = run_sweep("timing", OUT / "fig3.h5", [], args.limit, args.resume)
        _save("phase_timing", {"timing": info, "machine": machine()})
    else:
        compare(args.write)


if __name__ == "__main__":
    main()
