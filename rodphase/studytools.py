"""What the scripts of benchmarks/ and studies/ share: the machine a number was measured on,
the named Markdown block of docs/ a script rewrites, a sweep run through the CLI, and sweep
stores read point by point.

Nothing in the package calls these; they live here, not in a scripts module, so that every
script imports them the same way (``from rodphase.studytools import write_block``) wherever
it is run from, and so that they are tested (tests/test_studytools.py).
"""

from __future__ import annotations

import os
from pathlib import Path


def machine() -> dict:
    """CPU model, core count and load average (1, 5, 15 min), to print next to every timing."""
    cpu = "unknown"
    try:
        lines = Path("/proc/cpuinfo").read_text().splitlines()
    except OSError:  # not Linux
        lines = []
    for line in lines:
        if line.startswith("model name"):
            cpu = line.split(":", 1)[1].strip()
            break
    return {"cpu": cpu, "nproc": os.cpu_count(), "load": os.getloadavg()}


def write_block(doc: Path, name: str, text: str) -> None:
    """Replace the text between ``<!-- name:begin -->`` and ``<!-- name:end -->`` in `doc`
    (appended at the end, with both markers, when the file has no such block)."""
    doc = Path(doc)
    begin, end = f"<!-- {name}:begin -->", f"<!-- {name}:end -->"
    body = doc.read_text() if doc.exists() else ""
    if begin in body and end in body:
        head, rest = body.split(begin, 1)
        _, tail = rest.split(end, 1)
        body = f"{head}{begin}\n{text}\n{end}{tail}"
    else:
        body += f"\n{begin}\n{text}\n{end}\n"
    doc.write_text(body)
    print(f"updated {doc} ({name})")


def classified_sweep(config: str, path: Path, sets: list[str], jobs: int) -> float:
    """`rodphase sweep CONFIG -o PATH --jobs JOBS --quiet --set ...` (a new store, or the
    stored one resumed), then `rodphase classify PATH`; the sweep's wall time [s]. A sweep
    whose runs partly failed (exit 1: they are recorded) is fine; any other exit stops."""
    return timed_sweep(config, path, sets, jobs)[0]


def timed_rodphase(command: str, config: str, path: Path, args: list[str],
                   jobs: int) -> tuple[float, float]:
    """`rodphase COMMAND CONFIG -o PATH --jobs JOBS --quiet ARGS` and its cost: (wall [s],
    CPU [s]: user + system of the command's process and the workers it waited for, the
    compile included). A command whose runs partly failed (exit 1: they are recorded) is
    fine; any other exit stops."""
    import resource
    import subprocess
    import sys
    import time

    rodphase = str(Path(sys.executable).with_name("rodphase"))
    argv = [rodphase, command, config, "-o", str(path), "--jobs", str(jobs), "--quiet", *args]

    def children() -> float:
        usage = resource.getrusage(resource.RUSAGE_CHILDREN)
        return usage.ru_utime + usage.ru_stime

    cpu0, t0 = children(), time.perf_counter()
    done = subprocess.run(argv)
    wall, cpu = time.perf_counter() - t0, children() - cpu0
    if done.returncode not in (0, 1):
        raise SystemExit(f"{' '.join(argv)} exited {done.returncode}")
    return wall, cpu


def timed_sweep(config: str, path: Path, sets: list[str], jobs: int) -> tuple[float, float]:
    """classified_sweep's sweep, and its cost (timed_rodphase); classified afterwards."""
    import subprocess
    import sys

    timed = timed_rodphase("sweep", config, path, [a for s in sets for a in ("--set", s)], jobs)
    rodphase = str(Path(sys.executable).with_name("rodphase"))
    subprocess.run([rodphase, "classify", str(path)], check=True, capture_output=True)
    return timed


def sweep_table(path: Path):
    """The classified table of a sweep store, in run order. Sweeps of one config with the same
    sampler and seed draw the same points in the same order, so the i-th rows of two such
    tables are the same point (check it with same_points)."""
    from .api import table

    return table(path).sort_values("run_id").reset_index(drop=True)


def same_points(a, b, axes=("twist_density", "extension")) -> bool:
    """Whether the first rows of two sweep tables are the same points, on the axes both have."""
    import numpy as np

    n = min(len(a), len(b))
    return all(np.allclose(a[k][:n], b[k][:n], rtol=1e-9) for k in axes if k in a and k in b)


def boundary_error(reference, samples, axes, lo, span) -> float:
    """The share of `reference` points (a table with a phase column) whose phase the nearest
    point of `samples` (failed ones left out) gets wrong, nearest in the `axes` coordinates
    scaled to the box (lo, span): the area of the box the boundaries `samples` imply
    misplace."""
    import numpy as np
    from scipy.spatial import cKDTree

    def scaled(table):
        return (table[list(axes)].to_numpy(float) - lo) / span

    usable = samples[samples["phase"] != "failed"]
    _, nearest = cKDTree(scaled(usable)).query(scaled(reference))
    guessed = usable["phase"].to_numpy()[nearest]
    return float(np.mean(guessed != reference["phase"].to_numpy()))


# ---------------------------------------------------------------- current figures
# docs/current.json holds one value per quantity (with its date, machine and commit); the
# scripts that measure a quantity call record_current, which re-renders docs/current.md
# (the page of current figures) and docs/history/figures.md (every value a quantity had
# before). tests/test_docs.py fails when either page is stale against the JSON.

DOCS = Path(__file__).resolve().parents[1] / "docs"
CURRENT = DOCS / "current.json"


def git_commit(short: bool = True) -> str:
    """The commit of the checkout the code runs from ("unknown" outside git)."""
    import subprocess

    args = ["git", "rev-parse", "--short" if short else "--verify", "HEAD"]
    done = subprocess.run(args, capture_output=True, text=True, cwd=DOCS.parent, check=False)
    return done.stdout.strip() or "unknown"


def machine_text() -> str:
    """'CPU, N cores, load L' for a row of current figures."""
    m = machine()
    return f"{m['cpu']}, {m['nproc']} cores, load {m['load'][0]:.2f} at the start"


def record_current(key: str, value: str, *, source: str, machine: str | None = None,
                   date: str | None = None, commit: str | None = None,
                   extra: dict | None = None, path: Path = CURRENT) -> None:
    """Make `value` the current value of quantity `key` in docs/current.json (the previous
    value goes to its history), then re-render the pages made from it. `source` names the
    command that measured it; machine, date and commit default to this machine, today (UTC)
    and the checkout's commit. `extra` adds fields to the entry (e.g. the sha256 of the
    figure the same command drew, which tests/test_docs.py checks)."""
    import datetime
    import json

    path = Path(path)
    data = json.loads(path.read_text())
    entry = data["quantities"][key]  # a new quantity is added to the JSON by hand, once
    if "value" in entry:
        entry.setdefault("history", []).insert(
            0, {k: entry[k] for k in ("value", "date", "machine", "commit", "source")})
        del entry["history"][20:]  # the 20 latest are enough
    entry.update(value=value, source=source, machine=machine or machine_text(),
                 date=date or datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d"),
                 commit=commit or git_commit(), **(extra or {}))
    path.write_text(json.dumps(data, indent=1, ensure_ascii=False) + "\n")
    write_current_pages(path)


def render_current(data: dict) -> str:
    """docs/current.md from the JSON: one row per quantity."""
    rows = [f"| {q['title']} | {q['value']} | {q['date']} | {q['machine']} | `{q['commit']}` | "
            f"{q['source']} |" for q in data["quantities"].values()]
    return "\n".join([
        "# Current figures", "",
        "<!-- generated from docs/current.json by rodphase.studytools.render_current: do not "
        "edit; the command in the last column writes its row -->", "",
        data["intro"], "",
        "| quantity | value | date | machine | commit | measured by |",
        "|---|---|---|---|---|---|", *rows, "",
        "Earlier values of each quantity: [history of the figures](history/figures.md).", ""])


def render_figure_history(data: dict) -> str:
    """docs/history/figures.md from the JSON: every earlier value of each quantity."""
    out = ["# History of the current figures", "",
           "<!-- generated from docs/current.json by rodphase.studytools.render_figure_history: "
           "do not edit -->", "",
           "Each quantity of [the current figures](../current.md) with the values it had "
           "before, newest first. Values before 2026-12-07 were collected from the dated "
           "pages of this history ([the old current.md](current-2026-12-06.md) lists them "
           "with their sources).", ""]
    for q in data["quantities"].values():
        out += [f"## {q['title']}", "", "| value | date | machine | commit | measured by |",
                "|---|---|---|---|---|"]
        for h in [q] + q.get("history", []):
            out.append(f"| {h['value']} | {h['date']} | {h['machine']} | `{h['commit']}` | "
                       f"{h['source']} |")
        out.append("")
    return "\n".join(out)


def write_current_pages(path: Path = CURRENT) -> None:
    """Re-render docs/current.md and docs/history/figures.md from `path`."""
    import json

    data = json.loads(Path(path).read_text())
    docs = Path(path).parent
    (docs / "current.md").write_text(render_current(data))
    (docs / "history" / "figures.md").write_text(render_figure_history(data))
