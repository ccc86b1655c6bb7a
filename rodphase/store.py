"""The HDF5 layout of rodphase results, all of it in this one module (plain h5py, no physics).

One file holds one sweep (or one run): the resolved config and its hash as file attributes,
one group per finished run under /runs, and an optional per-run classification table under
/classification. docs/data-format.md describes every name and unit so that the file can be
read without rodphase.

Only the parent process writes. A run is written into /partial/<run_id> and moved to
/runs/<run_id> when complete, then the file is flushed, so /runs never holds half a run and a
killed sweep resumes from `done_ids()`.
"""

from __future__ import annotations

import json
import math
from datetime import datetime, timezone
from pathlib import Path

import h5py
import numpy as np
import pandas as pd

from .result import RunResult

FORMAT = "rodphase-store"
FORMAT_VERSION = 1
KINDS = ("sweep", "run")
FAILED = ("unstable", "not_converged")
PARTIAL = "partial"  # runs being written live here until complete
PARAM_PREFIX = "param_"
TIMING_PREFIX = "timing_"


class StoreMismatch(Exception):
    """The file exists but holds results of a different config."""


def _json_default(value):
    # numpy scalars and arrays end up in diagnostics; JSON only knows Python types
    if isinstance(value, (np.generic, np.ndarray)):
        return value.tolist()
    raise TypeError(f"diagnostics value {value!r} of type {type(value).__name__} "
                    "is not JSON-serialisable")


def _plain(value):
    """h5py attribute value → Python scalar (or list)."""
    if isinstance(value, bytes):
        return value.decode()
    if isinstance(value, (np.generic, np.ndarray)):
        return value.tolist()
    return value


def _check_id(run_id: str) -> str:
    if not run_id or "/" in run_id or run_id in (".", ".."):
        raise ValueError(f"run_id {run_id!r} cannot be an HDF5 group name: use a non-empty "
                         "name without '/'")
    return run_id


def _write_array(group: h5py.Group, name: str, data, *, per_snapshot: bool = False):
    data = np.asarray(data)
    if per_snapshot and data.size:
        # one chunk per snapshot: a movie frame is one chunk read, and gzip pays off on
        # slowly varying rods
        group.create_dataset(name, data=data, chunks=(1,) + data.shape[1:],
                             compression="gzip", compression_opts=4, shuffle=True)
    else:
        group.create_dataset(name, data=data)


def _replace(parent: h5py.Group, source: str, target: str):
    if target in parent:
        del parent[target]
    parent.move(source, target)
    partial = parent.file[PARTIAL]
    if not len(partial):  # keep the file tidy for readers: /partial only exists mid-write
        del parent.file[PARTIAL]


class Store:
    """An open rodphase HDF5 file. Use `open_store` (write) or `read_store` (read only)."""

    def __init__(self, file: h5py.File):
        self.file = file

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        if self.file.id.valid:
            self.file.close()

    @property
    def path(self) -> Path:
        return Path(self.file.filename)

    @property
    def attrs(self) -> dict:
        """File attributes: rodphase_version, kind, config_yaml, config_hash, created, ..."""
        return {k: _plain(v) for k, v in self.file.attrs.items()}

    # --- runs -----------------------------------------------------------------------------

    def write_run(self, run_id: str, params: dict, result: RunResult, timings: dict) -> None:
        """Write one run whole (replacing any earlier run of that id) and flush."""
        _check_id(run_id)
        diagnostics = json.dumps(result.diagnostics, default=_json_default)  # fail before writing
        partial = self.file.require_group(PARTIAL)
        if run_id in partial:  # left by a crash
            del partial[run_id]
        g = partial.create_group(run_id)

        for name, value in params.items():
            g.attrs[PARAM_PREFIX + name] = value
        g.attrs["status"] = result.status
        g.attrs["message"] = result.message
        g.attrs["diagnostics"] = diagnostics
        g.attrs["stage_ends"] = np.asarray(result.stage_ends, dtype=np.int64)
        for name, value in timings.items():
            g.attrs[TIMING_PREFIX + name] = (value if isinstance(value, (int, float, str, np.number))
                                             else json.dumps(value, default=_json_default))
        # wall time and steps as plain attributes: the table reads them for every run
        diag = result.diagnostics
        g.attrs["wall_time"] = float(timings.get("wall_time", diag.get("wall_time", math.nan)))
        g.attrs["steps"] = int(timings.get("steps", diag.get("steps", -1)))

        _write_array(g, "positions", result.positions)
        _write_array(g, "directors", result.directors)
        _write_array(g, "radii", result.radii)
        _write_array(g, "rest_lengths", result.rest_lengths)
        history = g.create_group("history", track_order=True)
        for name, column in result.history.items():
            _write_array(history, name, column)
        history.attrs["columns"] = list(result.history)
        snapshots = g.create_group("snapshots")
        _write_array(snapshots, "positions", result.snapshot_positions, per_snapshot=True)
        _write_array(snapshots, "d1", result.snapshot_d1, per_snapshot=True)

        # the move is one link change: the run appears under its final name complete or not at all
        _replace(self.file.require_group("runs"), f"/{PARTIAL}/{run_id}", run_id)
        self.file.flush()

    def run_ids(self) -> list[str]:
        return list(self.file["runs"]) if "runs" in self.file else []

    def done_ids(self, include_failed: bool = False) -> set[str]:
        """Runs to skip on resume: status "ok", and with include_failed also failed runs."""
        wanted = ("ok",) + (FAILED if include_failed else ())
        runs = self.file.get("runs", {})
        return {rid for rid in self.run_ids() if _plain(runs[rid].attrs["status"]) in wanted}

    def _run(self, run_id: str) -> h5py.Group:
        runs = self.file.get("runs", {})
        if run_id not in runs:
            raise KeyError(f"no run {run_id!r} in {self.path} ({len(runs)} runs stored)")
        return runs[run_id]

    def run_params(self, run_id: str) -> dict:
        g = self._run(run_id)
        return {k[len(PARAM_PREFIX):]: _plain(v) for k, v in g.attrs.items()
                if k.startswith(PARAM_PREFIX)}

    def run_timings(self, run_id: str) -> dict:
        g = self._run(run_id)
        return {k[len(TIMING_PREFIX):]: _plain(v) for k, v in g.attrs.items()
                if k.startswith(TIMING_PREFIX)}

    def read_run(self, run_id: str) -> RunResult:
        g = self._run(run_id)
        history = g["history"]
        columns = [_plain(c) for c in history.attrs.get("columns", list(history))]
        return RunResult(
            status=_plain(g.attrs["status"]),
            message=_plain(g.attrs["message"]),
            positions=g["positions"][()],
            directors=g["directors"][()],
            radii=g["radii"][()],
            rest_lengths=g["rest_lengths"][()],
            history={name: history[name][()] for name in columns},
            snapshot_positions=g["snapshots/positions"][()],
            snapshot_d1=g["snapshots/d1"][()],
            diagnostics=json.loads(_plain(g.attrs["diagnostics"])),
            stage_ends=[int(i) for i in g.attrs["stage_ends"]],
        )

    # --- tables ---------------------------------------------------------------------------

    def write_classification(self, df: pd.DataFrame) -> None:
        """Store a per-run table (must have a run_id column), replacing any earlier one.

        One 1-D dataset per column under /classification, in column order (also listed in
        its "columns" attribute). Numbers and booleans keep their dtype (pandas nullable
        integers become float with NaN); everything else is stored as UTF-8 strings, with
        missing values as "".
        """
        if "run_id" not in df.columns:
            raise ValueError(f"classification table needs a run_id column; it has "
                             f"{list(df.columns)}")
        tmp = f"/{PARTIAL}/classification"
        partial = self.file.require_group(PARTIAL)
        if "classification" in partial:
            del partial["classification"]
        g = partial.create_group("classification", track_order=True)
        for name in df.columns:
            g.create_dataset(str(name), data=_column_array(df[name]))
        g.attrs["columns"] = [str(c) for c in df.columns]
        _replace(self.file, tmp, "classification")
        self.file.flush()

    def classification(self) -> pd.DataFrame | None:
        if "classification" not in self.file:
            return None
        g = self.file["classification"]
        columns = [_plain(c) for c in g.attrs.get("columns", list(g))]
        data = {}
        for name in columns:
            ds = g[name]
            data[name] = ds.asstr()[()] if h5py.check_string_dtype(ds.dtype) else ds[()]
        return pd.DataFrame(data)

    def table(self) -> pd.DataFrame:
        """One row per run: run_id, params, status, message, wall_time, steps, and the
        classification columns if any (a column already present gets the suffix
        "_classified")."""
        runs = self.file.get("runs", {})
        rows = []
        for rid in self.run_ids():
            a = runs[rid].attrs
            row = {"run_id": rid}
            row.update(self.run_params(rid))
            row.update(status=_plain(a["status"]), message=_plain(a["message"]),
                       wall_time=float(a["wall_time"]), steps=int(a["steps"]))
            rows.append(row)
        table = pd.DataFrame(rows, columns=None if rows else
                             ["run_id", "status", "message", "wall_time", "steps"])
        classified = self.classification()
        if classified is not None:
            classified = classified.astype({"run_id": str})
            table = table.merge(classified, on="run_id", how="left",
                                suffixes=("", "_classified"))
        return table


def _column_array(column: pd.Series) -> np.ndarray:
    if pd.api.types.is_bool_dtype(column) and not column.hasnans:
        return column.to_numpy(dtype=bool)
    if pd.api.types.is_numeric_dtype(column) and not pd.api.types.is_bool_dtype(column):
        if column.hasnans or pd.api.types.is_float_dtype(column):
            return column.to_numpy(dtype=np.float64, na_value=np.nan)
        return column.to_numpy(dtype=np.int64)
    text = ["" if pd.isna(v) else str(v) for v in column]
    return np.array(text, dtype=h5py.string_dtype())


def open_store(path, *, config_text: str, config_hash: str, version: str, kind: str) -> Store:
    """Create the store at `path`, or open it to add runs if it holds the same config.

    Raises StoreMismatch if the file holds results of a config with another hash.
    """
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
    file = h5py.File(path, "a")
    held = _plain(file.attrs.get("config_hash"))
    if held is None and len(file):
        file.close()
        raise StoreMismatch(f"{path} is an HDF5 file but not a rodphase store (no config_hash "
                            "attribute); use another output file or --force to overwrite it")
    if held is not None and held != config_hash:
        file.close()
        raise StoreMismatch(f"{path} holds results of a different config (stored hash {held}, "
                            f"this config {config_hash}); use another output file, or --force "
                            "to overwrite it")
    if held is None:
        file.attrs.update(format=FORMAT, format_version=FORMAT_VERSION, rodphase_version=version,
                          kind=kind, config_yaml=config_text, config_hash=config_hash,
                          created=datetime.now(timezone.utc).isoformat(timespec="seconds"))
        file.require_group("runs")
    if PARTIAL in file:
        # only one process writes a store: anything partial is left by a killed writer
        del file[PARTIAL]
    file.flush()
    return Store(file)


class NotAStore(StoreMismatch):
    """The file is not a rodphase store: not HDF5 at all, or HDF5 from another program."""


def read_store(path) -> Store:
    """Open an existing store read-only; NotAStore if `path` is not a rodphase store."""
    return _open_existing(path, "r")


def edit_store(path) -> Store:
    """Open an existing store to add its classification; NotAStore if it is not one."""
    return _open_existing(path, "r+")


def _open_existing(path, mode: str) -> Store:
    try:
        file = h5py.File(path, mode)
    except OSError as exc:
        reason = str(exc).split("(")[-1].rstrip(")") if "(" in str(exc) else str(exc)
        raise NotAStore(f"{path} cannot be read as HDF5 ({reason}): give a file written by "
                        "rodphase run or rodphase sweep") from None
    if _plain(file.attrs.get("format")) != FORMAT or "runs" not in file:
        file.close()
        raise NotAStore(f"{path} is an HDF5 file but not a rodphase store (no format "
                        f"'{FORMAT}' attribute or /runs group): give a file written by "
                        "rodphase run or rodphase sweep")
    return Store(file)


def read_table(path) -> pd.DataFrame:
    """The per-run table of the store at `path` (see Store.table)."""
    with read_store(path) as store:
        return store.table()


def write_table_csv(table, path) -> Path:
    """Write a per-run table (a DataFrame, or the path of a store) as CSV; return the path."""
    if not isinstance(table, pd.DataFrame):
        table = read_table(table)
    path = Path(path)
    table.to_csv(path, index=False, float_format="%.10g")
    return path
