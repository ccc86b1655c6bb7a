"""First-compile cost: `make demo` and `rodphase run` on an empty numba cache, and where it goes.

    python benchmarks/compile_time.py demo --repeats 2      # the steps of `make demo`, cold cache
    python benchmarks/compile_time.py run --repeats 2       # `rodphase run twist_under_load`, cold
    python benchmarks/compile_time.py functions             # seconds per compiled function

Every repeat gets a new, empty NUMBA_CACHE_DIR (removed afterwards), so nothing is loaded
from an earlier compile: neither from a cache dir nor from the __pycache__ next to the
sources (numba writes there only without NUMBA_CACHE_DIR). The commands run this checkout's
rodphase with this interpreter (PYTHONPATH is set to the repository root).

demo: the three steps of `make demo` (sweep configs/quick.yaml --jobs 2, classify, plot),
each timed (wall), with the compile seconds the sweep prints ("ready in ..."), and the CPU
seconds of the sweep's process and the processes it waited for. run: the same for one
scene. functions: compile_kernel in this process with listeners on numba's compile, pass and
LLVM-lock events: wall and CPU seconds of every compiled function, the topology's and the
static functions' first (nested: a callee compiled while typing its caller is indented under
it and counted in the caller's time too), and its CPU split into typing, IR inlining, SSA,
lowering and LLVM's own time.
The load average (1/5/15 min) is printed before and after every repeat: the numbers are only
comparable at a similar load.
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _env(cache: str) -> dict:
    """The environment of a timed command: an empty numba cache, rodphase from ROOT."""
    env = dict(os.environ, NUMBA_CACHE_DIR=cache)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT)] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
    return env


def _children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _step(argv: list[str], env: dict, cwd: str) -> dict:
    cpu0, t0 = _children_cpu(), time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "rodphase.cli", *argv], env=env, cwd=cwd,
                          capture_output=True, text=True)
    wall, cpu = time.perf_counter() - t0, _children_cpu() - cpu0
    if proc.returncode not in (0, 1):
        sys.stderr.write(proc.stdout + proc.stderr)
        raise SystemExit(f"{' '.join(argv)} failed ({proc.returncode})")
    out = proc.stdout + proc.stderr
    ready = re.search(r"ready in ([0-9.]+) s(?: \(CPU ([0-9.]+) s\))?", out)
    runs = re.search(r"in ([0-9.]+) s \(\+ ([0-9.]+) s compiling\)", out)
    return {"wall": wall, "cpu": cpu,
            "compile": float(ready.group(1)) if ready else None,
            "compile_cpu": float(ready.group(2)) if ready and ready.group(2) else None,
            "runs": float(runs.group(1)) if runs else None}


def _load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def demo(repeats: int, jobs: int, keep: str | None = None, record: bool = False) -> None:
    """make demo's steps on an empty numba cache, `repeats` times; with `record`, the last
    repeat's compile and run times become rows of the current figures (docs/current.json)."""
    for r in range(repeats):
        cache, work = tempfile.mkdtemp(prefix="numba-cold-"), tempfile.mkdtemp(prefix="demo-")
        try:
            env, load0 = _env(cache), _load()
            sweep = _step(["sweep", str(ROOT / "configs/quick.yaml"), "-o", "quick.h5",
                           "--jobs", str(jobs)], env, work)
            classify = _step(["classify", "quick.h5", "--csv", "quick.csv"], env, work)
            plot = _step(["plot", "quick.h5", "--kind", "phase", "-o", "quick_phase.png"], env,
                         work)
            print(f"demo {r + 1}/{repeats}: sweep {sweep['wall']:.1f} s wall "
                  f"(compile {sweep['compile']} s wall, {sweep['compile_cpu']} s CPU; runs "
                  f"{sweep['runs']} s; CPU of the sweep and its reaped children "
                  f"{sweep['cpu']:.1f} s), classify {classify['wall']:.1f} s, plot "
                  f"{plot['wall']:.1f} s; total {sweep['wall'] + classify['wall'] + plot['wall']:.1f} s; "
                  f"load {load0} -> {_load()}", flush=True)
            if record and r == repeats - 1 and sweep["compile"] is not None:
                from rodphase.studytools import record_current

                total = sweep["wall"] + classify["wall"] + plot["wall"]
                record_current("compile_time", f"{sweep['compile']:.1f} s of compiling; the whole "
                               f"first `make demo` {total:.1f} s", source="`make bench-compile`")
                if sweep["runs"] is not None:
                    record_current("demo_time", f"{sweep['runs']:.1f} s",
                                   source="`make bench-compile`")
            if keep:
                Path(keep).mkdir(parents=True, exist_ok=True)
                shutil.copy(Path(work) / "quick.csv", Path(keep) / f"quick_{r + 1}.csv")
        finally:
            shutil.rmtree(cache, ignore_errors=True)
            shutil.rmtree(work, ignore_errors=True)


def run(repeats: int) -> None:
    for r in range(repeats):
        cache, work = tempfile.mkdtemp(prefix="numba-cold-"), tempfile.mkdtemp(prefix="run-")
        try:
            env, load0 = _env(cache), _load()
            step = _step(["run", "twist_under_load", "-o", "run.h5"], env, work)
            print(f"run {r + 1}/{repeats}: {step['wall']:.1f} s wall (compile {step['compile']} s "
                  f"wall, {step['compile_cpu']} s CPU), CPU of the process and its children "
                  f"{step['cpu']:.1f} s; load {load0} -> {_load()}", flush=True)
        finally:
            shutil.rmtree(cache, ignore_errors=True)
            shutil.rmtree(work, ignore_errors=True)


# numba's compiler passes, grouped by what they do (the rest are counted as "other")
PHASES = {"nopython_type_inference": "typing", "inline_inlinables": "IR inlining",
          "reconstruct_ssa": "SSA", "native_lowering": "lowering"}


def functions() -> None:
    """The three compiles of a first run, here, on a fresh cache, one after the other: the
    topology, the static functions and compile_kernel (which otherwise hands the first two to
    a second process): every compile of a dispatcher timed, and split into numba's passes and
    LLVM's own time (the time llvmlite holds its lock: parsing, optimising and emitting)."""
    if "NUMBA_CACHE_DIR" not in os.environ or "rodphase" in sys.modules:
        cache = tempfile.mkdtemp(prefix="numba-cold-")
        try:
            proc = subprocess.run([sys.executable, __file__, "functions"], env=_env(cache))
        finally:
            shutil.rmtree(cache, ignore_errors=True)
        raise SystemExit(proc.returncode)
    from numba.core import event

    records, stack, passes = [], [], []

    class Timer(event.Listener):
        def on_start(self, ev):
            records.append(None)  # filled in at the end: callers come before their callees
            stack.append((len(records) - 1, time.perf_counter(), time.process_time(), {}))

        def on_end(self, ev):
            index, t0, c0, phases = stack.pop()
            f = ev.data["dispatcher"].py_func
            records[index] = (len(stack), f"{f.__module__}.{f.__qualname__}",
                              ", ".join(map(str, ev.data["args"])),
                              time.perf_counter() - t0, time.process_time() - c0, phases)

    class Passes(event.Listener):
        # a pass of the innermost compile (a callee compiled while typing its caller runs
        # its own passes, inside the caller's typing pass)
        def on_start(self, ev):
            passes.append((ev.data["name"], time.process_time(), len(stack)))

        def on_end(self, ev):
            name, c0, depth = passes.pop()
            if stack and len(stack) == depth:
                phase = PHASES.get(name.split(" [")[0], "other")  # "name [function]"
                phases = stack[-1][3]
                phases[phase] = phases.get(phase, 0.0) + time.process_time() - c0

    llvm = [0.0]

    class Llvm(event.Listener):
        def on_start(self, ev):
            llvm[0] = time.process_time()

        def on_end(self, ev):
            if stack:
                phases = stack[-1][3]
                phases["LLVM"] = phases.get("LLVM", 0.0) + time.process_time() - llvm[0]

    event.register("numba:compile", Timer())
    event.register("numba:run_pass", Passes())
    event.register("numba:llvm_lock", Llvm())
    load0 = _load()
    from rodphase import topology
    from rodphase.rod.onset import compile_static
    from rodphase.runner import compile_kernel

    # the topology and the static functions first, here, so that they are timed too
    # (compile_kernel would hand them to a second process on an empty cache)
    for what, compile_them in (("topology (compile_history)", topology.compile_history),
                               ("static (onset.compile_static)", compile_static)):
        c0, t0 = time.process_time(), time.perf_counter()
        compile_them()
        print(f"{what}: {time.perf_counter() - t0:.1f} s wall, "
              f"{time.process_time() - c0:.1f} s CPU")
    c0 = time.process_time()
    wall = compile_kernel()
    print(f"then compile_kernel: {wall:.1f} s wall, {time.process_time() - c0:.1f} s CPU; "
          f"load {load0} -> {_load()}")
    print("own functions (callee lines under their caller; numba's own overloads left out).\n"
          "CPU s by phase: typing (less the callees compiled meanwhile, their own lines), IR\n"
          "inlining, SSA, lowering; LLVM: the time llvmlite holds its lock (optimising and\n"
          "emitting), mostly within lowering; other: numba's other passes:")
    for i, (depth, name, args, w, c, phases) in enumerate(records):
        if not name.startswith("rodphase."):
            continue
        callees = 0.0
        for later in records[i + 1:]:
            if later[0] <= depth:
                break
            if later[0] == depth + 1:
                callees += later[4]
        typing = max(phases.get("typing", 0.0) - callees, 0.0)
        split = (f"typing {typing:.1f}, inlining {phases.get('IR inlining', 0.0):.1f}, "
                 f"SSA {phases.get('SSA', 0.0):.1f}, lowering {phases.get('lowering', 0.0):.1f} "
                 f"(LLVM {phases.get('LLVM', 0.0):.1f}), other {phases.get('other', 0.0):.1f}")
        print(f"  {'  ' * depth}{w:6.2f} s wall {c:6.2f} s CPU  {name}({args[:60]})\n"
              f"  {'  ' * depth}{'':28s}{split}")
    for top in [r for r in records if r[0] == 0]:
        start = records.index(top)
        end = next((i for i in range(start + 1, len(records)) if records[i][0] == 0),
                   len(records))
        own = sum(r[4] for r in records[start + 1:end]
                  if r[0] == 1 and not r[1].startswith("rodphase."))
        print(f"  of {top[1]}: {own:.1f} s CPU compiling numba's own overloads directly under it")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("what", choices=["demo", "run", "functions"])
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--jobs", type=int, default=2, help="sweep workers (make demo: 2)")
    parser.add_argument("--repo", help="time the rodphase of this checkout instead (e.g. the "
                        "main branch, for a before/after comparison); configs/quick.yaml from it")
    parser.add_argument("--keep", metavar="DIR", help="demo: copy each repeat's quick.csv here")
    args = parser.parse_args(argv)
    if args.repo:
        global ROOT
        ROOT = Path(args.repo).resolve()
    # `functions` runs itself again in a process that must not import rodphase before it
    # times the compile (that child has NUMBA_CACHE_DIR set and says nothing here): the
    # machine line is this process's
    timed_child = (args.what == "functions" and "NUMBA_CACHE_DIR" in os.environ
                   and "rodphase" not in sys.modules)
    if not timed_child:
        from rodphase.studytools import machine

        m = machine()
        print(f"{m['cpu']}, nproc {m['nproc']}; python {sys.version.split()[0]}; rodphase from "
              f"{ROOT}", flush=True)
    if args.what == "demo":
        demo(args.repeats, args.jobs, args.keep, record=not args.repo)
    elif args.what == "run":
        run(args.repeats)
    else:
        functions()
    return 0


if __name__ == "__main__":
    sys.exit(main())
