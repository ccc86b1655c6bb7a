"""Holds that settle (issue #13): the shipped defaults against the implicit damping settings.

    python studies/damping_sweeps.py speed   [--steps 4000 --rounds 5]
    python studies/damping_sweeps.py demo    [--out DIR]
    python studies/damping_sweeps.py figures [--out DIR] [--only figS9,fig4a]
    python studies/damping_sweeps.py fig3    [--out DIR] [--samples 40]

Each command runs the same work with every variant of VARIANTS (the `--set` overrides that
turn the new terms on) and prints one line per variant; `--variants` picks some. `--set
KEY=VALUE` changes every scene or sweep of every variant alike (a smoke test makes them coarse).
`speed` is the kernel's CPU time per step on a solenoid in contact, variants interleaved in
one process round by round (min and median of the rounds), so that a change of load on a
shared machine hits them alike. `demo` counts the statuses of configs/quick.yaml's 24 runs.
`figures` runs studies/figures.py for each variant into DIR/<variant>/ and reads back the
numbers docs/history/reproduction.md quotes (every run's status, Fig S9's last hold, Fig 4a's force
noise, Fig 2b's writhe per solenoid turn). `fig3` times the first --samples points of
configs/fig3_paper.yaml per variant, interleaved in chunks, and counts their phases.
--jobs 1 throughout: on a shared machine one process per variant keeps the timings fair.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
VARIANTS: dict[str, list[tuple[str, object]]] = {
    "default": [],
    "strain": [("solver.strain_rate_damping", 1e-3)],
    "implicit": [("contact.dashpot", "implicit")],
    "both": [("contact.dashpot", "implicit"), ("solver.strain_rate_damping", 1e-3)],
    # the earlier design's: the implicit dashpot at twice the default ratio
    "both_z1": [("contact.dashpot", "implicit"), ("contact.damping_ratio", 1.0),
                ("solver.strain_rate_damping", 1e-3)],
}


def machine() -> str:
    model = ""
    try:
        for line in subprocess.run(["lscpu"], capture_output=True, text=True).stdout.splitlines():
            if line.startswith("Model name"):
                model = line.split(":", 1)[1].strip()
    except OSError:
        model = platform.processor()
    load = os.getloadavg()
    return f"{model}, {os.cpu_count()} CPUs, load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}"


def speed(variants, steps: int, rounds: int, extra=()) -> None:
    """µs/step (CPU time) of the kernel on the Fig 2b solenoid's hold, interleaved."""
    from rodphase import config as C
    from rodphase.rod import simulate
    from rodphase.rod.model import Stage, state_from
    from rodphase.scenes import SCENES
    from rodphase.scenes import build as build_problem

    # a solenoid in contact to start from: the coarse Fig 2b scene run to the end of its twist
    base = [("rod.elements", 100), ("loading.twist_density", 1.55), ("loading.twist_rate", 1.0),
            ("solver.hold_max_time", 0.5), *extra]
    cfg = C.load_scene("fig2b_solenoid", base, SCENES)
    start = simulate(build_problem(cfg))
    print(f"start state: {start.status}, {int(start.history['contacts'][-1])} touching pairs",
          flush=True)
    problems = {}
    for name in variants:
        p = build_problem(C.load_scene("fig2b_solenoid", base + VARIANTS[name], SCENES))
        p.state = state_from(start.positions, start.directors)
        problems[name] = p
    times: dict[str, list[float]] = {name: [] for name in variants}
    for name, p in problems.items():  # compile and warm up
        p.stages = (Stage(10 * 1e-5),)
        simulate(p)
    for _ in range(rounds):
        for name, p in problems.items():
            dt = simulate(p).diagnostics["dt"]
            p.stages = (Stage(steps * dt),)
            cpu = time.process_time()
            r = simulate(p)
            cpu = time.process_time() - cpu
            times[name].append(1e6 * cpu / r.diagnostics["steps"])
    print(machine())
    for name in variants:
        t = np.array(times[name])
        p = problems[name]
        print(f"{name:8s} dt {simulate_dt(p):.3g} s  µs/step min {t.min():.2f} median "
              f"{np.median(t):.2f}  (µs per simulated ms: {1e3 * np.median(t) / simulate_dt(p) / 1e6:.1f})")


def simulate_dt(problem) -> float:
    from rodphase.rod import time_step

    return time_step(problem)[0]


def demo(variants, out: Path, extra=()) -> None:
    from rodphase import config as C
    from rodphase.scenes import SCENES
    from rodphase.sweep import run_sweep

    out.mkdir(parents=True, exist_ok=True)
    for name in variants:
        sweep, scene = C.load_sweep(ROOT / "configs/quick.yaml", [*extra, *VARIANTS[name]],
                                    SCENES)
        path = out / f"quick_{name}.h5"
        if path.exists():
            path.unlink()
        report = run_sweep(sweep, scene, str(path), jobs=1, progress=False, echo=lambda s: None)
        statuses = _statuses(path)
        counts = {s: statuses.count(s) for s in sorted(set(statuses))}
        print(f"{name:8s} {len(statuses)} runs: " + ", ".join(f"{v} {k}" for k, v in counts.items())
              + f"; {report.wall:.0f} s of runs", flush=True)


def _statuses(path) -> list[str]:
    from rodphase.store import read_store

    with read_store(path) as store:
        return [store.read_run(rid).status for rid in store.run_ids()]


def figures(variants, out: Path, only: str, extra=()) -> None:
    for name in variants:
        folder = out / name
        cmd = [sys.executable, str(ROOT / "studies/figures.py"), "--out", str(folder), "--jobs", "1"]
        if only:
            cmd += ["--only", only]
        for item in extra:  # as given: figures.py parses them
            cmd += ["--set", item]
        for key, value in VARIANTS[name]:
            cmd += ["--set", f"{key}={value}"]
        start = time.perf_counter()
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
        wall = time.perf_counter() - start
        print(f"{name}: {wall:.0f} s wall", flush=True)
        for path in sorted(folder.glob("*.json")):
            m = json.loads(path.read_text())
            line = f"  {m['figure']:6s} {m.get('status', '-'):14s} {m.get('wall_time_total', 0):5.0f} s"
            if m["figure"] == "fig4a":
                line += f"  force noise {m['force_noise_F_C']:.3f} F_C, drops " + ", ".join(
                    f"{d['peak_F_C'] - d['bottom_F_C']:.2f} F_C @ {d['peak_dU']:.3f} m"
                    for d in m["drops"])
            if m["figure"] == "fig2b":
                line += "  " + ", ".join(f"{k} {m[k]}" for k in m if "writhe" in k and
                                        isinstance(m[k], (int, float)))
            if m.get("status") not in (None, "ok"):
                line += f"\n      {m['message']}"
            print(line, flush=True)
        _stage_residuals(folder)


def _stage_residuals(folder: Path) -> None:
    """Every hold's end (equilibrium or not, by residual or settled shape) from the stores."""
    from rodphase.store import read_store

    for path in sorted(folder.glob("*.h5")):
        with read_store(path) as store:
            for rid in store.run_ids():
                r = store.read_run(rid)
                holds = [s for s in r.diagnostics["stages"] if "hold" in s["label"]]
                text = "; ".join(f"{s['label']}: {'eq' if s['equilibrium'] else 'NOT'}"
                                 f"{' (settled)' if s['settled'] else ''} res {s['residual']:.2g}"
                                 for s in holds)
                print(f"    {path.stem}/{rid}: {text}")


def fig3(variants, out: Path, samples: int, chunk: int, resume: bool, extra=()) -> None:
    from rodphase import config as C
    from rodphase.scenes import SCENES
    from rodphase.store import read_store
    from rodphase.sweep import run_sweep
    from rodphase.tabulate import classify_table

    out.mkdir(parents=True, exist_ok=True)
    paths = {name: out / f"fig3_{name}.h5" for name in variants}
    for path in paths.values():
        if path.exists() and not resume:
            path.unlink()
    # interleaved: each variant's sweep grows by `chunk` samples in turn (resuming its store),
    # so that both see the same load. Two times: the sweep's (runs with topology, storing,
    # refining; of this invocation only) and the sum of the runs' own kernel wall times
    sweep_wall = {name: 0.0 for name in variants}
    for upto in range(chunk, samples + chunk, chunk):
        for name in variants:
            sweep, scene = C.load_sweep(ROOT / "configs/fig3_paper.yaml",
                                        [*extra, *VARIANTS[name],
                                         ("sweep.samples", min(upto, samples))],
                                        SCENES)
            report = run_sweep(sweep, scene, str(paths[name]), jobs=1, progress=False,
                               echo=lambda s: None, replace=True)
            sweep_wall[name] += report.wall
    print(machine())
    tables, walls = {}, {}
    for name in variants:
        with read_store(paths[name]) as store:
            ids = sorted(store.run_ids())[:samples]
            walls[name] = sum(store.run_timings(rid)["wall_time"] for rid in ids)
            tables[name] = classify_table(store).set_index("run_id").loc[ids]
            statuses = [store.read_run(rid).status for rid in ids]
        phases = tables[name]["phase"].value_counts().to_dict()
        print(f"{name:8s} {len(ids)} points: sweep wall {sweep_wall[name]:.0f} s "
              f"({sweep_wall[name] / max(sweep_wall[variants[0]], 1e-9):.2f}x) in this invocation; "
              f"kernel wall {walls[name]:.0f} s ({walls[name] / walls[variants[0]]:.2f}x); statuses "
              f"{ {s: statuses.count(s) for s in sorted(set(statuses))} }; phases {phases}",
              flush=True)
    first = tables[variants[0]]["phase"]
    for name in variants[1:]:
        differ = first.index[first.values != tables[name]["phase"].values]
        print(f"{name:8s} phase differs from {variants[0]} at {len(differ)} points: "
              + ", ".join(differ), flush=True)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("what", choices=("speed", "demo", "figures", "fig3"))
    parser.add_argument("--variants", default="default,both")
    parser.add_argument("--out", default="/tmp/damping_sweeps")
    parser.add_argument("--only", default="")
    parser.add_argument("--steps", type=int, default=4000)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--samples", type=int, default=40)
    parser.add_argument("--chunk", type=int, default=10)
    parser.add_argument("--resume", action="store_true", help="fig3: keep the stores, add runs")
    parser.add_argument("--set", dest="sets", action="append", default=[],
                        help="KEY=VALUE for every scene or sweep (repeatable)")
    args = parser.parse_args(argv)
    variants = args.variants.split(",")
    unknown = set(variants) - set(VARIANTS)
    if unknown:
        parser.error(f"unknown variants {sorted(unknown)}; choose from {', '.join(VARIANTS)}")
    from rodphase import config as C

    try:
        extra = [C.parse_override(s) for s in args.sets]
    except C.ConfigError as exc:
        parser.error(str(exc))
    print(machine(), flush=True)
    out = Path(args.out)
    if args.what == "speed":
        speed(variants, args.steps, args.rounds, extra)
    elif args.what == "demo":
        demo(variants, out, extra)
    elif args.what == "figures":
        figures(variants, out, args.only, args.sets)
    else:
        fig3(variants, out, args.samples, args.chunk, args.resume, extra)
    return 0


if __name__ == "__main__":
    sys.exit(main())
