"""Adversarial black-box robustness harness for the rodphase store (issue 17).

Every case drives the real command line in subprocesses (kill -9 at a random write call with
strace, SIGINT/SIGTERM/SIGKILL of the parent, a worker killed mid-run, a 1 MiB tmpfs, a
second writer, readers of a running sweep, bad input and stores crafted by someone else) and
judges only what a user sees: exit status, the lines printed, and what the public reading
API returns afterwards (`rodphase.store.read_table(path)` and
`rodphase.store.read_store(path).read_run(rid).positions`). Nothing here knows the store's
layout, so the same checks hold whether the output is one HDF5 file or a folder.

Stores are always inspected in a child process (`--inspect PATH`, JSON on stdout): a
damaged HDF5 file can crash the reader, and that crash is then a finding, not the end of
the harness.

    python studies/robustness.py                       # every case, 60 kill points
    python studies/robustness.py --kills 60 --write docs/explanation/robustness.md
    python studies/robustness.py --cases kill-9-during-write memory-300-runs

tests/test_robustness.py imports this file (importlib, by path) and runs each case as one
parametrized row with fewer kill points. Needs Linux (/proc), strace for the kill case and
root (mount) for the disk-full case. Prints one row per check: case, tried, right.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import pickle
import random
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = Path(__file__).resolve()

# Short runs that end "ok" (16 elements, a fast twist, brief holds with a loose tolerance,
# no stability probe): a sample takes well under a second once the kernel is compiled.
FAST = {"rod.elements": 16, "solver.hold_max_time": 0.2, "loading.twist_rate": 4.0,
        "loading.force_ramp_time": 0.1, "output.history_interval": 0.1,
        "solver.hold_tolerance": 0.1, "solver.stability_probe": False}
AXES = {"twist_density": [0.2, 0.5], "extension": [1.05, 1.2]}
SEED = 3
SAMPLES = 8          # the kill, force and crafted-store cases (and the reference sweep)
LONG_SAMPLES = 300   # sweeps that must still be running while something else happens (~10 s)
DISK_SAMPLES = 32    # ~1.9 MB with DISK_EXTRA: more than the 1 MiB tmpfs holds
DISK_EXTRA = {"output.history_interval": 0.02}
MEMORY_SAMPLES = 300
MEMORY_EXTRA = {"output.history_interval": 0.002}  # ~0.5 MB a run: the writer lags
MEMORY_LIMIT_MB = 60.0
TRACED = "pwrite64,write,rename,renameat,renameat2,fsync,fdatasync"
SIGNAL_DEADLINE = 15.0   # s for the parent to exit after SIGINT/SIGTERM; then workers dead
ORPHAN_DEADLINE = 20.0   # s after SIGKILL of the parent by which no worker may be alive
BAD_INPUT_DEADLINE = 20.0
RESUME_HINT = "run the same command"


class Skip(Exception):
    """The case cannot run here (say why): no strace, mount not permitted, not Linux."""


@dataclass
class Outcome:
    """One row of the table: a check tried `tried` times, right `right` times."""

    case: str
    tried: int = 0
    right: int = 0
    failures: list[str] = field(default_factory=list)
    seconds: float = 0.0

    def add(self, problems: list[str], label: str = "") -> bool:
        self.tried += 1
        if problems:
            self.failures.append((f"{label}: " if label else "") + "; ".join(problems))
            return False
        self.right += 1
        return True

    @property
    def passed(self) -> bool:
        return self.tried > 0 and self.right == self.tried

    def report(self) -> str:
        lines = [f"{self.case}: {self.right}/{self.tried} right ({self.seconds:.0f} s)"]
        lines += [f"  - {f}" for f in self.failures[:12]]
        if len(self.failures) > 12:
            lines.append(f"  ... and {len(self.failures) - 12} more")
        return "\n".join(lines)


# ---------------------------------------------------------------- processes

def proc_stat(pid: int) -> dict | None:
    """ppid, session, state and start time of a process from /proc, or None if gone."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except (FileNotFoundError, ProcessLookupError, PermissionError):
        return None
    rest = text[text.rindex(")") + 2:].split()
    return {"pid": pid, "state": rest[0], "ppid": int(rest[1]), "sid": int(rest[3]),
            "start": int(rest[19])}


def all_stats() -> list[dict]:
    stats = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            st = proc_stat(int(entry))
            if st is not None:
                stats.append(st)
    return stats


def descendants(pid: int) -> list[dict]:
    """Every live process below `pid` (children, their children, ...)."""
    stats = all_stats()
    found, frontier = [], {pid}
    while frontier:
        kids = [s for s in stats if s["ppid"] in frontier and s["state"] not in "ZX"]
        found += kids
        frontier = {s["pid"] for s in kids}
    return found


def session_members(sid: int) -> list[dict]:
    return [s for s in all_stats() if s["sid"] == sid and s["state"] not in "ZX"]


def is_alive(st: dict) -> bool:
    now = proc_stat(st["pid"])
    return now is not None and now["start"] == st["start"] and now["state"] not in "ZX"


def cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
    except OSError:
        return ""


def cpu_ticks(pid: int) -> int:
    try:
        rest = Path(f"/proc/{pid}/stat").read_text()
        rest = rest[rest.rindex(")") + 2:].split()
        return int(rest[11]) + int(rest[12])
    except (OSError, ValueError):
        return -1


def rss_mb(pid: int) -> float | None:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        return None
    return None


def kill_all(stats: list[dict]) -> int:
    """SIGKILL the given processes (ours, by pid and start time); return how many were alive."""
    alive = [s for s in stats if is_alive(s)]
    for s in alive:
        try:
            os.kill(s["pid"], signal.SIGKILL)
        except ProcessLookupError:
            pass
    deadline = time.monotonic() + 10
    while any(is_alive(s) for s in alive) and time.monotonic() < deadline:
        time.sleep(0.05)
    return len(alive)


def wait_dead(stats: list[dict], seconds: float) -> list[dict]:
    """Poll until every process is gone or `seconds` passed; return those still alive."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        alive = [s for s in stats if is_alive(s)]
        if not alive:
            return []
        time.sleep(0.2)
    return [s for s in stats if is_alive(s)]


@dataclass
class Result:
    rc: int | None
    out: str
    err: str
    seconds: float
    timed_out: bool = False

    @property
    def text(self) -> str:
        return self.out + "\n" + self.err

    def error_lines(self) -> list[str]:
        return [ln for ln in self.text.splitlines() if ln.startswith("error:")]


class Background:
    """A command started in its own session, output to files, so that it can be watched,
    signalled, and everything it started found (same session id) and cleaned up."""

    def __init__(self, cmd: list[str], workdir: Path, env: dict, name: str):
        self.out_path = workdir / f"{name}.stdout"
        self.err_path = workdir / f"{name}.stderr"
        self._out = open(self.out_path, "w")
        self._err = open(self.err_path, "w")
        self.start = time.monotonic()
        self.proc = subprocess.Popen(cmd, stdout=self._out, stderr=self._err, env=env,
                                     stdin=subprocess.DEVNULL, start_new_session=True)
        self.pid = self.proc.pid
        self.sid = self.pid
        self.seen: dict[tuple, dict] = {}  # every process of the session ever noticed

    def text(self) -> str:
        self._out.flush()
        self._err.flush()
        return self.out_path.read_text(errors="replace") + "\n" + self.err_path.read_text(
            errors="replace")

    def note_session(self) -> None:
        for s in session_members(self.sid):
            self.seen[(s["pid"], s["start"])] = s

    def wait_for_text(self, needle: str, timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            self.note_session()
            if needle in self.text():
                return True
            if self.proc.poll() is not None:
                return needle in self.text()
            time.sleep(0.1)
        return False

    def wait(self, timeout: float) -> int | None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                return self.proc.returncode
            self.note_session()
            time.sleep(0.1)
        return None

    def result(self) -> Result:
        self._out.close()
        self._err.close()
        return Result(self.proc.returncode, self.out_path.read_text(errors="replace"),
                      self.err_path.read_text(errors="replace"), time.monotonic() - self.start,
                      timed_out=self.proc.returncode is None)

    def cleanup(self) -> int:
        """Kill whatever of this session is still alive (ours); return how many were."""
        self.note_session()
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(10)
        n = kill_all(list(self.seen.values()) + session_members(self.sid))
        for f in (self._out, self._err):
            if not f.closed:
                f.close()
        return n


# ---------------------------------------------------------------- the lab

def _yaml(data: dict) -> str:
    import yaml

    return yaml.safe_dump(data, sort_keys=False)


class Lab:
    """Configs, the uninterrupted reference sweep and helpers, shared by all cases."""

    def __init__(self, workdir: Path, python: str = sys.executable, seed: int = 1,
                 log=print):
        self.workdir = Path(workdir)
        self.workdir.mkdir(parents=True, exist_ok=True)
        self.python = python
        self.rng = random.Random(seed)
        self.log = log
        self.cfg = self.write_config("sweep.yaml", SAMPLES)
        self.cfg_long = self.write_config("long.yaml", LONG_SAMPLES)
        self.cfg_disk = self.write_config("disk.yaml", DISK_SAMPLES, DISK_EXTRA)
        self._reference = None
        self._classified = None
        self._counter = 0

    # configs and commands
    def write_config(self, name: str, samples: int, extra: dict | None = None) -> Path:
        data = {"sweep": {"scene": "twist_under_load", "set": dict(FAST, **(extra or {})),
                          "axes": AXES, "sampler": "random", "samples": samples,
                          "seed": SEED}}
        path = self.workdir / name
        path.write_text(_yaml(data))
        return path

    def env(self, extra: dict | None = None) -> dict:
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join([str(ROOT)] + (
            [env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
        env["PYTHONUNBUFFERED"] = "1"
        env.update(extra or {})
        return env

    def cli(self, *args) -> list[str]:
        return [self.python, "-m", "rodphase.cli", *[str(a) for a in args]]

    def sweep_cmd(self, cfg: Path, out: Path, *extra) -> list[str]:
        return self.cli("sweep", cfg, "-o", out, "--jobs", 2, "--quiet", *extra)

    def fresh(self, name: str) -> Path:
        self._counter += 1
        d = self.workdir / f"{self._counter:03d}-{name}"
        d.mkdir(parents=True)
        return d

    def run(self, cmd: list[str], timeout: float = 600, env_extra: dict | None = None
            ) -> Result:
        """Run to the end (or its timeout), then kill whatever it left behind in its session.

        Output goes to files, not pipes: workers that outlive a crashed parent would hold a
        pipe open (loky's idle workers for minutes) and hide the parent's exit."""
        self._counter += 1
        logs = self.workdir / "logs"
        logs.mkdir(exist_ok=True)
        bg = Background(cmd, logs, self.env(env_extra), f"{self._counter:04d}")
        rc = bg.wait(timeout)
        bg.cleanup()
        res = bg.result()
        res.timed_out = rc is None
        return res

    def background(self, cmd: list[str], name: str, env_extra: dict | None = None,
                   workdir: Path | None = None) -> Background:
        return Background(cmd, workdir or self.workdir, self.env(env_extra), name)

    def inspect(self, path: Path) -> dict:
        """What the public reading API makes of the store at `path` (in a child process)."""
        res = self.run([self.python, str(SCRIPT), "--inspect", str(path)], timeout=300)
        lines = [ln for ln in res.out.splitlines() if ln.startswith("{")]
        if res.rc != 0 or not lines:
            tail = (res.err.strip().splitlines() or ["(no output)"])[-1]
            return {"exists": Path(path).exists(), "opens": False, "runs": {}, "rows": 0,
                    "error": f"the reader died (exit {res.rc}): {tail}"}
        return json.loads(lines[-1])

    # the reference
    def reference(self) -> dict:
        """An uninterrupted sweep of `cfg` (compiling the kernel if needed), traced to count
        the parent's write calls; returns its inspection plus the counts."""
        if self._reference is not None:
            return self._reference
        d = self.fresh("reference")
        out = d / "ref.h5"
        trace = d / "trace.txt"
        cmd = self.sweep_cmd(self.cfg, out)
        if shutil.which("strace"):
            cmd = ["strace", "-o", str(trace), "-e", "trace=pwrite64,write"] + cmd
        self.log("reference sweep (the first one in a fresh install compiles the kernel) ...")
        res = self.run(cmd, timeout=1200)
        if res.rc != 0:
            raise RuntimeError(f"the reference sweep failed (exit {res.rc}): {res.text[-2000:]}")
        info = self.inspect(out)
        problems = []
        if not info["opens"] or info["rows"] != SAMPLES:
            problems.append(f"{info.get('rows')} rows, {info.get('error')}")
        bad = {r: v["status"] for r, v in info["runs"].items() if v["status"] != "ok"}
        if bad:
            problems.append(f"runs not ok: {bad}")
        if problems:
            raise RuntimeError("the reference sweep is not usable: " + "; ".join(problems))
        counts = {"pwrite64": 0, "write": 0}
        if trace.exists():
            for line in trace.read_text(errors="replace").splitlines():
                for name in counts:
                    if line.startswith(name + "("):
                        counts[name] += 1
        info.update(path=str(out), calls=counts)
        self.log(f"reference: {info['rows']} runs, parent write calls {counts}")
        self._reference = info
        return info

    def classified_base(self) -> Path:
        """A copy of the reference store, classified (so that plot --kind phase can draw)."""
        if self._classified is not None:
            return self._classified
        d = self.fresh("classified")
        base = d / "base.h5"
        copy_store(Path(self.reference()["path"]), base)
        res = self.run(self.cli("classify", base), timeout=300)
        if res.rc != 0:
            raise RuntimeError(f"classify of a copy of the reference failed: {res.text[-1500:]}")
        self._classified = base
        return base


def copy_store(src: Path, dst: Path) -> None:
    if src.is_dir():
        shutil.copytree(src, dst)
    else:
        shutil.copy2(src, dst)


# ---------------------------------------------------------------- the inspector (child)

def inspect_main(path: str) -> None:
    """Print, as one JSON line, what read_table and read_run say about the store."""
    import numpy as np
    import pandas as pd

    from rodphase.store import read_store, read_table

    info = {"exists": Path(path).exists(), "opens": False, "rows": 0, "runs": {}, "error": ""}
    if not info["exists"]:
        print(json.dumps(info))
        return
    try:
        table = read_table(path)
        if not isinstance(table, pd.DataFrame):
            raise TypeError(f"read_table returned {type(table).__name__}")
    except Exception as exc:  # noqa: BLE001 - any failure to open is the finding
        info["error"] = f"{type(exc).__name__}: {str(exc)[:300]}"
        print(json.dumps(info))
        return
    info["opens"] = True
    info["rows"] = len(table)

    def value(row, key):
        if key not in row or row[key] is None:
            return None
        v = row[key]
        try:
            return None if pd.isna(v) else (float(v) if isinstance(v, (int, float, np.number))
                                             else str(v))
        except (TypeError, ValueError):
            return str(v)

    runs = {}
    for _, row in table.iterrows():
        rid = str(row["run_id"])
        message = str(value(row, "message"))
        runs[rid] = {"status": value(row, "status"), "message": message[:300],
                     "names_worker": "worker" in message.lower(),
                     "wall_time": value(row, "wall_time"),
                     "twist_density": value(row, "twist_density"),
                     "extension": value(row, "extension"),
                     "pos_hash": None, "diag_wall": None, "read_error": None}
    try:
        store = read_store(path)
    except Exception as exc:  # noqa: BLE001
        for r in runs.values():
            r["read_error"] = f"read_store: {type(exc).__name__}: {str(exc)[:200]}"
    else:
        try:
            for rid, r in runs.items():
                try:
                    res = store.read_run(rid)
                    pos = np.ascontiguousarray(res.positions)
                    if pos.ndim != 2 or pos.shape[1] != 3 or not np.isfinite(pos).all():
                        raise ValueError(f"positions of shape {pos.shape} or not finite")
                    r["pos_hash"] = hashlib.sha256(pos.tobytes()).hexdigest()
                    wall = (res.diagnostics or {}).get("wall_time")
                    r["diag_wall"] = float(wall) if wall is not None else None
                except Exception as exc:  # noqa: BLE001
                    r["read_error"] = f"{type(exc).__name__}: {str(exc)[:200]}"
        finally:
            close = getattr(store, "close", None)
            if close:
                close()
    info["runs"] = runs
    print(json.dumps(info))


# ---------------------------------------------------------------- shared judgements

def store_problems(info: dict, *, seen: set[str] = frozenset(), expect_rows: int | None = None,
                   reference: dict | None = None, all_ok: bool = False,
                   same_config: bool = False) -> list[str]:
    """What is wrong with an inspected store: does not open, finished runs lost, a run that
    does not read back, a run whose final positions differ from the reference sample with
    the same parameters."""
    problems = []
    if not info["exists"]:
        if seen:
            problems.append(f"the output is gone, {len(seen)} finished runs lost")
        if expect_rows:
            problems.append("no output")
        return problems
    if not info["opens"]:
        return [f"the store does not open: {info['error']}"]
    runs = info["runs"]
    lost = sorted(set(seen) - set(runs))
    if lost:
        problems.append(f"{len(lost)} finished run(s) lost: {', '.join(lost[:5])}")
    if expect_rows is not None and info["rows"] != expect_rows:
        problems.append(f"{info['rows']} rows, expected {expect_rows}")
    unreadable = {r: v["read_error"] for r, v in runs.items() if v["read_error"]}
    if unreadable:
        rid, why = next(iter(unreadable.items()))
        problems.append(f"{len(unreadable)} run(s) do not read back ({rid}: {why})")
    if all_ok:
        bad = {r: v["status"] for r, v in runs.items() if v["status"] != "ok"}
        if bad:
            problems.append(f"runs not ok: {dict(list(bad.items())[:5])}")
    if reference is not None:
        mismatch, compared = compare(reference, info)
        if mismatch:
            problems.append(f"{len(mismatch)} run(s) differ from the reference: "
                            f"{', '.join(mismatch[:5])}")
        if same_config and compared != len(runs):
            problems.append(f"only {compared} of {len(runs)} runs match a reference run "
                            "by id and parameters")
    return problems


def compare(reference: dict, info: dict) -> tuple[list[str], int]:
    """(run ids whose final positions differ from the reference sample, how many runs were
    compared). A run is compared with the reference run of the same id when both list the
    same parameters (or neither lists any), else with the reference run of its parameters."""
    ref_runs = reference["runs"]
    by_params = {(v["twist_density"], v["extension"]): v["pos_hash"] for v in ref_runs.values()
                 if v["twist_density"] is not None and v["extension"] is not None}
    mismatch, compared = [], 0
    for rid, v in info["runs"].items():
        key = (v["twist_density"], v["extension"])
        if rid in ref_runs and key == (ref_runs[rid]["twist_density"],
                                       ref_runs[rid]["extension"]):
            want = ref_runs[rid]["pos_hash"]
        elif key in by_params:
            want = by_params[key]
        else:
            continue
        compared += 1
        if v["pos_hash"] is not None and v["pos_hash"] != want:
            mismatch.append(rid)
    return mismatch, compared


def output_problems(res: Result, *, rc: int | tuple | None = None, error_names=(),
                    error_words=None, one_error: bool = True, traceback: bool = True,
                    within: float | None = None, forbid=()) -> list[str]:
    problems = []
    if res.timed_out:
        problems.append(f"did not finish in {res.seconds:.0f} s")
    wanted = rc if isinstance(rc, tuple) else (rc,) if rc is not None else None
    if wanted is not None and res.rc not in wanted:
        said = [ln.strip() for ln in res.text.splitlines() if ln.strip()][-1:] or ["nothing"]
        problems.append(f"exit {res.rc}, expected {' or '.join(map(str, wanted))} "
                        f"(last line: {said[0][:160]!r})")
    if traceback and "Traceback" in res.text:
        problems.append(traceback_report(res.text))
    if one_error:
        errors = res.error_lines()
        if len(errors) != 1:
            problems.append(f"{len(errors)} 'error:' lines, expected 1"
                            + (f" ({errors[0][:120]} ...)" if errors else ""))
        if errors:
            line = errors[0]
            if error_names and not any(n.lower() in line.lower() for n in error_names):
                problems.append(f"the error line names none of {list(error_names)}: {line[:200]}")
            if error_words and not re.search(error_words, line, re.I):
                problems.append(f"the error line does not say /{error_words}/: {line[:200]}")
    if within is not None and res.seconds > within:
        problems.append(f"took {res.seconds:.1f} s (> {within:.0f} s)")
    for word in forbid:
        if word in res.text:
            problems.append(f"printed {word!r}: it started simulating")
    return problems


# ---------------------------------------------------------------- 1. kill -9 during a write

def case_kill(lab: Lab, kills: int = 8, chain: int = 3) -> list[Outcome]:
    """kill -9 of the writer at the N-th pwrite64 (strace inject), chains of kills resumed
    on the same output, then the same command to the end. Rows: the store opens and keeps
    every run seen before (per kill); the rerun completes bit-identical (per chain);
    workers left behind (per kill, informative: the orphans row judges them)."""
    if not shutil.which("strace"):
        raise Skip("strace is not installed")
    ref = lab.reference()
    syscall = "pwrite64" if ref["calls"]["pwrite64"] else "write"
    n_calls = ref["calls"][syscall]
    if not n_calls:
        raise Skip("the reference sweep made no pwrite64/write calls under strace")
    per_kill = Outcome("kill-9-during-write")
    per_chain = Outcome("kill-9: rerun completes, bit-identical")
    orphans = Outcome("kill-9: no worker left 2 s after the kill")
    start = time.monotonic()
    chain_no = 0
    while per_kill.tried < kills:
        chain_no += 1
        d = lab.fresh(f"kill-chain-{chain_no}")
        out = d / "out.h5"
        seen: set[str] = set()
        kill_labels = []
        for _ in range(min(chain, kills - per_kill.tried)):
            n = lab.rng.randint(1, n_calls)
            label = f"chain {chain_no} kill at {syscall} #{n}"
            cmd = ["strace", "-o", "/dev/null", "-e", f"trace={TRACED}",
                   "-e", f"inject={syscall}:signal=SIGKILL:when={n}"] + lab.sweep_cmd(lab.cfg, out)
            bg = lab.background(cmd, f"kill-{chain_no}-{n}", workdir=d)
            rc = bg.wait(600)
            bg.note_session()
            left = [s for s in bg.seen.values() if s["pid"] != bg.pid]
            left_alive = wait_dead(left, 2.0)
            orphans.add([f"{len(left_alive)} worker(s) alive 2 s after the kill"]
                        if left_alive else [], label)
            bg.cleanup()
            res = bg.result()
            landed = rc is not None and rc < 0 or rc == 137
            if rc is None:
                per_kill.add([f"the killed command hung ({res.seconds:.0f} s)"], label)
                continue
            if not landed:
                label += f" (not reached: the command exited {rc})"
            info = lab.inspect(out)
            problems = store_problems(info, seen=seen, reference=ref, same_config=True)
            if not landed and rc not in (0, 1):
                last = (res.text.strip().splitlines() or ["?"])[-1]
                problems.append(f"exit {rc} without being killed: {last[:200]}")
            kill_labels.append(label)
            if not per_kill.add(problems, label):
                break  # judge every kill point on a store the earlier kills left intact
            seen |= set(info["runs"])
        res = lab.run(lab.sweep_cmd(lab.cfg, out), timeout=600)
        problems = output_problems(res, rc=0, one_error=False)
        info = lab.inspect(out)
        problems += store_problems(info, seen=seen, expect_rows=SAMPLES, reference=ref,
                                   all_ok=True, same_config=True)
        per_chain.add(problems, f"chain {chain_no} ({'; '.join(kill_labels)})")
    for o in (per_kill, per_chain, orphans):
        o.seconds = time.monotonic() - start
    return [per_kill, per_chain, orphans]


# ---------------------------------------------------------------- 2. memory

def case_memory(lab: Lab, samples: int = MEMORY_SAMPLES, limit_mb: float = MEMORY_LIMIT_MB
                ) -> list[Outcome]:
    """A sweep of many short runs with --jobs 2: the parent's RSS (VmRSS every 0.2 s) may
    grow by at most `limit_mb` from the first sample after "Launching" to the end."""
    lab.reference()  # compiled
    o = Outcome(f"memory-{samples}-runs")
    start = time.monotonic()
    d = lab.fresh("memory")
    cfg = lab.write_config(f"memory-{samples}.yaml", samples, MEMORY_EXTRA)
    out = d / "out.h5"
    bg = lab.background(lab.sweep_cmd(cfg, out), "memory", workdir=d)
    try:
        samples_mb = []
        launched = False
        while bg.proc.poll() is None:
            if not launched:
                launched = "Launching" in bg.text()
            if launched:
                mb = rss_mb(bg.pid)
                if mb is not None:
                    samples_mb.append(mb)
            if time.monotonic() - bg.start > 3600:
                break
            time.sleep(0.2)
        rc = bg.wait(5)
    finally:
        bg.cleanup()
    res = bg.result()
    problems = output_problems(res, rc=0, one_error=False)
    if len(samples_mb) < 2:
        problems.append("too few RSS samples (the sweep ended at once?)")
    else:
        growth_end = samples_mb[-1] - samples_mb[0]
        growth_peak = max(samples_mb) - samples_mb[0]
        o.failures.append(f"info: RSS {samples_mb[0]:.0f} MB after Launching, peak "
                          f"{max(samples_mb):.0f} MB, last {samples_mb[-1]:.0f} MB "
                          f"(growth {growth_peak:.0f} MB peak, {growth_end:.0f} MB end; "
                          f"{len(samples_mb)} samples, rc {rc})")
        if growth_peak > limit_mb:
            problems.append(f"parent RSS grew by {growth_peak:.0f} MB (> {limit_mb:.0f} MB)")
    info = lab.inspect(out)
    problems += store_problems(info, expect_rows=samples)
    o.add(problems, f"{samples} runs")
    o.seconds = time.monotonic() - start
    return [o]


# ---------------------------------------------------------------- 3. signals

def _start_and_wait_for_workers(lab: Lab, name: str, cfg: Path, out: Path, d: Path,
                                env_extra: dict | None = None) -> tuple[Background, list[str]]:
    bg = lab.background(lab.sweep_cmd(cfg, out), name, env_extra=env_extra, workdir=d)
    if not bg.wait_for_text("Launching", 600):
        return bg, [f"never printed 'Launching' (exit {bg.proc.poll()}): {bg.text()[-400:]}"]
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and bg.proc.poll() is None:
        workers = [w for w in descendants(bg.pid) if "resource_tracker" not in cmdline(w["pid"])]
        if workers and all(cpu_ticks(w["pid"]) > 0 for w in workers):
            break
        time.sleep(0.1)
    time.sleep(1.0)  # runs are under way (and some written)
    if bg.proc.poll() is not None:
        return bg, [f"the sweep ended before the signal (exit {bg.proc.returncode}): make it "
                    "longer"]
    return bg, []


def traceback_report(text: str) -> str:
    """A Traceback in printed text, whole: where it starts, its frames and its exception (a
    rare one, e.g. from a helper process sharing the stderr, must be diagnosable from the
    report alone)."""
    lines = text.splitlines()
    start = next(i for i, ln in enumerate(lines) if "Traceback" in ln)
    block = [lines[start]]
    for ln in lines[start + 1:]:
        block.append(ln)
        if ln and not ln.startswith(" "):  # the exception line ends the block
            break
    before = lines[start - 1].strip()[:160] if start > 0 else ""
    return ("Traceback" + (f" after {before!r}" if before else "") + ":\n        "
            + "\n        ".join(ln[:200] for ln in block[-12:]))


def case_signal(lab: Lab, sig: int, repeats: int = 1) -> list[Outcome]:
    """SIGINT/SIGTERM to the parent mid-sweep: exit 130/143 within 15 s with a resume hint
    and no Traceback; none of its workers alive 15 s after the signal; the store opens and
    the same command completes it."""
    name = {signal.SIGINT: "sigint", signal.SIGTERM: "sigterm"}[sig]
    expect = 128 + int(sig)
    ref = lab.reference()
    o = Outcome(name)
    start = time.monotonic()
    for k in range(repeats):
        d = lab.fresh(name)
        out = d / "out.h5"
        bg, problems = _start_and_wait_for_workers(lab, name, lab.cfg_long, out, d)
        if not problems:
            workers = descendants(bg.pid)
            t0 = time.monotonic()
            os.kill(bg.pid, sig)
            rc = bg.wait(SIGNAL_DEADLINE)
            took = time.monotonic() - t0
            if rc is None:
                problems.append(f"still running {SIGNAL_DEADLINE:.0f} s after {name.upper()}")
            elif rc != expect:
                problems.append(f"exit {rc}, expected {expect}")
            alive = wait_dead(workers, max(0.0, SIGNAL_DEADLINE - (time.monotonic() - t0)))
            if alive:
                problems.append(f"{len(alive)} of {len(workers)} worker(s) alive "
                                f"{SIGNAL_DEADLINE:.0f} s after the signal")
            cleaned = bg.cleanup()
            res = bg.result()
            if RESUME_HINT not in res.text.lower():
                tail = " | ".join(res.text.strip().splitlines()[-2:])[:200]
                problems.append(f"no line saying {RESUME_HINT!r} (printed: {tail!r})")
            if "Traceback" in res.err:
                problems.append(traceback_report(res.err))
            if problems and rc is not None:
                problems.insert(0, f"exited after {took:.1f} s")
            info = lab.inspect(out)
            problems += store_problems(info, reference=ref)
            if info["opens"] or not info["exists"]:
                seen = set(info["runs"])
                again = lab.run(lab.sweep_cmd(lab.cfg_long, out), timeout=600)
                p2 = output_problems(again, rc=0, one_error=False)
                info2 = lab.inspect(out)
                p2 += store_problems(info2, seen=seen, expect_rows=LONG_SAMPLES,
                                     reference=ref, all_ok=True)
                problems += [f"the same command afterwards: {p}" for p in p2]
            if cleaned:
                problems.append(f"(cleaned up {cleaned} leftover process(es))")
        else:
            bg.cleanup()
            bg.result()
        o.add(problems, f"try {k + 1}")
    o.seconds = time.monotonic() - start
    return [o]


def case_parent_sigkill(lab: Lab, repeats: int = 1) -> list[Outcome]:
    """SIGKILL of the parent mid-sweep: no worker of it alive 20 s later."""
    lab.reference()
    o = Outcome("parent-sigkill-no-orphans")
    start = time.monotonic()
    for k in range(repeats):
        d = lab.fresh("parent-sigkill")
        bg, problems = _start_and_wait_for_workers(lab, "parent-sigkill", lab.cfg_long,
                                                   d / "out.h5", d)
        if not problems:
            workers = descendants(bg.pid)
            os.kill(bg.pid, signal.SIGKILL)
            alive = wait_dead(workers, ORPHAN_DEADLINE)
            if alive:
                problems.append(f"{len(alive)} of {len(workers)} worker(s) alive "
                                f"{ORPHAN_DEADLINE:.0f} s after SIGKILL of the parent: "
                                + ", ".join(cmdline(s["pid"])[:60] for s in alive[:2]))
        bg.cleanup()
        bg.result()
        o.add(problems, f"try {k + 1}")
    o.seconds = time.monotonic() - start
    return [o]


# ---------------------------------------------------------------- 4. a worker dies

def case_worker_dies(lab: Lab, repeats: int = 1) -> list[Outcome]:
    """SIGKILL of one busy worker mid-sweep: the sweep goes on, exits 0 or 1 without a
    Traceback, every sample is in the store, and a run that is not ok is an "error" whose
    message mentions the worker."""
    ref = lab.reference()
    o = Outcome("worker-dies")
    start = time.monotonic()
    for k in range(repeats):
        d = lab.fresh("worker-dies")
        out = d / "out.h5"
        bg, problems = _start_and_wait_for_workers(lab, "worker-dies", lab.cfg_long, out, d)
        if not problems:
            workers = [w for w in descendants(bg.pid)
                       if "resource_tracker" not in cmdline(w["pid"])]
            before = {w["pid"]: cpu_ticks(w["pid"]) for w in workers}
            time.sleep(0.3)
            busiest = max(workers, key=lambda w: cpu_ticks(w["pid"]) - before[w["pid"]])
            os.kill(busiest["pid"], signal.SIGKILL)
            bg.wait(600)
            bg.cleanup()
            res = bg.result()
            problems = output_problems(res, rc=(0, 1), one_error=False)
            info = lab.inspect(out)
            problems += store_problems(info, expect_rows=LONG_SAMPLES, reference=ref)
            for rid, v in info["runs"].items():
                if v["status"] != "ok" and not (v["status"] == "error" and v["names_worker"]):
                    problems.append(f"{rid}: {v['status']}: {(v['message'] or '')[:120]!r} "
                                    "(neither retried nor an error naming the worker)")
        else:
            bg.cleanup()
            bg.result()
        o.add(problems, f"try {k + 1}")
    o.seconds = time.monotonic() - start
    return [o]


# ---------------------------------------------------------------- 5. disk full

@contextmanager
def tmpfs(directory: Path, size: str):
    directory.mkdir(parents=True, exist_ok=True)
    res = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(directory)],
                         capture_output=True, text=True)
    if res.returncode != 0:
        raise Skip(f"cannot mount a tmpfs here ({res.stderr.strip() or res.returncode}): "
                   "the disk-full case needs root")
    try:
        yield directory
    finally:
        if subprocess.run(["umount", str(directory)], capture_output=True).returncode:
            subprocess.run(["umount", "-l", str(directory)], capture_output=True)


def case_disk_full(lab: Lab) -> list[Outcome]:
    """Output on a 1 MiB tmpfs: exit 2 with one 'error:' line about the disk/space, no
    Traceback, no crash; every run in the store reads back; after growing the tmpfs to
    64 MiB the same command completes."""
    lab.reference()
    o = Outcome("disk-full")
    start = time.monotonic()
    d = lab.fresh("disk-full")
    with tmpfs(d / "mnt", "1m") as mnt:
        out = mnt / "out.h5"
        cmd = lab.sweep_cmd(lab.cfg_disk, out)
        res = lab.run(cmd, timeout=600)
        problems = output_problems(res, rc=2, error_words=r"disk|space")
        if res.rc is not None and (res.rc < 0 or res.rc == 139):
            problems.append(f"crashed (exit {res.rc})")
        info = lab.inspect(out)
        problems += store_problems(info)
        seen = set(info["runs"]) if info["opens"] else set()
        r = subprocess.run(["mount", "-o", "remount,size=64m", str(mnt)], capture_output=True,
                           text=True)
        if r.returncode:
            problems.append(f"remount failed: {r.stderr.strip()}")
        else:
            again = lab.run(cmd, timeout=600)
            p2 = output_problems(again, rc=0, one_error=False)
            p2 += store_problems(lab.inspect(out), seen=seen, expect_rows=DISK_SAMPLES,
                                 all_ok=True)
            problems += [f"after freeing space: {p}" for p in p2]
    o.add(problems)
    o.seconds = time.monotonic() - start
    return [o]


# ---------------------------------------------------------------- 6. a second writer, readers

def _running_sweep(lab: Lab, name: str, env_extra: dict | None):
    d = lab.fresh(name)
    out = d / "out.h5"
    bg, problems = _start_and_wait_for_workers(lab, name, lab.cfg_long, out, d, env_extra)
    if not problems:
        deadline = time.monotonic() + 90
        # until a run is stored: a fixed wait was too short on a loaded machine, and a reader
        # rightly answered "no finished runs yet"
        while (_stored_runs(out) < 1 and time.monotonic() < deadline
               and bg.proc.poll() is None):
            time.sleep(0.2)
        if not out.exists():
            problems.append("the output never appeared")
    return d, out, bg, problems


def _stored_runs(out: Path) -> int:
    """Runs stored so far in a store a sweep is writing, its unmerged parts included (0 while
    it cannot be read yet)."""
    from rodphase.store import read_store

    try:
        with read_store(out) as store:
            return len(store.run_ids())
    except Exception:  # not there yet, or not yet a store: keep waiting
        return 0


def _finish_first(lab: Lab, bg: Background, out: Path, ref: dict) -> list[str]:
    rc = bg.wait(600)
    bg.cleanup()
    res = bg.result()
    problems = [f"first sweep: {p}" for p in output_problems(res, rc=0, one_error=False)]
    if rc is None:
        problems.append("first sweep: hung")
    problems += [f"first sweep's store: {p}" for p in store_problems(
        lab.inspect(out), expect_rows=LONG_SAMPLES, reference=ref, all_ok=True)]
    return problems


def case_second_writer(lab: Lab, locking: bool = True) -> list[Outcome]:
    """While a sweep writes OUT, a second sweep into OUT exits 2 with one 'error:' line
    naming OUT and saying another process writes it; the first completes uncorrupted.
    locking=False sets HDF5_USE_FILE_LOCKING=FALSE for both (Lustre, GPFS, NFS)."""
    ref = lab.reference()
    name = "second-writer" if locking else "second-writer-no-hdf5-locking"
    env_extra = None if locking else {"HDF5_USE_FILE_LOCKING": "FALSE"}
    o = Outcome(name)
    start = time.monotonic()
    d, out, bg, problems = _running_sweep(lab, name, env_extra)
    if not problems:
        second = lab.run(lab.cli("sweep", lab.cfg_long, "-o", out, "--jobs", 1, "--quiet"),
                         timeout=60, env_extra=env_extra)
        if bg.proc.poll() is not None:
            problems.append("inconclusive: the first sweep ended before the second writer "
                            "did (make the sweep longer)")
        problems += [f"second writer: {p}" for p in output_problems(
            second, rc=2, error_names=(out.name,),
            error_words=r"another|being written|in use|locked|busy")]
        problems += _finish_first(lab, bg, out, ref)
    else:
        bg.cleanup()
        bg.result()
    o.add(problems)
    o.seconds = time.monotonic() - start
    return [o]


def _readers_at_once(lab: Lab, d: Path, commands: dict) -> list:
    """Start every CLI command of `commands` (name -> arguments) at once in the background,
    as a user watching a sweep would, wait for all (120 s each) and return their results."""
    readers = [lab.background(lab.cli(*args), name, workdir=d) for name, args in commands.items()]
    for r in readers:
        r.wait(120)
        r.cleanup()
    return [r.result() for r in readers]


def case_reader_during_sweep(lab: Lab) -> list[Outcome]:
    """While a sweep writes OUT, classify --csv and plot --kind shape of OUT (at once) exit
    0 without a Traceback and write their files; the sweep's store ends complete."""
    ref = lab.reference()
    o = Outcome("reader-during-sweep")
    start = time.monotonic()
    d, out, bg, problems = _running_sweep(lab, "reader-during-sweep", None)
    if not problems:
        csv, png = d / "x.csv", d / "x.png"
        readers = _readers_at_once(lab, d, {"classify": ("classify", out, "--csv", csv),
                                            "plot": ("plot", out, "--kind", "shape", "-o", png)})
        if bg.proc.poll() is not None:
            problems.append("inconclusive: the sweep ended before the readers did (make the "
                            "sweep longer)")
        for what, res, path in (("classify", readers[0], csv), ("plot", readers[1], png)):
            p = output_problems(res, rc=0, one_error=False)
            if res.rc == 0 and not (path.exists() and path.stat().st_size):
                p.append(f"wrote no {path.name}")
            problems += [f"{what}: {x}" for x in p]
        problems += _finish_first(lab, bg, out, ref)
    else:
        bg.cleanup()
        bg.result()
    o.add(problems)
    o.seconds = time.monotonic() - start
    return [o]


# ---------------------------------------------------------------- 7. bad input

def _bad_input(lab: Lab, case: str, cmd_args: list, names: tuple, out: Path | None,
               forbid=("Launching", "Running"), raw: bool = False) -> list[Outcome]:
    o = Outcome(case)
    start = time.monotonic()
    res = lab.run([str(a) for a in cmd_args] if raw else lab.cli(*cmd_args), timeout=60)
    problems = output_problems(res, rc=2, error_names=names, within=BAD_INPUT_DEADLINE,
                               forbid=forbid)
    if out is not None and out.exists():
        info = lab.inspect(out)
        if info["rows"]:
            problems.append(f"{info['rows']} runs were simulated into {out.name}")
    o.add(problems)
    o.seconds = time.monotonic() - start
    return [o]


# sweep arguments that must be refused before anything runs, and the words its one error
# line must name, per bad-input row
SWEEP_BAD_INPUT = {
    "bad-scheduler-address": (["--backend", "dask", "--scheduler", "not-an-address"],
                              ("scheduler", "not-an-address")),
    "unreachable-scheduler": (["--backend", "dask", "--scheduler", "tcp://127.0.0.1:9"],
                              ("scheduler", "127.0.0.1:9")),
    "set-overridden-by-axis": (["--jobs", 1, "--set", "loading.twist_density=1.0"],
                               ("twist_density",)),
}


def case_sweep_bad_input(lab: Lab, case_id: str) -> list[Outcome]:
    extra, words = SWEEP_BAD_INPUT[case_id]
    out = lab.fresh(case_id) / "out.h5"
    return _bad_input(lab, case_id, ["sweep", lab.cfg, "-o", out, "--quiet", *extra], words, out)


def case_run_unwritable(lab: Lab) -> list[Outcome]:
    d = lab.fresh("run-unwritable")
    blocker = d / "FILE"
    blocker.write_text("a regular file, not a folder\n")
    out = blocker / "out.h5"
    return _bad_input(lab, "run-unwritable-output",
                      ["run", "twist_under_load", "-o", out, "--set", "rod.elements=16"],
                      (str(blocker), str(out), "FILE/out.h5"), None)


def case_force_same_config(lab: Lab) -> list[Outcome]:
    """--force over a complete store of the SAME config keeps its runs: same ids, same
    positions, and the same measured wall times (nothing simulated again)."""
    ref = lab.reference()
    o = Outcome("force-same-config-keeps-runs")
    start = time.monotonic()
    d = lab.fresh("force")
    out = d / "out.h5"
    copy_store(Path(ref["path"]), out)
    before = lab.inspect(out)
    res = lab.run(lab.sweep_cmd(lab.cfg, out, "--force"), timeout=600)
    problems = output_problems(res, rc=0, one_error=False)
    after = lab.inspect(out)
    problems += store_problems(after, seen=set(before["runs"]), expect_rows=SAMPLES,
                               reference=ref, same_config=True)
    redone = [rid for rid, v in after["runs"].items() if rid in before["runs"] and (
        v["diag_wall"] != before["runs"][rid]["diag_wall"]
        or v["wall_time"] != before["runs"][rid]["wall_time"])]
    if before["runs"] and all(v["diag_wall"] is None and v["wall_time"] is None
                              for v in before["runs"].values()):
        problems.append("inconclusive: the runs carry no wall time (diagnostics or table) to "
                        "tell a kept run from one simulated again")
    if redone:
        problems.append(f"{len(redone)} of {len(before['runs'])} finished runs were deleted "
                        "and simulated again (their wall times changed)")
    o.add(problems)
    o.seconds = time.monotonic() - start
    return [o]


def case_snapshots_cannot_fit(lab: Lab) -> list[Outcome]:
    """A snapshot every step under a 2 GiB address-space limit (issue 30: the run ran to
    its end, then died with ArrayMemoryError): refused before it starts, one line naming
    output.history_interval, nothing written."""
    d = lab.fresh("snapshots-cannot-fit")
    out = d / "out.h5"
    cmd = lab.cli("run", "twist_under_load", "-o", out, "--set", "rod.elements=20",
                  "--set", "loading.twist_density=-1", "--set", "output.history_interval=1e-7")
    rows = _bad_input(lab, "snapshots-cannot-fit", ["sh", "-c", "ulimit -v 2097152; exec \"$@\"",
                                                    "sh", *cmd],
                      ("output.history_interval",), None, raw=True)
    if out.exists() or list(d.iterdir()):
        rows[0].failures.append(f"left {sorted(p.name for p in d.iterdir())}")
        rows[0].right = 0
    return rows


def _empty_store(lab: Lab, path: Path) -> None:
    """A store as a sweep killed before its first run leaves it (made with the store API)."""
    code = ("import sys; from rodphase import store as st; "
            "st.open_store(sys.argv[1], config_text='sweep: {}\\n', config_hash='h', "
            "version='0', kind='sweep').close()")
    res = lab.run([lab.python, "-c", code, str(path)], timeout=120)
    if res.rc != 0:
        raise RuntimeError(f"could not make an empty store: {res.text[-800:]}")


def case_plot_empty_store(lab: Lab) -> list[Outcome]:
    """Every plot kind and classify of a store with no run: one error line each, exit 2."""
    d = lab.fresh("plot-empty-store")
    store = d / "empty.h5"
    _empty_store(lab, store)
    o = Outcome("plot-empty-store")
    start = time.monotonic()
    for kind in ("phase", "topology", "force", "shape", "hat", "path"):
        png = d / f"{kind}.png"
        res = lab.run(lab.cli("plot", store, "--kind", kind, "-o", png), timeout=120)
        problems = output_problems(res, rc=2, error_names=("empty.h5",))
        if png.exists():
            problems.append(f"wrote {png.name}")
        o.add(problems, kind)
    res = lab.run(lab.cli("classify", store), timeout=120)
    o.add(output_problems(res, rc=2, error_names=("empty.h5",)), "classify")
    o.seconds = time.monotonic() - start
    return [o]


def case_plot_hat_of_sweep(lab: Lab) -> list[Outcome]:
    """plot --kind hat of a sweep's store whose runs start on the straight branch and only
    hold (as the demo's do: loading.quasi_static_below) says so in one line instead of
    writing an empty figure with exit 0."""
    d = lab.fresh("plot-hat-of-sweep")
    cfg = d / "held.yaml"
    cfg.write_text(_yaml({"sweep": {
        "scene": "twist_under_load", "set": dict(FAST, **{"loading.quasi_static_below": 0.95}),
        "axes": {"twist_density": [0.05, 0.1], "extension": [1.05, 1.2]},
        "sampler": "random", "samples": 2, "seed": SEED}}))
    base = d / "held.h5"
    res = lab.run(lab.sweep_cmd(cfg, base), timeout=600)
    if res.rc != 0:
        raise RuntimeError(f"the held sweep failed (exit {res.rc}): {res.text[-1500:]}")
    png = d / "hat.png"
    rows = _bad_input(lab, "plot-hat-of-sweep", ["plot", base, "--kind", "hat", "-o", png],
                      ("--kind hat",), None)
    if png.exists():
        rows[0].failures.append("wrote hat.png")
        rows[0].right = 0
    return rows


INCONCLUSIVE = "inconclusive: the sweep ended before the readers did"


def case_plot_phase_while_written(lab: Lab) -> list[Outcome]:
    """While a sweep writes OUT, plot --kind phase draws the runs finished so far (exit 0, a
    figure) and classify prints them with one note saying why the table is not stored.
    A try whose sweep ended before both readers did says nothing and is made once more (a
    loaded machine starts the readers slower than the ~10 s sweep lasts; seen once)."""
    ref = lab.reference()
    o = Outcome("plot-phase-while-written")
    start = time.monotonic()
    for attempt in range(2):
        problems = _plot_while_written_once(lab, ref, f"plot-phase-while-written-{attempt}")
        if problems != [INCONCLUSIVE]:
            break
    o.add(problems)
    o.seconds = time.monotonic() - start
    return [o]


def _plot_while_written_once(lab: Lab, ref: dict, name: str) -> list[str]:
    d, out, bg, problems = _running_sweep(lab, name, None)
    if problems:
        bg.cleanup()
        bg.result()
        return problems
    # _running_sweep waited for a stored run; both readers at once, as a user watching a
    # sweep would (one after the other they outlasted the sweep's ~10 s)
    png = d / "phase.png"
    readers = _readers_at_once(lab, d, {"plot": ("plot", out, "--kind", "phase", "-o", png),
                                        "classify": ("classify", out)})
    res = readers[0]
    p = output_problems(res, rc=0, one_error=False)
    if res.rc == 0 and not (png.exists() and png.stat().st_size):
        p.append("wrote no phase.png")
    problems += [f"plot: {x}" for x in p]
    res = readers[1]
    p = output_problems(res, rc=0, one_error=False)
    if not re.search(r"^\d+ runs: ", res.out, re.M):
        p.append("printed no table summary")
    if len([ln for ln in res.text.splitlines() if ln.startswith("note:")]) != 1:
        p.append("no single note saying why the table is not stored")
    problems += [f"classify: {x}" for x in p]
    if bg.proc.poll() is not None:
        problems.append(INCONCLUSIVE)
    return problems + _finish_first(lab, bg, out, ref)


def case_unknown_run_id(lab: Lab) -> list[Outcome]:
    """plot --run of an id the store lacks: one line naming it and the ids stored, without
    the stray quotes of a printed KeyError."""
    base = lab.classified_base()
    d = lab.fresh("unknown-run-id")
    o = Outcome("unknown-run-id")
    start = time.monotonic()
    res = lab.run(lab.cli("plot", base, "--kind", "topology", "--run", "run-99999", "-o",
                          d / "x.png"), timeout=60)
    problems = output_problems(res, rc=2, error_names=("run-00000",), within=BAD_INPUT_DEADLINE)
    errors = res.error_lines()
    if errors and not errors[0].startswith("error: --run: 'run-99999'"):
        problems.append(f"the line does not start with the option and the id: {errors[0][:120]}")
    o.add(problems)
    o.seconds = time.monotonic() - start
    return [o]


def case_misspelt_scene(lab: Lab) -> list[Outcome]:
    out = lab.fresh("misspelt-scene") / "out.h5"
    rows = _bad_input(lab, "misspelt-scene", ["run", "twist_under_lod", "-o", out],
                      ("did you mean 'twist_under_load'",), None)
    if out.exists():
        rows[0].failures.append("made out.h5")
        rows[0].right = 0
    return rows


# ---------------------------------------------------------------- stores from strangers

def _h5_files(store: Path) -> list[Path]:
    if store.is_dir():
        return sorted(p for p in store.rglob("*") if p.is_file() and _is_hdf5(p))
    return [store]


def _is_hdf5(path: Path) -> bool:
    with open(path, "rb") as f:
        return f.read(8) == b"\x89HDF\r\n\x1a\n"


def _find_run_group(f):
    """(parent group, a run group) of an open h5py file: a group holding 'positions'."""
    import h5py

    found = []

    def visit(name, obj):
        if isinstance(obj, h5py.Group) and "positions" in obj and isinstance(
                obj.get("positions", getlink=True), h5py.HardLink) and not found:
            found.append(name)

    f.visititems(visit)
    if not found:
        return None, None
    name = found[0]
    parent = f[name.rsplit("/", 1)[0]] if "/" in name else f
    return parent, f[name]


def craft(kind: str, base: Path, dst: Path, elsewhere: Path) -> None:
    """A copy of the store `base` at `dst`, made hostile: 'external-link' (an
    h5py.ExternalLink beside the runs, to a run in a file elsewhere), 'external-storage'
    (a run's positions stored in a raw file elsewhere), 'pickled-attribute' (a run's
    `message` is raw pickle bytes) or 'truncated-store' (the first half of the bytes)."""
    import h5py
    import numpy as np

    copy_store(base, dst)
    elsewhere.mkdir(parents=True, exist_ok=True)
    files = _h5_files(dst)
    if kind == "truncated-store":
        for path in files:
            data = path.read_bytes()
            path.write_bytes(data[: len(data) // 2])
        return
    for path in files:
        with h5py.File(path, "a") as f:
            parent, run = _find_run_group(f)
            if run is None:
                continue
            if kind == "external-link":
                secret = elsewhere / "secret.h5"
                copy_store(_h5_files(base)[0], secret)
                with h5py.File(secret, "r") as s:
                    _, target = _find_run_group(s)
                    target_name = target.name
                parent["run-99999"] = h5py.ExternalLink(str(secret), target_name)
            elif kind == "external-storage":
                pos = run["positions"][()]
                raw = elsewhere / "positions.bin"
                raw.write_bytes(np.ascontiguousarray(pos, dtype="<f8").tobytes())
                del run["positions"]
                run.create_dataset("positions", shape=pos.shape, dtype="<f8",
                                   external=[(str(raw), 0, h5py.h5f.UNLIMITED)])
            elif kind == "pickled-attribute":
                payload = pickle.dumps({"from": "someone else", "payload": list(range(5))})
                # opaque bytes (np.void) where a string belongs, and in a second run the
                # same bytes as a byte string (not UTF-8)
                run.attrs["message"] = np.void(payload)
                others = [parent[k] for k in parent if parent[k].name != run.name
                          and isinstance(parent[k], h5py.Group)]
                if others:
                    others[0].attrs["message"] = np.bytes_(payload)
            else:
                raise ValueError(kind)
            return
    raise RuntimeError(f"no run group found in {dst} to craft {kind}")


CRAFTED = ("external-link", "external-storage", "pickled-attribute", "truncated-store")


def case_crafted(lab: Lab, kind: str) -> list[Outcome]:
    """classify and plot --kind phase of a hostile store: each exits 2 with one 'error:'
    line and no Traceback."""
    base = lab.classified_base()
    o = Outcome(kind)
    start = time.monotonic()
    d = lab.fresh(kind)
    stores = {}
    for what in ("classify", "plot"):
        stores[what] = d / f"{what}.h5"
        craft(kind, base, stores[what], d / f"elsewhere-{what}")
    procs = {"classify": lab.background(lab.cli("classify", stores["classify"], "--csv",
                                                d / "x.csv"), "classify", workdir=d),
             "plot": lab.background(lab.cli("plot", stores["plot"], "--kind", "phase", "-o",
                                            d / "x.png"), "plot", workdir=d)}
    problems = []
    for what, bg in procs.items():
        bg.wait(120)
        bg.cleanup()
        res = bg.result()
        problems += [f"{what}: {p}" for p in output_problems(res, rc=2)]
    o.add(problems)
    o.seconds = time.monotonic() - start
    return [o]


# ---------------------------------------------------------------- the table

def cases(kills: int = 60, repeats: int = 1, memory_samples: int = MEMORY_SAMPLES) -> dict:
    """Case id → function(lab) → list of Outcome rows."""
    table = {
        "kill-9-during-write": lambda lab: case_kill(lab, kills=kills),
        "sigint": lambda lab: case_signal(lab, signal.SIGINT, repeats),
        "sigterm": lambda lab: case_signal(lab, signal.SIGTERM, repeats),
        "parent-sigkill-no-orphans": lambda lab: case_parent_sigkill(lab, repeats),
        "worker-dies": lambda lab: case_worker_dies(lab, repeats),
        "disk-full": case_disk_full,
        "second-writer": lambda lab: case_second_writer(lab, locking=True),
        "second-writer-no-hdf5-locking": lambda lab: case_second_writer(lab, locking=False),
        "reader-during-sweep": case_reader_during_sweep,
        **{case_id: (lambda c: lambda lab: case_sweep_bad_input(lab, c))(case_id)
           for case_id in SWEEP_BAD_INPUT},
        "run-unwritable-output": case_run_unwritable,
        "snapshots-cannot-fit": case_snapshots_cannot_fit,
        "plot-empty-store": case_plot_empty_store,
        "plot-hat-of-sweep": case_plot_hat_of_sweep,
        "plot-phase-while-written": case_plot_phase_while_written,
        "unknown-run-id": case_unknown_run_id,
        "misspelt-scene": case_misspelt_scene,
        "force-same-config-keeps-runs": case_force_same_config,
    }
    for kind in CRAFTED:
        table[kind] = (lambda k: lambda lab: case_crafted(lab, k))(kind)
    table[f"memory-{memory_samples}-runs"] = lambda lab: case_memory(lab, memory_samples)
    return table


def markdown(rows: list[Outcome], header: str) -> str:
    lines = [header, "", "| case | tried | right |", "|---|---:|---:|"]
    for r in rows:
        lines.append(f"| {r.case} | {r.tried} | {r.right} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--kills", type=int, default=60, help="kill points (default 60)")
    parser.add_argument("--repeats", type=int, default=1,
                        help="tries of each signal / worker case (default 1)")
    parser.add_argument("--memory-samples", type=int, default=MEMORY_SAMPLES)
    parser.add_argument("--cases", nargs="*", help="only these case ids")
    parser.add_argument("--seed", type=int, default=1, help="seed of the kill points")
    parser.add_argument("--workdir", type=Path, help="keep everything here (default: a "
                        "temporary folder, removed afterwards)")
    parser.add_argument("--python", default=sys.executable,
                        help="the Python that runs rodphase (default: this one)")
    parser.add_argument("--write", type=Path, metavar="MD",
                        help="also put the table into this Markdown file (a named block)")
    parser.add_argument("--inspect", metavar="STORE", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.inspect:
        inspect_main(args.inspect)
        return 0
    table = cases(args.kills, args.repeats, args.memory_samples)
    chosen = args.cases or list(table)
    unknown = [c for c in chosen if c not in table]
    if unknown:
        parser.error(f"unknown case(s) {unknown}; known: {', '.join(table)}")
    workdir = args.workdir or Path(tempfile.mkdtemp(prefix="rodphase-robustness-"))
    lab = Lab(workdir, python=args.python, seed=args.seed)
    rows: list[Outcome] = []
    started = time.monotonic()
    for case in chosen:
        try:
            got = table[case](lab)
        except Skip as why:
            print(f"{case}: skipped: {why}", flush=True)
            continue
        for row in got:
            print(row.report(), flush=True)
            rows.append(row)
    total = time.monotonic() - started
    header = (f"Robustness of the store (studies/robustness.py, {args.kills} kill points, "
              f"seed {args.seed}, {time.strftime('%Y-%m-%d', time.gmtime())}, "
              f"{os.cpu_count()} cores, {total:.0f} s):")
    text = markdown(rows, header)
    print()
    print(text)
    if args.write:
        from rodphase.studytools import write_block

        write_block(args.write, "robustness", text)
        if args.cases is None:  # the whole corpus: its row of the current figures
            from rodphase.studytools import record_current

            tries, right = sum(r.tried for r in rows), sum(r.right for r in rows)
            record_current("robustness", f"{len(rows)} rows, {tries} tries, {right} right; "
                           f"{total:.0f} s ({args.kills} kill points, seed {args.seed})",
                           source="`make robustness`")
    if args.workdir is None:
        shutil.rmtree(workdir, ignore_errors=True)
    return 0 if all(r.passed or r.case.startswith("kill-9: no worker") for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
