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

from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from . import config as C

# run_sweep and classify_file, not sweep and classify: those are the names of rodphase's own
# modules, which would replace the functions as package attributes once imported
__all__ = ["classify_file", "histories", "load", "load_sweep", "open", "run", "run_sweep",
           "table"]


def _overrides(overrides, settings: dict) -> list[tuple[str, Any]]:
    items: list[tuple[str, Any]] = []
    if overrides is None:
        pass
    elif isinstance(overrides, Mapping):
        items += [(str(k), v) for k, v in overrides.items()]
    elif isinstance(overrides, str):
        items.append(C.parse_override(overrides))
    elif isinstance(overrides, Iterable):
        for item in overrides:
            if isinstance(item, str):
                items.append(C.parse_override(item))
            elif isinstance(item, (tuple, list)) and len(item) == 2:
                items.append((str(item[0]), item[1]))
            else:
                raise C.ConfigError("overrides", item, 'a "key=value" string or a (key, value) pair')
    else:
        raise C.ConfigError("overrides", overrides,
                            'a dict, a "key=value" string, or a list of either or of pairs')
    items += [(key.replace("__", "."), value) for key, value in settings.items()]
    return items


def load(scene, overrides=None, **settings) -> C.Frozen:
    """A validated scene config: `scene` is a shipped scene's name, a YAML path, a plain dict
    (a scene mapping), or a config from an earlier load (then the overrides apply to it)."""
    from .scenes import SCENES

    items = _overrides(overrides, settings)
    if isinstance(scene, Mapping):
        plain = scene.plain() if isinstance(scene, C.Frozen) else dict(scene)
        return C.checked_initial_state(C.validate_scene(C.apply_overrides(plain, items), SCENES))
    return C.load_scene(str(scene), items, SCENES)


def load_sweep(sweep, overrides=None, **settings) -> tuple[C.Frozen, C.Frozen]:
    """(sweep, base scene) from a sweep file or a shipped sweep's name ("quick",
    "fig3_paper"). Keys under "sweep." change the sweep, all others the scene."""
    from .scenes import SCENES

    return C.load_sweep(sweep, _overrides(overrides, settings), SCENES)


def run(scene, overrides=None, **settings):
    """Simulate one scene (see `load` for the arguments) and return its RunResult. A run that
    goes unstable or does not settle comes back with that status; it does not raise."""
    from .runner import keep_snapshots, run_scene, snapshot_policy

    cfg = load(scene, overrides, **settings)
    return keep_snapshots(run_scene(cfg), snapshot_policy(cfg, "all"))


def run_sweep(sweep, output, overrides=None, *, jobs: int = 2, backend: str = "loky",
          scheduler: str | None = None, retry_failed: bool = False, replace: bool = False,
          progress: bool = False, **settings):
    """Run a sweep into the store `output` (resuming it), classify it, and return its table
    (one row per run: parameters, status, phase, alignment, Lk/Tw/Wr, ...). Runs that failed
    are in the table with their status. A scene registered at run time (a builder added to
    rodphase.scenes.SCENES in this session) is sent to the workers with the jobs."""
    from .sweep import run_sweep

    sweep_cfg, scene_cfg = load_sweep(sweep, overrides, **settings)
    Path(output).parent.mkdir(parents=True, exist_ok=True)
    report = run_sweep(sweep_cfg, scene_cfg, str(output), jobs=jobs, backend=backend,
                       scheduler=scheduler, retry_failed=retry_failed, replace=replace,
                       progress=progress, echo=lambda _: None)
    if report.stopped_by:
        raise KeyboardInterrupt(f"stopped by {report.stopped_by}; call again to go on")
    return classify_file(output)


def classify_file(path, **thresholds):
    """Classify every run of a store (epsilon, plectoneme_below, solenoid_above as in
    `rodphase classify`), store the classification, and return the whole table."""
    from .store import edit_store
    from .tabulate import classify_store

    with edit_store(path) as store:
        return classify_store(store, **thresholds)


def open(path):  # noqa: A001 - rodphase.open(path) reads as the user expects
    """The store at `path`, open for reading (use as a context manager): run_ids(),
    read_run(id) → RunResult, table(), histories(columns), attrs."""
    from .store import read_store

    return read_store(path)


def table(path):
    """The per-run table of a store (parameters, status, classification if stored)."""
    from .store import read_table

    return read_table(path)


def histories(path, columns=None, run_ids=None):
    """Every run's time history stacked in one long table (see Store.histories)."""
    from .store import read_histories

    return read_histories(path, columns, run_ids)
