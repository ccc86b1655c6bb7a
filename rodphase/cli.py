"""The rodphase command line: parse, call, report. No physics here.

Exit status: 0 success, 1 some runs failed (unstable / not converged / error), 2 bad input.
"""

from __future__ import annotations

import functools
import sys
import time
from collections import Counter
from pathlib import Path

import click

from ._version import __version__
from .config import (
    PACKAGE_CONFIGS,
    ConfigError,
    ResolutionWarning,
    config_hash,
    earlier_hashes,
    load_scene,
    load_sweep,
    make_output_folder,
    parse_override,
    read_yaml,
    resolve_sweep_path,
    stored_config,
    to_yaml,
)

FORCE_HELP = ("Replace OUTPUT if it holds another config's results (it is replaced when the "
              "first new run is stored, not before). With the same config it changes nothing: "
              "finished runs are kept and skipped.")
SET_HELP = ("Override any config value, repeatable: --set rod.elements=60 --set "
            "loading.twist_density=1.2 (sweep keys: --set sweep.samples=40). Units are the "
            "config's: m, s, Pa, N, turns/s.")


def reports_errors(func):
    """Bad input → 'error: key: value (allowed: ...)' on stderr, exit 2, no traceback."""

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        from .store import StoreError, StoreFull

        try:
            return func(*args, **kwargs)
        except StoreFull as exc:
            click.echo(f"error: {exc}. Every run stored before is intact: free some space and "
                       "run the same command to go on.", err=True)
            sys.exit(2)
        except (ConfigError, StoreError, FileNotFoundError, KeyError) as exc:
            # str(KeyError) quotes its message: print the message itself
            text = exc.args[0] if isinstance(exc, KeyError) and exc.args else exc
            click.echo(f"error: {text}", err=True)
            sys.exit(2)

    return wrapper


def _overrides(items) -> list:
    return [parse_override(item) for item in items]


def _has_runs(store, store_file) -> list[str]:
    """The store's run ids; a store without any is refused in one line."""
    ids = store.run_ids()
    if not ids:
        raise ConfigError(str(store_file), "no finished runs yet",
                            "a store with at least one run (a sweep killed before its first "
                            "run has none; run the same sweep command again)")
    return ids


def _check_run(store, store_file, run_id: str) -> str:
    """`run_id` if the store holds it, else the one-line error that lists what it holds."""
    ids = _has_runs(store, store_file)
    if run_id not in ids:
        shown = ", ".join(ids) if len(ids) <= 6 else f"{', '.join(ids[:3])}, ..., {ids[-1]}"
        raise ConfigError("--run", run_id, f"a run id of {store_file} ({len(ids)} stored: "
                            f"{shown})")
    return run_id


class _OneLineUsageErrors(click.Group):
    """Click's own refusals (a file that does not exist, an option it does not know, a
    missing value) in the form of every other bad input: one `error:` line on stderr naming
    what was wrong, exit status 2, no usage block."""

    def main(self, args=None, prog_name=None, complete_var=None, standalone_mode=True,
             **extra):
        if not standalone_mode:
            return super().main(args, prog_name, complete_var, False, **extra)
        try:
            code = super().main(args, prog_name, complete_var, False, **extra)
        except click.exceptions.NoArgsIsHelpError as exc:
            exc.show()  # `rodphase` alone: the help, as click shows it
            sys.exit(exc.exit_code)
        except click.UsageError as exc:
            command = exc.ctx.command_path if exc.ctx is not None else "rodphase"
            click.echo(f"error: {exc.format_message()} (see {command} --help)", err=True)
            sys.exit(exc.exit_code)
        except click.Abort:
            click.echo("Aborted!", err=True)
            sys.exit(1)
        sys.exit(code if isinstance(code, int) else 0)


def _warn_once_per_key() -> None:
    """Config warnings (rodphase.config.ResolutionWarning) as one 'warning:' line each on
    stderr, once per key: a sweep validates every sample, and 200 samples below the same
    resolution are one thing to say."""
    import warnings

    said: set[str] = set()

    def show(message, category, filename, lineno, file=None, line=None):
        if not issubclass(category, ResolutionWarning):
            return shown(message, category, filename, lineno, file, line)
        key = str(message).split(" ", 1)[0]
        if key not in said:
            said.add(key)
            click.echo(f"warning: {message}", err=True)

    shown = warnings.showwarning
    warnings.showwarning = show
    warnings.simplefilter("always", ResolutionWarning)


@click.group(cls=_OneLineUsageErrors, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="rodphase")
@click.option("-v", "--verbose", count=True,
              help="Log what happens to stderr: -v each stored run, merge and retry; -vv more.")
def main(verbose):
    """Shapes of stretched and twisted soft filaments: simulate, classify, map phases.

    A scene is one experiment (YAML); a sweep samples a scene over twist density Φa and
    extension L/L0 and writes every run to one HDF5 file, which `classify` labels
    (straight, plectoneme, solenoid, mixed) and `plot` draws.
    """
    _warn_once_per_key()
    if verbose:
        import logging

        logging.basicConfig(level=logging.INFO if verbose == 1 else logging.DEBUG,
                            format="%(asctime)s %(levelname)s %(name)s: %(message)s")


@main.command()
@click.argument("scene")
@click.option("-o", "--output", "output", required=True, type=click.Path(dir_okay=False),
              help="HDF5 file to write (created, or resumed if it holds the same config).")
@click.option("--set", "sets", multiple=True, metavar="KEY=VALUE", help=SET_HELP)
@click.option("--force", is_flag=True, help=FORCE_HELP)
@reports_errors
def run(scene, output, sets, force):
    """Run one SCENE (a YAML file or a shipped scene name, see `rodphase scenes`).

    \b
    Example:
      rodphase run twist_under_load -o run.h5 --set loading.twist_density=1.2
      rodphase run my_scene.yaml -o out/mine.h5 --set rod.elements=120
    """
    from .restart import checked_initial_state
    from .scenes import SCENES

    cfg = checked_initial_state(load_scene(scene, _overrides(sets), SCENES))
    from .runner import check_memory, keep_snapshots, run_scene, snapshot_policy
    from .store import open_store
    from .sweep import Interrupted, interruptible, stop_on_signals
    from .tabulate import classify_store

    check_memory(cfg)  # a run whose snapshots cannot fit is refused before it costs anything
    make_output_folder(output)
    existed = Path(output).exists()
    # the output is opened (locked, its config checked) before simulating: a run that cannot
    # be written is refused before it costs anything. Ctrl-C and SIGTERM stop it as they stop
    # a sweep (never inside the store's write), and say what was kept
    with stop_on_signals() as stop:
        try:
            with open_store(output, config_text=to_yaml(scene=cfg),
                            config_hash=config_hash(cfg), version=__version__, kind="run",
                            replace=force, earlier=earlier_hashes(cfg)) as store:
                from .runner import compile_kernel, cpu_seconds

                click.echo("Compiling the kernel (once; numba caches it on disk) ...")
                cpu = cpu_seconds()
                with interruptible():
                    wall = compile_kernel()  # kept out of the run's own timing
                click.echo(f"  ready in {wall:.1f} s (CPU {cpu_seconds() - cpu:.1f} s)")
                click.echo(f"Running {cfg.scene} ({cfg.rod.elements} elements) ...")
                started = time.perf_counter()
                with interruptible():
                    result = keep_snapshots(run_scene(cfg), snapshot_policy(cfg, "all"))
                store.write_run("run", {}, result, {"wall_time": result.diagnostics["wall_time"]})
                table = classify_store(store)
        except Interrupted:
            _stopped_run(output, existed, stop.signal_name,
                         time.perf_counter() - started if "started" in locals() else None)
    d = result.diagnostics
    click.echo(f"{result.status}: {result.message}")
    if d.get("dt_asleep") is not None and d.get("contact_woke_at") is None:
        steps = f"{d['steps']} steps of {d['dt_asleep']:.3g} s (contact never woke)"
    elif d.get("dt_asleep") is not None:
        steps = (f"{d['steps']} steps of {d['dt_asleep']:.3g} s, and of {d['dt']:.3g} s from "
                 f"contact's first touch at t = {d['contact_woke_at']:.3g} s,")
    else:
        steps = f"{d['steps']} steps of {d['dt']:.3g} s"
    click.echo(f"{steps} in {d['wall_time']:.1f} s ({d['us_per_step']:.1f} µs/step); "
               f"written to {output}")
    row = table.iloc[0]
    parts = [f"phase {row['phase']}", f"alignment {row['alignment']:.2f}"]
    for key in ("link", "twist", "writhe"):
        if key in row:
            parts.append(f"{key} {row[key]:.3f}")
    click.echo(", ".join(parts))
    escapes = _escapes_line(result)
    if escapes:
        click.echo(escapes)
    sys.exit(0 if result.ok else 1)


def _stopped_run(output, existed: bool, signal_name: str, seconds: float | None) -> None:
    """A run stopped by a signal: what was kept, how to go on; exit 128 + the signal's
    number, as a stopped sweep. A run is stored whole or not at all, so a store that this
    command made holds nothing and is removed."""
    import signal

    from .store import lock_path, parts_folder

    when = "while compiling" if seconds is None else f"after {seconds:.1f} s of the run"
    if existed:
        kept = f"{output} is as it was"
    else:
        for leftover in (Path(output), lock_path(output)):
            leftover.unlink(missing_ok=True)
        if parts_folder(output).is_dir() and not any(parts_folder(output).iterdir()):
            parts_folder(output).rmdir()
        kept = f"{output}, made by this command, was removed"
    click.echo(f"stopped by {signal_name} {when}: a run is stored only once it has finished, "
               f"so nothing was stored ({kept}); run the same command to start it again.",
               err=True)
    sys.exit(128 + signal.Signals[signal_name].value)


def _escapes_line(result) -> str:
    """'link -4.365 of -6.366 turns put in: +2.00 turns in 5 escapes (...)', or "" for a run
    that lost no link: the link alone does not say that some of it left the rod."""
    import numpy as np

    from .result import rotation_put_in

    h = result.history
    if "link_escapes" not in h or not len(h["link_escapes"]) or not h["link_escapes"][-1]:
        return ""
    turns = float(rotation_put_in(h)[-1] / (2 * np.pi))
    link = float(h["link"][-1])
    count = int(h["link_escapes"][-1])
    when = [n for n in result.diagnostics.get("notes", []) if n.startswith("link left")]
    detail = when[0][when[0].find("(ΔLk") :] if when and "(ΔLk" in when[0] else ""
    return (f"link {link:.3f} of {turns:.3f} turns put in: {link - turns:+.2f} turns in "
            f"{count} escape(s) past the ends {detail}").rstrip()


def _where_runs_go(command):
    """--jobs, --backend and --scheduler: the options of every command that runs a sweep."""
    for option in reversed([
            click.option("--jobs", "-j", default=2, show_default=True,
                         type=click.IntRange(1, 4096), help="Parallel workers (processes)."),
            click.option("--backend", type=click.Choice(["loky", "dask"]), default="loky",
                         show_default=True,
                         help="loky: processes on this machine; dask: a Dask cluster."),
            click.option("--scheduler", default=None, metavar="ADDRESS",
                         help="Dask scheduler address (tcp://host:8786); default: a local "
                         "cluster.")]):
        command = option(command)
    return command


@main.command()
@click.argument("sweep_file", metavar="SWEEP.yaml", type=click.Path(dir_okay=False))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False),
              help="HDF5 file; rerunning into it resumes and skips finished runs.")
@_where_runs_go
@click.option("--reconnect-timeout", default="120", show_default=True, metavar="SECONDS",
              help="Dask: how long to wait for a lost scheduler to answer again (then the runs "
              "in flight are sent again), or for a worker once every worker has left.")
@click.option("--retry-failed", is_flag=True, help="Run again the runs that failed before.")
@click.option("--set", "sets", multiple=True, metavar="KEY=VALUE", help=SET_HELP)
@click.option("--quiet", is_flag=True, help="No progress bar (none either when stderr is not a "
              "terminal).")
@click.option("--force", is_flag=True, help=FORCE_HELP)
@reports_errors
def sweep(sweep_file, output, jobs, backend, scheduler, reconnect_timeout, retry_failed, sets,
          quiet, force):
    """Run a sweep: sample the scene over its axes and simulate every sample.

    Every finished run is safe on disk as soon as it is counted: after Ctrl-C, SIGTERM, a
    kill or a full disk, the same command goes on where the sweep stopped.

    \b
    Example:
      rodphase sweep quick -o out/quick.h5 --jobs 2
      rodphase sweep fig3_paper -o fig3.h5 --set sweep.samples=400 --set rod.elements=120
      rodphase sweep fig3_paper -o fig3.h5 --backend dask --scheduler tcp://head:8786
    """
    from .restart import checked_initial_state
    from .runner import check_jobs_memory
    from .scenes import SCENES
    from .sweep import ClusterLost, plan, run_sweep

    sweep_cfg, scene_cfg = load_sweep(sweep_file, _overrides(sets), SCENES)
    if sweep_cfg.sampler == "boundaries":
        raise ConfigError("sweep.sampler", "boundaries", "a sampler of points; the boundaries "
                          "sampler places its runs by bracketing: rodphase boundaries")
    checked_initial_state(scene_cfg)
    check_jobs_memory(plan(sweep_cfg, scene_cfg), jobs)
    try:
        patience = float(reconnect_timeout)
    except ValueError:
        patience = reconnect_timeout  # refused by run_sweep, by name
    # run_sweep makes the output's folder, once nothing can refuse to start any more
    try:
        report = run_sweep(sweep_cfg, scene_cfg, output, jobs=jobs, backend=backend,
                           scheduler=scheduler, retry_failed=retry_failed, replace=force,
                           # a bar's carriage returns garble a log file (batch jobs, CI)
                           progress=not quiet and sys.stderr.isatty(), echo=click.echo,
                           reconnect_timeout=patience,
                           # without a terminal (nohup, CI), a line at a steady pace instead
                           lines=None if quiet or sys.stderr.isatty() else click.echo)
    except ClusterLost as exc:
        import shlex

        # the command as typed (`rodphase -v sweep ...` too); from elsewhere, in words
        again = shlex.join(["rodphase", *sys.argv[1:]]) if "sweep" in sys.argv[1:3] else (
            "the same rodphase sweep command")
        click.echo(f"stopped: {exc.what}; {exc.stored} of {exc.total} runs are stored in "
                   f"{output}; once the cluster is back, go on with: {again}", err=True)
        sys.exit(1)
    if report.stopped_by:
        import signal

        click.echo(f"stopped by {report.stopped_by}: {report.done + report.failed} run(s) "
                   f"finished and stored in {output} this time; run the same command to go "
                   "on from there.", err=True)
        sys.exit(128 + signal.Signals[report.stopped_by].value)
    by_status = Counter(status for _, status, _ in report.failures)
    counts = ", ".join(f"{n} {status}" for status, n in sorted(by_status.items())) or "0 failed"
    compiled = f" (+ {report.compile_time:.1f} s compiling)" if report.compile_time else ""
    this_time = "this time: " if report.skipped else ""
    click.echo(f"{this_time}{report.done} ok, {counts}, {report.skipped} skipped of "
               f"{report.total} in {report.wall:.1f} s{compiled}; written to {output}")
    failures = list(report.failures)
    if report.skipped:
        # a resumed sweep: the runs skipped count too (a failed one is skipped, not retried)
        stored, earlier = _stored_summary(output, {rid for rid, _, _ in failures})
        click.echo(stored)
        failures += earlier
        by_status.update(status for _, status, _ in earlier)
    for run_id, status, message in failures:
        click.echo(f"  {run_id}: {status}: {message}")
    if by_status.get("not_converged"):
        click.echo("  (a not_converged run keeps its final shape: it is classified, and its "
                   "status says the hold ran out of time)")
    if failures and report.skipped and not retry_failed:
        click.echo("  (failed runs are kept and skipped; --retry-failed runs them again)")
    if set(sweep_cfg.axes) == {"twist_density", "extension"} and not quiet:
        # the dots answer "what happened here"; the diagram's lines are another command's
        # (for Fig 3 in a quarter of the map's time: docs/explanation/performance.md)
        click.echo(f"the lines of this box (onset, plectoneme-solenoid boundary, triple point, "
                   f"each with its bracket): rodphase boundaries {sweep_file} -o LINES.h5")
    sys.exit(0 if not failures else 1)


def _stored_summary(output, listed: set[str]) -> tuple[str, list[tuple[str, str, str]]]:
    """'OUT holds N runs: 39 ok, 1 unstable' and the failed runs stored before (those not in
    `listed`), as (run id, status, message)."""
    from .store import read_store

    with read_store(output) as store:
        table = store.table()
    counts = Counter(table["status"]) if len(table) else Counter()
    earlier = [(str(row.run_id), str(row.status), str(row.message).splitlines()[-1]
                if str(row.message) else "") for row in table.itertuples()
               if row.status != "ok" and str(row.run_id) not in listed]
    text = ", ".join(f"{n} {status}" for status, n in sorted(counts.items())) or "no runs"
    return f"{output} holds {len(table)} runs: {text}", earlier


@main.command()
@click.argument("sweep_file", metavar="SWEEP.yaml", type=click.Path(dir_okay=False))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False),
              help="HDF5 file of the runs the trace places (an ordinary sweep store, with the "
              "boundaries kept under /boundaries); rerunning into it resumes.")
@click.option("--csv", "csv_path", type=click.Path(dir_okay=False),
              help="Also write the boundaries as CSV: one row per boundary point (kind, "
              "extension, twist_density and their brackets).")
@click.option("--only", type=click.Choice(["onset"]), default=None,
              help="onset: only the straight rod's onset line, from the model's static "
              "stability (seconds, no runs, nothing stored).")
@click.option("--tolerance", type=float, default=None,
              help="Width in L/L0 of a plectoneme-solenoid bracket [default 0.01: ±0.005].")
@click.option("--twist-tolerance", type=float, default=None,
              help="Width in Phi*a of the triple point's bracket [default 0.1: ±0.05].")
@click.option("--levels", type=int, default=None,
              help="Twist levels of the first round, spread over the box [default 6].")
@click.option("--hysteresis", is_flag=True,
              help="Also turn the end back: at loads along the onset, one run each twists "
              "past the onset, then back in holds, and gives the twist at which the rod comes "
              "back straight (rows 'restraighten'; timed apart).")
@_where_runs_go
@click.option("--set", "sets", multiple=True, metavar="KEY=VALUE", help=SET_HELP)
@click.option("--quiet", is_flag=True, help="No progress bar.")
@click.option("--force", is_flag=True, help=FORCE_HELP)
@reports_errors
def boundaries(sweep_file, output, csv_path, only, tolerance, twist_tolerance, levels,
               hysteresis, jobs, backend, scheduler, sets, quiet, force):
    """Trace the phase diagram's lines: the straight rod's onset, the plectoneme-solenoid
    boundary and the triple point, each with its bracket.

    The sweep's axes (twist_density Phi*a and extension L/L0) give the box, its scene and
    `set` the rod and protocol; its sampler and samples do not apply. The onset comes from
    the model's own stability (no dynamics); the boundary from runs of the scene's protocol
    placed by bisection along lines of constant twist, until each bracket is narrower than
    --tolerance in L/L0.

    \b
    Example:
      rodphase boundaries fig3_paper -o out/fig3_lines.h5 --csv out/fig3_lines.csv
      rodphase boundaries fig3_paper -o out/onset.h5 --only onset --set rod.radius=0.0125
    """
    from .boundaries import summary, sweep_for_boundaries, trace

    if hysteresis and only == "onset":
        raise click.UsageError("--hysteresis takes runs; --only onset makes none")
    settings = {"tolerance": tolerance, "twist_tolerance": twist_tolerance, "levels": levels}
    sweep_cfg, scene_cfg = sweep_for_boundaries(sweep_file, _overrides(sets), settings)
    found = trace(sweep_cfg, scene_cfg, output, only_onset=only == "onset",
                  hysteresis=hysteresis, jobs=jobs,
                  backend=backend, scheduler=scheduler, echo=click.echo, replace=force,
                  progress=not quiet and sys.stderr.isatty())
    for report in (found.report, found.hysteresis_report):
        if report is not None and report.stopped_by:
            import signal

            click.echo(f"stopped by {report.stopped_by}: the runs finished so far are "
                       f"stored in {output}; run the same command to go on.", err=True)
            sys.exit(128 + signal.Signals[report.stopped_by].value)
    click.echo(summary(found))
    if found.report is None:
        click.echo(f"onset line in {found.onset_seconds:.2f} CPU s (no runs)")
    else:
        r = found.report
        click.echo(f"{r.done} runs ok, {r.failed} failed, {r.skipped} reused of {r.total} in "
                   f"{r.wall:.1f} s; runs and boundaries in {output}")
        if found.hysteresis_report is not None:
            h = found.hysteresis_report
            click.echo(f"hysteresis: {h.done} holds ok, {h.failed} failed, {h.skipped} reused "
                       f"of {h.total} in {h.wall:.1f} s (timed apart)")
    if csv_path:
        make_output_folder(csv_path)
        found.table.to_csv(csv_path, index=False, float_format="%.10g")
        click.echo(f"boundaries: {csv_path}")


@main.command()
@click.argument("store_file", metavar="OUT.h5", type=click.Path(exists=True, dir_okay=False))
@click.option("--csv", "csv_path", type=click.Path(dir_okay=False), help="Also write the table as CSV.")
@click.option("--epsilon", default=0.2, show_default=True, type=click.FloatRange(0, 10),
              help="Contact tolerance ε: partners closer than (2+ε)·a count.")
@click.option("--plectoneme-below", default=-0.5, show_default=True, type=float,
              help="Alignment below this is a plectoneme.")
@click.option("--solenoid-above", default=0.5, show_default=True, type=float,
              help="Alignment above this is a solenoid (between: mixed).")
@click.option("--separation", default=5.0, show_default=True, type=click.FloatRange(0, 50),
              help="Partner separation in rest radii of arc: elements closer along the rod "
                   "are never partners. 5 is the paper's; a coil whose turns are shorter "
                   "(the tightest solenoids above L/L0 ≈ 1.165) reads as straight with it, "
                   "and e.g. 4 sees it.")
@reports_errors
def classify(store_file, csv_path, epsilon, plectoneme_below, solenoid_above, separation):
    """Label every run of OUT.h5 by loop alignment and store the table back into it.

    \b
    Example:
      rodphase classify out/quick.h5 --csv out/quick.csv
      rodphase classify out/quick.h5 --epsilon 0.3 --solenoid-above 0.6
    """
    from .store import StoreBusy, edit_store, read_store, write_table_csv
    from .tabulate import classify_store, classify_table

    thresholds = dict(epsilon=epsilon, plectoneme_below=plectoneme_below,
                      solenoid_above=solenoid_above, separation=separation)
    try:
        store = edit_store(store_file)
        busy = None
    except StoreBusy as exc:
        # a sweep is still writing it: classify what has finished, but leave the file to it
        store, busy = read_store(store_file), exc
    with store:
        _has_runs(store, store_file)
        table = (store.table(classify_table(store, **thresholds)) if busy else
                 classify_store(store, **thresholds))
    if busy:
        click.echo(f"note: {busy}; the table below covers the runs finished so far and is not "
                   "stored in the file (classify again when the sweep has ended)", err=True)
    counts = table["phase"].value_counts().to_dict()
    click.echo(f"{len(table)} runs: " + ", ".join(f"{k} {v}" for k, v in sorted(counts.items())))
    if csv_path:
        make_output_folder(csv_path)
        write_table_csv(table, csv_path)
        click.echo(f"table written to {csv_path} (units and meanings of its columns in "
                   f"{csv_path}-metadata.json)")


@main.command()
@click.argument("store_file", metavar="OUT.h5", type=click.Path(exists=True, dir_okay=False))
@click.option("--kind", type=click.Choice(["phase", "topology", "force", "response", "shape", "hat",
                                           "path"]),
              default="phase", show_default=True,
              help="phase: Φa vs L/L0 map; topology: Lk/Tw/Wr vs Φa; force: end force vs "
              "displacement; response: ΔU, ΔWr, ΔTw vs a modulus or radius ramp; shape: "
              "final rod shapes; hat: extension and torque vs turns (scene hat_curve); path: "
              "each run's protocol as a line through the (L/L0, Φa) plane, marked by phase.")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False),
              help="Figure file; its suffix picks the format: .png, .pdf, .svg (any that "
              "matplotlib writes).")
@click.option("--run", "run_id", default=None,
              help="Run id for topology/force/response/hat/shape/path (default: the first; "
              "see `rodphase classify`).")
@click.option("--experiments", type=click.Path(exists=True, dir_okay=False),
              help="CSV of experimental points (twist_density, extension, kind) to overlay.")
@click.option("--twist", type=click.Choice(["rest", "current"]), default="rest", show_default=True,
              help="Phase map twist axis (vertical; L/L0 is horizontal): rest = the paper's "
              "Φa = θ·a0/L0 (end rotation θ, rest radius a0, rest length L0); current = Φa of "
              "the stretched straight rod, θ·(a0/√e)/(e·L0) = rest Φa / e^1.5.")
@click.option("--background", type=click.Path(exists=True, dir_okay=False),
              help="With --kind path: a classified sweep file drawn faintly behind the paths.")
@click.option("--size", default=None, metavar="column|page|W,H",
              help="Phase map size: a journal's single column (3.4 in wide), full page width "
                   "(7 in), or width,height in inches.")
@click.option("--caption/--no-caption", default=True, show_default=True,
              help="Phase map: a line under it with the sweep's parameters and run counts.")
@click.option("--theory/--no-theory", default=True, show_default=True,
              help="Phase map: the straight rod's buckling twist along L/L0, the model's own "
                   "(from its stiffness, at the sweep's resolution), the sheared and the unsheared "
                   "clamped Greenhill twist (for a rod clamped at both ends under an end load), "
                   "and the boundaries `rodphase boundaries` traced into the store (the "
                   "plectoneme-solenoid line with its bracket, the triple point).")
@reports_errors
def plot(store_file, kind, output, run_id, experiments, twist, background, size, caption,
         theory):
    """Draw a figure from OUT.h5.

    \b
    Example:
      rodphase plot out/quick.h5 --kind phase --size column -o phase.pdf
      rodphase plot out/quick.h5 --kind topology --run run-00003 -o lk.png
    """
    make_output_folder(output)
    if size is not None and size not in ("column", "page"):
        try:
            width, height = (float(v) for v in size.split(","))
            size = (width, height)
        except ValueError:
            raise ConfigError("--size", size, "column, page, or width,height in inches "
                                "(e.g. 3.4,3)") from None
    try:
        _draw(store_file, kind, output, run_id, experiments, twist, background, size, caption,
              theory)
    except ConfigError:
        raise  # already names what was given and what is allowed
    except ValueError as exc:
        # a figure that this file's data cannot make (say why, no traceback)
        raise ConfigError(f"--kind {kind}", store_file, str(exc)) from None
    click.echo(f"written {output}")


def _classified_table(store, ids: list[str]):
    """The store's table with a phase for every run: the runs that the stored classification
    lacks (a store not classified yet, or still being written by a sweep) are classified
    here with the default thresholds, for this figure only (the file is not changed)."""
    import pandas as pd

    from .tabulate import classify_table

    stored = store.classification()
    have = set() if stored is None else set(stored["run_id"].astype(str)) & set(ids)
    missing = [rid for rid in ids if rid not in have]
    if not missing:
        return store.table()
    fresh = classify_table(store, run_ids=missing)
    kept = None if stored is None else stored[stored["run_id"].astype(str).isin(have)]
    both = fresh if kept is None or kept.empty else pd.concat([kept, fresh], ignore_index=True)
    click.echo(f"note: {len(missing)} of {len(ids)} runs classified for this figure only (not "
               "stored; `rodphase classify` stores them once no sweep writes the file)",
               err=True)
    return store.table(both)


def _run_with_history(store, ids: list[str]) -> str:
    """The first run whose history has two rows or more (a curve to draw), else the first:
    straight runs started on their equilibrium may settle at their first row."""
    for rid in ids:
        if len(store.histories(columns=["time"], run_ids=[rid])) >= 2:
            return rid
    return ids[0]


def _draw(store_file, kind, output, run_id, experiments, twist, background, size, caption,
          theory=True):
    import pandas as pd

    from . import plot as plots
    from .store import read_store

    with read_store(store_file) as store:
        ids = _has_runs(store, store_file)
        if run_id is not None:
            _check_run(store, store_file, run_id)
        if kind == "phase":
            table = _classified_table(store, ids)
            exp = pd.read_csv(experiments) if experiments else None
            column = "phi_a_current" if twist == "current" else (
                "twist_density" if "twist_density" in table else "phi_a_rest")
            config = stored_config(store.attrs.get("config_yaml", ""))
            text = plots.sweep_caption(config, table) if caption else None
            lines = None
            if theory and "extension" in table and table["extension"].notna().any():
                from .tabulate import onset_lines

                e = table["extension"].astype(float)
                # 13 points (an onset each): phase_map draws a spline through them
                lines = onset_lines(config, [e.min() + (e.max() - e.min()) * i / 12
                                             for i in range(13)])
            traced = store.boundaries() if theory else None
            plots.phase_map(table, output, experiments=exp, twist=column, caption=text,
                            size=size, onset=lines, lines=traced)
        elif kind == "path":
            from .tabulate import path_table

            ids = [run_id] if run_id else ids[:6]
            paths = {}
            for rid in ids:
                result = store.read_run(rid)
                every = max(1, len(result.history["time"]) // 300)
                paths[rid] = path_table(result, every=every)
            behind = None
            if background:
                with read_store(background) as other:
                    behind = _classified_table(other, _has_runs(other, background))
            plots.phase_path(paths, output, background=behind)
        elif kind == "shape":
            table = store.table()
            ids = [run_id] if run_id else plots.shape_panels(table)
            shapes = []
            for rid in ids:
                result = store.read_run(rid)
                shapes.append((plots.run_label(table.set_index("run_id").loc[rid]),
                               result.positions, result.rest_radius))
            plots.shape_grid(shapes, output)
        else:
            rid = run_id or _run_with_history(store, ids)
            result = store.read_run(rid)
            if kind in ("topology", "force") and len(result.history["time"]) < 2:
                raise ConfigError("--run", rid, "a run with a history of two rows or more "
                                    f"to draw its {kind} curves: this one has one row (a run "
                                    "started on its straight equilibrium that settled at once)")
            params = plots.params_text(store.run_params(rid))
            if kind == "topology":
                plots.topology_curves(result, output, title=f"{rid}: {params}" if params else rid)
            elif kind == "hat":
                plots.hat_curve(result, output)
            elif kind == "response":
                plots.control_response(result, output)
            else:
                plots.force_displacement(result.history, output)


@main.command()
@click.argument("store_file", metavar="OUT.h5", type=click.Path(exists=True, dir_okay=False))
@click.option("--run", "run_id", required=True, help="Run id (see `rodphase classify`).")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False),
              help="Movie file: .gif, or .mp4 when ffmpeg is installed.")
@click.option("--fps", default=10, show_default=True, type=click.IntRange(1, 120))
@click.option("--height", default=None, type=click.FloatRange(0.5, 20),
              help="Picture height in inches at 150 dpi (default: about 3).")
@reports_errors
def movie(store_file, run_id, output, fps, height):
    """Animate one run's snapshots (3D rod), frames labelled with time and Φa.

    \b
    Example:
      rodphase movie run.h5 --run run -o run.gif --fps 20
      rodphase movie out/quick.h5 --run run-00003 -o rod.mp4 --height 4   # needs ffmpeg
    """
    import shutil

    from . import plot as plots
    from .store import read_store

    if Path(output).suffix.lower() != ".gif" and shutil.which("ffmpeg") is None:
        # writing a GIF under another name (or beside it) would surprise: say it instead
        raise ConfigError("--output", output, "a .gif file, or an .mp4 once ffmpeg is "
                            "installed (apt install ffmpeg, conda install ffmpeg)")
    with read_store(store_file) as store:
        result = store.read_run(_check_run(store, store_file, run_id))
    if len(result.snapshot_positions) < 2:
        raise ConfigError("--run", run_id, "a run with two snapshots or more to animate: "
                            f"this one kept {len(result.snapshot_positions)} (a sweep keeps the "
                            "final state only; run it with --set output.snapshots=all)")
    make_output_folder(output)
    from .analysis import twist_density

    h = result.history
    rows = result.snapshot_history_rows
    phi_a = twist_density(result)[rows] if "end_rotation" in h else None
    path = plots.movie(result.snapshot_positions, result.rest_radius, output, fps=fps,
                   times=h["time"][rows], twist_density=phi_a, height=height)
    click.echo(f"written {path}")


@main.command()
@click.argument("store_file", metavar="OUT.h5", type=click.Path(exists=True, dir_okay=False))
@click.option("--run", "run_id", required=True, help="Run id (see `rodphase classify`).")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False),
              help="VTK file (.vtk); with --snapshots the stem of a numbered series.")
@click.option("--snapshots", is_flag=True, help="Every stored snapshot, one file each.")
@reports_errors
def export(store_file, run_id, output, snapshots):
    """Write a run's rod as VTK polydata for ParaView, VisIt or PyVista (a Tube filter on the
    point data `radius` renders it as a shaded tube of its real thickness).

    \b
    Example:
      rodphase export out/quick.h5 --run run-00003 -o rod.vtk
      rodphase export run.h5 --run run --snapshots -o frames/rod   # frames/rod_0000.vtk ...
    """
    from .export import write_vtk, write_vtk_series
    from .store import read_store

    make_output_folder(output)
    with read_store(store_file) as store:
        result = store.read_run(_check_run(store, store_file, run_id))
    if snapshots:
        written = write_vtk_series(output, result.snapshot_positions, result.radii)
        click.echo(f"written {len(written)} files {written[0]} ... {written[-1]}"
                   if written else "the run has no snapshots")
    else:
        click.echo(f"written {write_vtk(output, result.positions, result.radii, title=run_id)}")


@main.command()
@click.argument("name", metavar="SCENE_OR_SWEEP")
@click.option("--set", "sets", multiple=True, metavar="KEY=VALUE", help=SET_HELP)
@reports_errors
def config(name, sets):
    """Print the resolved config (defaults filled in, overrides applied) as YAML.

    \b
    Example:
      rodphase config twist_under_load --set rod.elements=60
      rodphase config quick --set sweep.samples=40
    """
    from .restart import checked_initial_state
    from .scenes import SCENES

    try:
        path = resolve_sweep_path(name)
        is_sweep = "sweep" in read_yaml(path)
    except ConfigError:
        is_sweep = False
    overrides = _overrides(sets)
    if is_sweep:
        from .config import Frozen

        sweep_cfg, scene_cfg = load_sweep(path, overrides, SCENES)
        checked_initial_state(scene_cfg)
        click.echo(_origins(sweep_cfg["set"], overrides), nl=False)
        # a value of sweep.set that --set replaces is shown once, where it is in force
        replaced = {k for k, _ in overrides if not k.startswith("sweep.")}
        shown = Frozen({**sweep_cfg, "set": Frozen(
            {k: v for k, v in sweep_cfg["set"].items() if k not in replaced})})
        click.echo(to_yaml(sweep=shown, scene=scene_cfg), nl=False)
    else:
        scene_cfg = checked_initial_state(load_scene(name, overrides, SCENES))
        click.echo(_origins({}, overrides), nl=False)
        click.echo(to_yaml(scene=scene_cfg), nl=False)


def _origins(sweep_set, overrides) -> str:
    """YAML comments saying which scene values come from sweep.set and --set, rather than
    from the scene file or the defaults ("" if none do)."""
    lines = []
    given = dict(overrides)
    for key, value in sweep_set.items():
        if key in given:
            lines.append(f"#   {key}: {given[key]!r} from --set (replacing sweep.set's "
                         f"{value!r})")
        else:
            lines.append(f"#   {key}: {value!r} from sweep.set")
    lines += [f"#   {key}: {value!r} from --set" for key, value in given.items()
              if key not in sweep_set]
    if not lines:
        return ""
    return "# set on top of the config files (their other values are the files' or defaults):\n" + (
        "\n".join(lines) + "\n")


@main.command()
def scenes():
    """List the shipped scenes and sweeps (usable by name in run, sweep and config).

    \b
    Example:
      rodphase scenes
      rodphase config fig2b_solenoid    # one of them, resolved
    """
    import shutil
    import textwrap

    import yaml

    root = PACKAGE_CONFIGS
    width = max(shutil.get_terminal_size((100, 24)).columns, 60)
    for path in sorted((root / "scenes").glob("*.yaml")) + sorted(root.glob("*.yaml")):
        data = yaml.safe_load(path.read_text()) or {}
        text = data.get("description") or (data.get("sweep") or {}).get("description", "")
        if not text:
            text = _first_sentence(path.read_text())
        name = f"{str(path.relative_to(root)):40s} "
        # wrapped, not cut: a sweep's description is the first sentence of its comment
        click.echo(textwrap.fill(text, width=width - 1, initial_indent=name,
                                 subsequent_indent=" " * len(name)) if text else name.rstrip())


def _first_sentence(yaml_text: str) -> str:
    """The first sentence of a YAML file's leading comment block (its lines joined)."""
    import re

    lines = []
    for line in yaml_text.splitlines():
        if not line.startswith("#"):
            break
        lines.append(line[1:].strip())
    block = " ".join(part for part in lines if part)
    found = re.match(r"(.+?[.!?])(\s|$)", block)
    return found.group(1) if found else block


if __name__ == "__main__":
    main(prog_name="rodphase")  # `python -m rodphase.cli` speaks of itself as the command
