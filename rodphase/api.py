"""rodphase from Python: the few calls a notebook needs, the same paths the CLI takes.

    import rodphase
    cfg = rodphase.load("twist_under_load", {"rod.elements": 60}, loading__twist_density=1.2)
    result = rodphase.run(cfg)                       # a RunResult: positions (n+1, 3), history, ...
    table = rodphase.run_sweep("quick", "out/quick.h5", sweep__samples=8)   # classified table
    with rodphase.open("out/quick.h5") as store:     # read (safe while a sweep writes it)
        shape = store.read_run("run-00003").positions

Overrides come as a dict {"rod.elements": 60}, as "key=value" strings (as `--set` takes
them), as (key, value) pairs, or as keywords with "__" for the dots (rod__elements=60); they
are applied in that order. Units are the config's: m, s, Pa, N, turns/s. A top-level key
goes in as itself: rodphase.run(cfg, initial_state="out/run.h5#run") starts from that stored
run's final state (see rodphase.restart).
"""

from __future__ import annotations

import os
import sys
import threading
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from . import config

# run_sweep and classify_file, not sweep and classify: those are the names of rodphase's own
# modules, which would replace the functions as package attributes once imported
__all__ = ["classify_file", "histories", "load", "load_sweep", "open", "run", "run_sweep",
           "table", "trace_boundaries"]


def _overrides(overrides, settings: dict) -> list[tuple[str, Any]]:
    items: list[tuple[str, Any]] = []
    if overrides is None:
        pass
    elif isinstance(overrides, Mapping):
        items += [(str(k), v) for k, v in overrides.items()]
    elif isinstance(overrides, str):
        items.append(config.parse_override(overrides))
    elif isinstance(overrides, Iterable):
        for item in overrides:
            if isinstance(item, str):
                items.append(config.parse_override(item))
            elif isinstance(item, (tuple, list)) and len(item) == 2:
                items.append((str(item[0]), item[1]))
            else:
                raise config.ConfigError("overrides", item, 'a "key=value" string or a (key, value) pair')
    else:
        raise config.ConfigError("overrides", overrides,
                            'a dict, a "key=value" string, or a list of either or of pairs')
    items += [(key.replace("__", "."), value) for key, value in settings.items()]
    return items


def load(scene, overrides=None, **settings) -> config.Frozen:
    """A validated scene config, every default filled in.

    Parameters
    ----------
    scene : str, path, mapping or Frozen
        A shipped scene's name (``rodphase scenes`` lists them), a YAML path, a plain dict
        (a scene mapping), or a config from an earlier load (the overrides then apply to it).
    overrides : dict, str, or iterable of (key, value) or "key=value", optional
        Config values to change, by dotted key: ``{"rod.elements": 60}``.
    **settings
        More overrides as keywords, ``__`` for the dots: ``rod__elements=60``.

    Returns
    -------
    Frozen
        The read-only config, sections as attributes (``cfg.rod.elements``).

    Raises
    ------
    ConfigError
        A bad key or value, naming the key, the value and what is allowed.
    """
    from .restart import checked_initial_state
    from .scenes import SCENES

    items = _overrides(overrides, settings)
    if isinstance(scene, Mapping):
        plain = scene.plain() if isinstance(scene, config.Frozen) else dict(scene)
        return checked_initial_state(config.validate_scene(config.apply_overrides(plain, items), SCENES))
    return checked_initial_state(config.load_scene(str(scene), items, SCENES))


def load_sweep(sweep, overrides=None, **settings) -> tuple[config.Frozen, config.Frozen]:
    """A validated sweep and the scene it samples.

    Parameters
    ----------
    sweep : str or path
        A sweep YAML or a shipped sweep's name (``"quick"``, ``"fig3_paper"``).
    overrides, **settings
        As for `load`; keys under ``sweep.`` change the sweep, all others the scene.

    Returns
    -------
    tuple of (Frozen, Frozen)
        The sweep section and the base scene config.
    """
    from .restart import checked_initial_state
    from .scenes import SCENES

    sweep_cfg, scene_cfg = config.load_sweep(sweep, _overrides(overrides, settings), SCENES)
    return sweep_cfg, checked_initial_state(scene_cfg)


def _say(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def interactive() -> bool:
    """Whether a person watches: a Python prompt, a Jupyter/IPython kernel, or a terminal."""
    return (hasattr(sys, "ps1") or "ipykernel" in sys.modules
            or bool(getattr(sys.stderr, "isatty", lambda: False)()))


_warm = False
# a kernel loaded from numba's disk cache is ready in about half a second; longer is a compile
COMPILE_NOTICE_AFTER = 1.5  # s


def _warm_kernel(say=_say) -> None:
    """Compile the kernel (or load it from numba's cache) once per process, announcing it
    when it takes long, as the CLI does: a first run on a new machine is otherwise silent for
    about a minute."""
    global _warm
    if _warm:
        return
    from .runner import compile_kernel

    timer = threading.Timer(COMPILE_NOTICE_AFTER, say, ["Compiling the kernel (once; numba "
                                                        "caches it on disk) ..."])
    timer.daemon = True
    timer.start()
    try:
        seconds = compile_kernel()
    finally:
        timer.cancel()
    if seconds > COMPILE_NOTICE_AFTER:
        say(f"  ready in {seconds:.1f} s")
    _warm = True


def run(scene, overrides=None, **settings):
    """Simulate one scene.

    A run that goes unstable or does not settle comes back with that status; it does not
    raise. The first call compiles the kernel, and says so when that takes long.

    Parameters
    ----------
    scene, overrides, **settings
        As for `load`. A top-level key goes in as itself:
        ``initial_state="out/run.h5#run"`` starts from that stored run's final state.

    Returns
    -------
    RunResult
        The final state (``positions`` (n+1, 3) in m, ``directors``, ``radii``), the
        ``history`` (a dict of columns; ``history_frame`` as a DataFrame), the snapshots,
        ``status`` (``ok``, ``unstable``, ``not_converged``, ``error``), ``message`` and
        ``diagnostics``.

    Raises
    ------
    ConfigError
        A bad config, or snapshots (``output.history_interval``) that would not fit in
        memory; refused before anything runs.
    """
    from .runner import check_memory, keep_snapshots, run_scene, snapshot_policy

    cfg = load(scene, overrides, **settings)
    check_memory(cfg)
    _warm_kernel()
    return keep_snapshots(run_scene(cfg), snapshot_policy(cfg, "all"))


def run_sweep(sweep, output, overrides=None, *, jobs: int | None = None, backend: str = "loky",
              scheduler: str | None = None, retry_failed: bool = False, replace: bool = False,
              progress: bool | None = None, **settings):
    """Run a sweep into a store (resuming it), classify it, and return its table.

    Runs that failed are in the table with their status. A scene registered at run time (a
    builder added to ``rodphase.scenes.SCENES`` in this session) is sent to the workers with
    the jobs.

    Parameters
    ----------
    sweep, overrides, **settings
        As for `load_sweep`.
    output : str or path
        The HDF5 store; a store of the same config is resumed (finished runs skipped).
    jobs : int, optional
        Parallel workers; default this machine's cores.
    backend : {"loky", "dask"}
        Local processes, or a Dask cluster (``scheduler``; a local one without it).
    scheduler : str, optional
        A Dask scheduler's address, ``tcp://host:8786``.
    retry_failed : bool
        Run again the runs stored as failed.
    replace : bool
        Replace an `output` that holds another config's runs (once the first new run is
        stored); without it such a store raises StoreMismatch.
    progress : bool, optional
        A progress bar and the CLI's messages on stderr; default on in an interactive
        session, a notebook or a terminal.

    Returns
    -------
    pandas.DataFrame
        One row per run: the sampled parameters, ``status``, ``message``, ``alignment``,
        ``phase``, final ``link``, ``twist``, ``writhe`` and more (columns and units:
        the HDF5 format's table).

    Raises
    ------
    StoreMismatch
        `output` holds another config's runs and `replace` is false.
    KeyboardInterrupt
        The sweep was stopped by a signal; call again to go on.
    """
    from .runner import check_jobs_memory
    from .store import StoreMismatch
    from .sweep import plan, run_sweep

    sweep_cfg, scene_cfg = load_sweep(sweep, overrides, **settings)
    jobs = max(1, os.cpu_count() or 1) if jobs is None else int(jobs)
    progress = interactive() if progress is None else bool(progress)
    check_jobs_memory(plan(sweep_cfg, scene_cfg), jobs)
    Path(output).parent.mkdir(parents=True, exist_ok=True)
    try:
        report = run_sweep(sweep_cfg, scene_cfg, str(output), jobs=jobs, backend=backend,
                           scheduler=scheduler, retry_failed=retry_failed, replace=replace,
                           progress=progress, echo=_say if progress else lambda _: None)
    except StoreMismatch as exc:
        # the store speaks the CLI's words; from Python the switch is a keyword
        raise type(exc)(str(exc).replace("--force", "replace=True")) from None
    if report.stopped_by:
        raise KeyboardInterrupt(f"stopped by {report.stopped_by}; call again to go on")
    return classify_file(output)


def trace_boundaries(sweep, output=None, overrides=None, *, only_onset: bool = False,
               hysteresis: bool = False, tolerance: float | None = None,
               twist_tolerance: float | None = None, levels: int | None = None,
               jobs: int | None = None, backend: str = "loky", scheduler: str | None = None,
               replace: bool = False, progress: bool | None = None, **settings):
    """The phase diagram's lines for a sweep's box: the straight rod's onset, the
    plectoneme–solenoid boundary and the triple point, each with its bracket (as
    ``rodphase boundaries``; see rodphase.boundaries).

    Parameters
    ----------
    sweep, overrides, **settings
        As for `load_sweep`; the sweep's axes must be twist_density and extension.
    output : str or path, optional
        The HDF5 store of the runs the trace places (resumed like any sweep); not needed
        with `only_onset`.
    only_onset : bool
        Only the onset line, from the model's static stability: no runs, nothing stored.
    hysteresis : bool
        Also the return runs: at loads along the onset, twisted past it and back in holds;
        ``restraighten`` rows give where the rod comes straight again.
    tolerance, twist_tolerance, levels : optional
        The width in L/L0 of a plectoneme–solenoid bracket (0.01), the width in Φa of the
        triple point's (0.1), the twist levels of the first round (6).
    jobs, backend, scheduler, replace, progress
        As for `run_sweep`.

    Returns
    -------
    pandas.DataFrame
        One row per boundary point: ``kind`` (onset, plectoneme_solenoid, triple_point,
        restraighten),
        ``extension``, ``twist_density``, their brackets ``extension_low``/``_high`` and
        ``twist_density_low``/``_high``, and flags (rodphase.boundaries.COLUMNS);
        ``attrs["claims"]``: the onset's slope and intercept at high extension with their
        errors, and the extension from which solenoids win.
    """
    from .boundaries import sweep_for_boundaries, trace

    chosen = {"tolerance": tolerance, "twist_tolerance": twist_tolerance, "levels": levels}
    sweep_cfg, scene_cfg = sweep_for_boundaries(sweep, _overrides(overrides, settings), chosen)
    if not only_onset and output is None:
        raise config.ConfigError("output", None, "a store path for the runs (or only_onset)")
    if only_onset and hysteresis:
        raise config.ConfigError("hysteresis", True, "False with only_onset (it makes runs; "
                                 "only_onset makes none)")
    jobs = max(1, os.cpu_count() or 1) if jobs is None else int(jobs)
    progress = interactive() if progress is None else bool(progress)
    if output is not None:
        Path(output).parent.mkdir(parents=True, exist_ok=True)
    found = trace(sweep_cfg, scene_cfg, None if output is None else str(output),
                  only_onset=only_onset, hysteresis=hysteresis, jobs=jobs,
                  backend=backend, scheduler=scheduler,
                  progress=progress, echo=_say if progress else lambda _: None,
                  replace=replace)
    for report in (found.report, found.hysteresis_report):
        if report is not None and report.stopped_by:
            raise KeyboardInterrupt(f"stopped by {report.stopped_by}; call again to go on")
    found.table.attrs["claims"] = found.claims
    return found.table


def classify_file(path, **thresholds):
    """Classify every run of a store and store the classification in it.

    Parameters
    ----------
    path : str or path
        The store.
    **thresholds
        ``epsilon`` (0.2), ``plectoneme_below`` (−0.5), ``solenoid_above`` (0.5),
        ``separation`` (5 rest radii): as the options of ``rodphase classify``.

    Returns
    -------
    pandas.DataFrame
        The whole table, one row per run, with ``alignment`` and ``phase``.
    """
    from .store import edit_store
    from .tabulate import classify_store

    with edit_store(path) as store:
        return classify_store(store, **thresholds)


def open(path):  # noqa: A001 - rodphase.open(path) reads as the user expects
    """Open a store for reading; safe while a sweep writes it.

    Parameters
    ----------
    path : str or path
        The store.

    Returns
    -------
    Store
        Use as a context manager: ``run_ids()``, ``read_run(id)`` → RunResult, ``table()``,
        ``histories(columns)``, ``attrs``.
    """
    from .store import read_store

    return read_store(path)


def table(path):
    """The per-run table of a store.

    Parameters
    ----------
    path : str or path
        The store.

    Returns
    -------
    pandas.DataFrame
        One row per run: parameters, status, timings, and the classification if stored.
    """
    from .store import read_table

    return read_table(path)


def histories(path, columns=None, run_ids=None):
    """Every run's time history, stacked in one long table.

    Parameters
    ----------
    path : str or path
        The store.
    columns : list of str, optional
        History columns to read; default all (a run lacking one gets NaN).
    run_ids : list of str, optional
        Runs to read; default all.

    Returns
    -------
    pandas.DataFrame
        One row per (run, history row), with ``run_id``, the run's parameters and status,
        and the history columns.
    """
    from .store import read_histories

    return read_histories(path, columns, run_ids)
