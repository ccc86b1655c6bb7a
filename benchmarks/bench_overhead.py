"""The cost around a run in a sweep: what a stored run costs beyond its simulation.

Run from the checkout (after `make install`):

    .venv/bin/python benchmarks/bench_overhead.py                  # 2,000 runs, --jobs 2
    .venv/bin/python benchmarks/bench_overhead.py --runs 300 --jobs 2 --keep out/bench.h5

Two parts, both on tiny, short runs (20 elements, a small twist, a 0.2 s hold: a few
milliseconds of simulation each, as the continuation solver will make them):

1. End to end: `rodphase sweep` of RUNS runs into a new store. The overhead per stored run
   is (sweep wall time − Σ simulation wall time / jobs) / runs: what the map costs beyond
   the simulations on perfectly shared cores. The parent's peak memory (ru_maxrss) is noted
   to show that the writer's memory stays bounded.
2. The breakdown, in this process on one typical result, each piece timed alone (median of
   repeats): serialisation (pickle of what a worker returns), building the run's part file
   in memory, writing it durably (write, fsync, rename), the merge into the HDF5 file (per
   run, at MERGE_EVERY runs a merge), reading the store's state on resume, planning and
   ordering the jobs, and the progress bar.

Numbers depend on the machine and its load: note `lscpu` model name and `uptime` with them
(docs/history/benchmarks.md, "The cost around a run").
"""

from __future__ import annotations

import argparse
import os
import pickle
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

TINY = {"rod.elements": 20, "solver.hold_max_time": 0.2, "loading.twist_rate": 2.0,
        "loading.force_ramp_time": 0.1, "output.history_interval": 0.1}


def sweep_yaml(folder: Path, runs: int) -> Path:
    data = {"sweep": {"scene": "twist_under_load", "set": TINY,
                      "axes": {"twist_density": [0.0, 0.1], "extension": [1.0, 1.2]},
                      "sampler": "random", "samples": runs, "seed": 7}}
    path = folder / "bench.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def end_to_end(folder: Path, runs: int, jobs: int, out: Path) -> dict:
    from rodphase.store import read_table

    path = sweep_yaml(folder, runs)
    code = ("import resource, sys; from rodphase.cli import main\n"
            "try:\n    main()\nfinally:\n"
            "    print('maxrss_kb', resource.getrusage(resource.RUSAGE_SELF).ru_maxrss,"
            " file=sys.stderr)\n")
    # compile (or load the cached kernel) first, outside the timing
    subprocess.run([sys.executable, "-c", "from rodphase.runner import compile_kernel; "
                    "compile_kernel()"], check=True)
    start = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", code, "sweep", str(path), "-o", str(out),
                           "--jobs", str(jobs), "--quiet"], capture_output=True, text=True)
    wall = time.perf_counter() - start
    if proc.returncode not in (0, 1):
        raise SystemExit(proc.stdout + proc.stderr)
    summary = next(line for line in proc.stdout.splitlines() if "skipped of" in line)
    sweep_wall = float(summary.split(" in ")[1].split(" s")[0])
    maxrss = int(proc.stderr.split("maxrss_kb")[1].split()[0])
    table = read_table(out)
    simulated = float(table["wall_time"].sum())
    return {"runs": len(table), "jobs": jobs, "sweep_wall_s": sweep_wall,
            "process_wall_s": wall, "simulation_s": simulated,
            "simulation_per_run_ms": 1e3 * simulated / len(table),
            "overhead_per_run_ms": 1e3 * (sweep_wall - simulated / jobs) / len(table),
            "parent_maxrss_MB": maxrss / 1024, "store_MB": out.stat().st_size / 1e6}


def timed(fn, repeat: int = 7) -> float:
    """Median ms of fn()."""
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return 1e3 * statistics.median(times)


def breakdown(folder: Path, store_path: Path) -> dict:
    from rodphase import config as C
    from rodphase import store as S
    from rodphase import sweep as W
    from rodphase.scenes import SCENES

    sweep, scene = C.load_sweep(str(sweep_yaml(folder, 200)), [], SCENES)
    jobs = W.plan(sweep, scene)
    job = jobs[0]
    outcome = W.execute(job)  # what a worker returns for one run
    run_id, params, result, _ = outcome[0]
    timings = {"wall_time": result.diagnostics.get("wall_time", 0.0)}
    parts: dict[str, float] = {}
    parts["serialise (pickle out + in, per run)"] = timed(
        lambda: pickle.loads(pickle.dumps(outcome, protocol=pickle.HIGHEST_PROTOCOL)))
    parts["  bytes per run"] = float(len(pickle.dumps(outcome, protocol=5)))
    parts["serialise the job sent (per run)"] = timed(lambda: pickle.loads(pickle.dumps(job)))
    target = folder / "breakdown.h5"
    text, digest = C.to_yaml(sweep=sweep, scene=scene), C.config_hash(sweep, scene)
    with S.open_store(target, config_text=text, config_hash=digest, version="bench",
                      kind="sweep") as store:
        counter = iter(range(10**6))
        parts["write_run (build + write + fsync + rename)"] = timed(
            lambda: store.write_run(f"run-{next(counter):05d}", params, result, timings), 20)
        if hasattr(store, "write_part"):  # the parent's share when a worker built the part
            names = [f"run-{next(counter):05d}" for _ in range(20)]
            images = {name: S.run_image(name, params, result, timings, digest) for name in names}
            parts["build the part in memory (a worker's share)"] = timed(
                lambda: S.run_image(run_id, params, result, timings, digest), 20)
            order = iter(names)

            def write_next():
                name = next(order)
                store.write_part(name, images[name])

            parts["write_part (write + fsync + rename)"] = timed(write_next, 20)
        # a merge of MERGE_EVERY parts into a main file that already holds 400 runs
        for k in range(400 - len(store.run_ids())):
            store.write_run(f"run-{next(counter):05d}", params, result, timings)
        store.merge()
        every, S.MERGE_EVERY = S.MERGE_EVERY, 10**9  # no merge on the way: time it alone
        try:
            for k in range(every):
                store.write_run(f"run-{next(counter):05d}", params, result, timings)
        finally:
            S.MERGE_EVERY = every
        t = time.perf_counter()
        store.merge()
        parts[f"merge, per run (of {every} into 400)"] = (
            1e3 * (time.perf_counter() - t) / every)
    with S.read_store(target) as store:
        n = len(store.run_ids())
        t = time.perf_counter()
        store.done_ids(include_failed=True)
        parts["resume: status of each stored run"] = 1e3 * (time.perf_counter() - t) / n
    t = time.perf_counter()
    planned = W.plan(sweep, scene)
    parts["plan: each sample's scene validated"] = 1e3 * (time.perf_counter() - t) / len(planned)
    t = time.perf_counter()
    W.longest_first(planned)
    parts["order: longest first"] = 1e3 * (time.perf_counter() - t) / len(planned)
    from tqdm import tqdm

    with open(os.devnull, "w") as null:  # as sweep._progress makes it, drawn to /dev/null
        bar = tqdm(total=10_000, unit="run", dynamic_ncols=True, file=null)
        t = time.perf_counter()
        for _ in range(2000):
            bar.update(1)
            bar.set_postfix(done=1, failed=0, refresh=False)
        parts["progress bar update"] = 1e3 * (time.perf_counter() - t) / 2000
        bar.close()
    return parts


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=2000)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--keep", type=Path, default=None, help="keep the sweep's store here")
    parser.add_argument("--skip-sweep", action="store_true", help="the breakdown only")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        load = os.getloadavg()
        print(f"load average before: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} "
              f"on {os.cpu_count()} cores")
        print("breakdown (ms per run unless said):")
        for name, value in breakdown(folder, folder / "b.h5").items():
            print(f"  {name:<48} {value:10.2f}")
        if not args.skip_sweep:
            out = args.keep or folder / "sweep.h5"
            out.parent.mkdir(parents=True, exist_ok=True)
            result = end_to_end(folder, args.runs, args.jobs, out)
            print("end to end:")
            for name, value in result.items():
                print(f"  {name:<24} {value:10.2f}" if isinstance(value, float)
                      else f"  {name:<24} {value:>10}")
        load = os.getloadavg()
        print(f"load average after: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
        print(f"peak memory of this process: "
              f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")


if __name__ == "__main__":
    main()
