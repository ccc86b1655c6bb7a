"""The rodphase result store: its HDF5 layout and how it is written safely, all in this module.

A store is one HDF5 file, OUT.h5, holding one sweep (or one run): the resolved config and its
hash as file attributes, one group per finished run under /runs, and an optional per-run
classification table under /classification. docs/reference/data-format.md describes every name and
unit so that the file can be read with h5py or pandas alone.

Crash safety rests on one rule: OUT.h5 is never modified in place.
- A finished run goes into a small file of its own in the folder OUT.h5.parts/, written under
  a temporary name, flushed to disk and renamed: when write_run returns, the run is durable,
  whatever kills the process next.
- Parts are merged into OUT.h5 by writing a new copy beside it and renaming it over the old one
  (rename is atomic on POSIX file systems); then the merged parts are deleted. A new
  classification table is stored the same way.
So a kill at any instant (SIGKILL, OOM, power cut after the data reached the disk) leaves
OUT.h5 whole, old or new, and every finished run in it or in a part. Readers see both and can
follow a running sweep; the next writer merges what it finds. A full disk fails a write before
the rename, so nothing already stored is touched.

One writer per store, enforced here by an advisory lock on OUT.h5.lock (flock: the kernel
drops it with the process, so a killed writer leaves no stale lock), independent of HDF5's
own file locking, which clusters often switch off (HDF5_USE_FILE_LOCKING=FALSE).
"""

from __future__ import annotations

import contextlib
import errno
import io
import json
import logging
import math
import os
import shutil
import socket
from collections.abc import Iterator
from datetime import datetime, timezone
from pathlib import Path

import h5py
import numpy as np
import pandas as pd

try:
    import fcntl
except ImportError:  # Windows: the lock falls back to a file created exclusively
    fcntl = None

from .result import RunResult, history_unit

log = logging.getLogger(__name__)

FORMAT = "rodphase-store"
FORMAT_VERSION = 2  # 2: runs arrive through OUT.h5.parts/; the file's own layout is that of 1
READABLE_VERSIONS = (1, 2)
KINDS = ("sweep", "run")
FAILED = ("unstable", "not_converged")
PARAM_PREFIX = "param_"
TIMING_PREFIX = "timing_"
PARTS_SUFFIX = ".parts"
LOCK_SUFFIX = ".lock"
# Parts are merged into the main file once this many have gathered (and when the writer
# closes). Each merge copies the main file once, so a sweep of N runs copies it about
# N / MERGE_EVERY times; between merges, readers open one small file per unmerged run.
MERGE_EVERY = 200
# what a write fails with when the disk, the quota or the file-size limit is reached
_NO_SPACE = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)
_NO_SPACE_TEXT = ("No space left", "errno = 28", "Disk quota", "File too large", "errno = 27")


class StoreError(Exception):
    """A store that cannot be used as asked; the message says why and what to do."""


class StoreMismatch(StoreError):
    """The file exists but holds results of a different config."""


class NotAStore(StoreMismatch):
    """The file is not a rodphase store: not HDF5, HDF5 from another program, or a layout
    that rodphase never writes (links, external storage, undecodable attributes)."""


class StoreBusy(StoreError):
    """Another process is writing this store."""


class StoreFull(StoreError):
    """The disk (or quota) is full: nothing already stored was touched."""


# ----------------------------------------------------------------------------- small pieces

def parts_folder(path) -> Path:
    """Where finished runs wait to be merged into the store at `path`."""
    return Path(f"{path}{PARTS_SUFFIX}")


def lock_path(path) -> Path:
    return Path(f"{path}{LOCK_SUFFIX}")


def _json_default(value):
    # numpy scalars and arrays end up in diagnostics; JSON only knows Python types
    if isinstance(value, (np.generic, np.ndarray)):
        return value.tolist()
    raise TypeError(f"diagnostics value {value!r} of type {type(value).__name__} "
                    "is not JSON-serialisable")


def _plain(value, where: str = "attribute"):
    """h5py attribute value → Python scalar (or list). Raises NotAStore for values rodphase
    never writes (opaque bytes such as a pickle, text that is not UTF-8)."""
    if isinstance(value, np.void) or (isinstance(value, np.ndarray) and value.dtype.kind == "V"):
        raise NotAStore(f"{where} holds opaque binary data (rodphase writes only numbers and "
                        "UTF-8 text): not a file written by rodphase")
    if isinstance(value, bytes):
        try:
            return value.decode()
        except UnicodeDecodeError:
            raise NotAStore(f"{where} is not UTF-8 text: not a file written by rodphase") from None
    if isinstance(value, (np.generic, np.ndarray)):
        return value.tolist()
    return value


def _check_shapes(g: h5py.Group) -> None:
    """The final state's arrays are numbers of the shapes rodphase writes (n elements):
    ValueError naming the first that is not (a damaged file, or another program's)."""
    n = g["rest_lengths"].shape[0] if g["rest_lengths"].ndim == 1 else -1
    expected = {"positions": (n + 1, 3), "directors": (n, 3, 3), "radii": (n,),
                "rest_lengths": (n,)}
    for name, shape in expected.items():
        data = g[name]
        if data.shape != shape or data.dtype.kind not in "fiu":
            raise ValueError(f"{name} is {data.dtype} of shape {data.shape}, not numbers of "
                             f"shape {shape}")


def _check_id(run_id: str) -> str:
    if not run_id or "/" in run_id or run_id in (".", "..") or run_id.startswith("."):
        raise ValueError(f"run_id {run_id!r} cannot be a run name: use a non-empty name "
                         "without '/' that does not start with '.'")
    return run_id


def _no_space(exc: BaseException) -> bool:
    if isinstance(exc, OSError) and exc.errno in _NO_SPACE:
        return True
    return isinstance(exc, (OSError, RuntimeError)) and any(t in str(exc) for t in _NO_SPACE_TEXT)


def _fsync(path: Path) -> None:
    # a directory is fsynced so that the rename itself reaches the disk
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    except OSError as exc:  # some file systems refuse fsync on a directory
        if exc.errno not in (errno.EINVAL, errno.EBADF):
            raise
    finally:
        os.close(fd)


def _temporary_name(target: Path) -> Path:
    return target.with_name(f".{target.name}.{os.getpid()}.tmp")


@contextlib.contextmanager
def _written_aside(target: Path) -> Iterator[Path]:
    """Yield a temporary path beside `target`; once the caller has written and closed it,
    flush it to disk and rename it over `target`. On any failure the temporary file is
    removed and `target` is as it was; a full disk becomes StoreFull."""
    tmp = _temporary_name(target)
    try:
        yield tmp
        _fsync(tmp)
        os.replace(tmp, target)
        _fsync(target.parent)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            tmp.unlink()
        if _no_space(exc):
            raise StoreFull(f"the disk is full (or a quota or file-size limit was reached) "
                            f"writing {target}: {_short(exc)}") from None
        raise


def _short(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    return text[:200]


def _in_memory() -> h5py.File:
    """A new HDF5 file built in memory (its bytes: `.id.get_file_image()` after flush).

    HDF5 does not survive a full disk: a failed write of compressed chunks crashed the
    process (segfault, double free) in tests on a full tmpfs. So rodphase never lets HDF5
    write where the disk may run out: small files are built in memory and written out by
    Python, whose errors are clean; large rewrites get their space reserved first."""
    return h5py.File(io.BytesIO(), "w")


def _write_image(file: h5py.File, target: Path) -> None:
    """Write an in-memory HDF5 file to `target`, aside and renamed into place."""
    file.flush()
    image = file.id.get_file_image()
    file.close()
    with _written_aside(target) as tmp:
        with open(tmp, "wb") as out:
            out.write(image)


def _reserve(path: Path, size: int) -> None:
    """Allocate `size` bytes for `path` now, so that HDF5's later writes up to that size
    cannot meet a full disk (HDF5 trims the file to its real end when it closes it)."""
    if hasattr(os, "posix_fallocate"):
        fd = os.open(path, os.O_RDWR)
        try:
            os.posix_fallocate(fd, 0, size)
        finally:
            os.close(fd)
        return
    with open(path, "r+b") as fh:  # macOS, Windows: write the zeros (a sparse seek reserves nothing)
        fh.seek(0, os.SEEK_END)
        while fh.tell() < size:
            fh.write(bytes(min(1 << 20, size - fh.tell())))


def _h5(path, mode: str) -> h5py.File:
    # The main file is never written in place (see the module docstring), so HDF5's own
    # locks add nothing and would make a reader fail while a sweep merges.
    try:
        return h5py.File(path, mode, locking=False)
    except OSError as exc:
        if "locking flag values don't match" not in str(exc):
            raise
        # the file is open elsewhere in this process with HDF5's default locking (xarray
        # keeps the files it opened open), and HDF5 refuses a second open with other flags
        return h5py.File(path, mode)


def _check_layout(file: h5py.File, where: str) -> None:
    """Refuse what rodphase never writes and what would make it read elsewhere on the disk:
    soft and external links, external or virtual dataset storage."""
    problems = []

    def visit(name, link):
        if isinstance(link, (h5py.ExternalLink, h5py.SoftLink)):
            kind = "an external link" if isinstance(link, h5py.ExternalLink) else "a soft link"
            problems.append(f"{name} is {kind}")
            return 1  # stop at the first
        obj = file.get(name)
        if isinstance(obj, h5py.Dataset) and (obj.external or obj.is_virtual):
            problems.append(f"{name} keeps its data outside the file")
            return 1
        return None

    file.visititems_links(visit)
    if problems:
        raise NotAStore(f"{where}: {problems[0]}, which rodphase never writes: refusing to "
                        "follow it (a file from elsewhere could make rodphase read other files)")


# ----------------------------------------------------------------------------- writer lock

def _holder() -> bytes:
    since = datetime.now(timezone.utc).isoformat(timespec="seconds")
    return f"pid {os.getpid()} on {socket.gethostname()} since {since}\n".encode()


class _WriterLock:
    """An advisory lock on OUT.h5.lock, held for as long as a writer has the store open."""

    def __init__(self, store_path: Path):
        self.store_path = store_path
        self.path = lock_path(store_path)
        self.fd: int | None = None

    def acquire(self) -> _WriterLock:
        if fcntl is None:
            return self._acquire_exclusive()
        while True:
            try:
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            except OSError as exc:
                raise StoreError(f"cannot write {self.store_path}: {exc.strerror} "
                                 f"({self.path})") from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                with open(self.path, errors="replace") as fh:
                    holder = fh.read(200).strip() or "unknown"
                os.close(fd)
                raise StoreBusy(f"{self.store_path} is being written by another rodphase "
                                f"process ({holder}): wait until it ends, or write to another "
                                "output") from None
            except OSError as exc:
                os.close(fd)
                raise StoreError(f"cannot lock {self.path} ({exc.strerror}): this file system "
                                 "offers no file locks; write the output to one that does "
                                 "(a local or scratch disk)") from None
            # the previous holder unlinks the file as it releases it: a lock taken on the
            # unlinked file would not exclude the next process, so check it is still the file
            try:
                same = os.fstat(fd).st_ino == os.stat(self.path).st_ino
            except FileNotFoundError:
                same = False
            if same:
                break
            os.close(fd)
        os.ftruncate(fd, 0)
        os.write(fd, _holder())
        self.fd = fd
        return self

    def _acquire_exclusive(self) -> _WriterLock:
        # without flock a lock file outlives a killed writer: the message says so
        try:
            self.fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_EXCL, 0o644)
        except FileExistsError:
            holder = self.path.read_text(errors="replace").strip() or "unknown"
            raise StoreBusy(f"{self.store_path} is being written by another rodphase process "
                            f"({holder}); if that process no longer runs, delete "
                            f"{self.path}") from None
        os.write(self.fd, _holder())
        return self

    def release(self) -> None:
        if self.fd is None:
            return
        with contextlib.suppress(OSError):
            self.path.unlink()
        os.close(self.fd)
        self.fd = None


# ----------------------------------------------------------------------------- the store

class Store:
    """An open rodphase store: OUT.h5 and its unmerged parts, read as one.

    Use `read_store` to read (safe while a sweep writes it), `open_store` to add runs, and
    `edit_store` to store a classification; the last two take the store's writer lock."""

    def __init__(self, path, *, lock: _WriterLock | None = None,
                 new_attrs: dict | None = None, replace: bool = False):
        self._path = Path(path)
        self._lock = lock
        self._new_attrs = new_attrs  # the file attributes a writer gives a new main file
        self._replace = replace  # the main file holds another config: ignore it, replace it
        self.file: h5py.File | None = None
        self._parts: dict[str, Path] = {}
        self._foreign_parts: list[Path] = []  # another config's, deleted when replacing
        self._refresh()

    # --- opening and closing -------------------------------------------------------------

    def __enter__(self):
        return self

    def __repr__(self) -> str:
        if self.file is None and not self.writable:
            return f"<rodphase Store {str(self._path)!r}: closed>"
        mode = "open for writing" if self.writable else "read-only"
        kind = self.attrs.get("kind", "?")
        classified = self.file is not None and "classification" in self.file
        return (f"<rodphase Store {str(self._path)!r} ({mode}): {kind}, "
                f"{len(self.run_ids())} run(s), "
                f"{'classified' if classified else 'not classified'}>")

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Close; a writer first merges its parts (if that fails, they stay, still durable)."""
        try:
            if self.writable:
                self.merge()
        finally:
            self._close_main()
            if self._lock is not None:
                self._lock.release()
                self._lock = None

    @property
    def path(self) -> Path:
        return self._path

    @property
    def writable(self) -> bool:
        return self._lock is not None and self._lock.fd is not None

    @property
    def attrs(self) -> dict:
        """File attributes: rodphase_version, kind, config_yaml, config_hash, created, ..."""
        if self.file is None:
            return dict(self._new_attrs or {})
        with self._damaged("its file attributes"):
            return {k: _plain(v, f"{self._path}: file attribute {k}")
                    for k, v in self.file.attrs.items()}

    def _close_main(self) -> None:
        if self.file is not None and self.file.id.valid:
            self.file.close()
        self.file = None

    def _refresh(self, check: bool = True) -> None:
        """(Re)open the main file and list the parts that belong to it. check=False: the
        main file is one this writer just made from checked files, and is not checked for
        foreign links again (a walk over every object of the file: seconds at 2,000 runs)."""
        self._close_main()
        if not self._replace and self._path.exists():
            self.file = _open_main(self._path, check)
        wanted = self.attrs.get("config_hash")
        self._parts, self._foreign_parts = {}, []
        folder = parts_folder(self._path)
        if not folder.is_dir():
            return
        for part in sorted(folder.glob("*.h5")):
            if part.name.startswith("."):
                continue  # a temporary file: a run still being written (or a killed writer's)
            try:
                with _h5(part, "r") as f:
                    _check_layout(f, str(part))
                    held = _plain(f.attrs.get("config_hash"), f"{part}: config_hash")
            except FileNotFoundError:
                continue  # merged and deleted since the listing
            except OSError as exc:
                if self.writable:
                    raise NotAStore(f"{part} cannot be read as HDF5 ({_short(exc)}): it is "
                                    "not one of rodphase's run files; move it away") from None
                continue
            if held != wanted:
                if self._replace:
                    self._foreign_parts.append(part)
                    continue
                if self.writable:
                    raise StoreMismatch(
                        f"{folder} holds runs of another config (hash {held}, this config "
                        f"{wanted}); use another output file, or --force to replace them")
                continue  # a reader shows the runs of the main file's config only
            self._parts[part.stem] = part

    # --- runs -----------------------------------------------------------------------------

    @contextlib.contextmanager
    def _run_group(self, run_id: str) -> Iterator[h5py.Group]:
        part = self._parts.get(run_id)
        if part is not None:
            try:
                f = _h5(part, "r")
            except FileNotFoundError:
                f = None
                self._refresh()  # merged by the writer since we listed it: it is in the main file
            if f is not None:
                with f, self._damaged(f"run {run_id}"):
                    yield f["runs"][run_id]
                return
        runs = self.file["runs"] if self.file is not None else {}
        if run_id not in runs:
            raise KeyError(f"no run {run_id!r} in {self._path} ({len(self.run_ids())} runs "
                           "stored)")
        with self._damaged(f"run {run_id}"):
            yield runs[run_id]

    @contextlib.contextmanager
    def _damaged(self, what: str) -> Iterator[None]:
        """What reading `what` meets in a damaged file or one laid out by another program (a
        member or attribute missing or of another type, a bit flipped) as NotAStore, one
        line naming the file, instead of h5py's, json's or numpy's own exception."""
        try:
            yield
        except (KeyError, TypeError, ValueError, IndexError, OSError, AttributeError,
                RuntimeError) as exc:  # h5py raises RuntimeError for a broken B-tree
            raise NotAStore(f"{self._path}: {what} cannot be read ({type(exc).__name__}: "
                            f"{_short(exc)}): the file is damaged or was not written by "
                            "rodphase") from None

    def run_ids(self) -> list[str]:
        with self._damaged("its list of runs"):
            merged = list(self.file["runs"]) if self.file is not None else []
        return sorted(set(merged) | set(self._parts))

    def _status(self, run_id: str) -> str:
        with self._run_group(run_id) as g:
            return _plain(g.attrs["status"], f"{self._path}: run {run_id} status")

    def done_ids(self, include_failed: bool = False) -> set[str]:
        """Runs to skip on resume: status "ok", and with include_failed also failed runs."""
        wanted = ("ok",) + (FAILED if include_failed else ())
        return {rid for rid in self.run_ids() if self._status(rid) in wanted}

    def run_params(self, run_id: str) -> dict:
        with self._run_group(run_id) as g:
            return self._prefixed(g, run_id, PARAM_PREFIX)

    def run_timings(self, run_id: str) -> dict:
        with self._run_group(run_id) as g:
            return self._prefixed(g, run_id, TIMING_PREFIX)

    def _prefixed(self, g: h5py.Group, run_id: str, prefix: str) -> dict:
        return {k[len(prefix):]: _plain(v, f"{self._path}: run {run_id} attribute {k}")
                for k, v in g.attrs.items() if k.startswith(prefix)}

    def read_run(self, run_id: str, snapshots: bool = True) -> RunResult:
        """One stored run. With snapshots=False its snapshots are left on disk (empty arrays
        of the right shape), to read a final state cheaply."""
        with self._run_group(run_id) as g:
            where = f"{self._path}: run {run_id}"
            history = g["history"]
            columns = [_plain(c, where) for c in history.attrs.get("columns", list(history))]
            picked = slice(None) if snapshots else slice(0, 0)
            _check_shapes(g)
            return RunResult(
                status=_plain(g.attrs["status"], where),
                message=_plain(g.attrs["message"], f"{where} message"),
                positions=g["positions"][()],
                directors=g["directors"][()],
                radii=g["radii"][()],
                rest_lengths=g["rest_lengths"][()],
                history={name: history[name][()] for name in columns},
                snapshot_positions=g["snapshots/positions"][picked],
                snapshot_d1=g["snapshots/d1"][picked],
                diagnostics=json.loads(_plain(g.attrs["diagnostics"], f"{where} diagnostics")),
                stage_ends=[int(i) for i in g.attrs["stage_ends"]],
                # files before the snapshot policy kept one snapshot per history row
                snapshot_rows=(g["snapshots/rows"][picked] if "rows" in g["snapshots"]
                               else None if snapshots else np.zeros(0, dtype=np.int64)),
                **{name: g[name][()] if name in g else None for name in RESTART_ARRAYS},
            )

    def write_run(self, run_id: str, params: dict, result: RunResult, timings: dict) -> None:
        """Make one finished run durable (replacing any earlier run of that id): when this
        returns, the run survives a kill of this process."""
        self._need_writer()
        self.write_part(run_id, run_image(run_id, params, result, timings,
                                          self.attrs["config_hash"]))

    def write_part(self, run_id: str, image: bytes) -> None:
        """Make one finished run durable from its part file as run_image built it (in a
        worker, say: the parent then only writes bytes). When this returns, the run
        survives a kill of this process."""
        self._need_writer()
        _check_id(run_id)
        folder = parts_folder(self._path)
        try:
            folder.mkdir(exist_ok=True)
        except OSError as exc:
            if _no_space(exc):
                raise StoreFull(f"the disk is full writing {folder}: {_short(exc)}") from None
            raise
        target = folder / f"{run_id}.h5"
        with _written_aside(target) as tmp:
            with open(tmp, "wb") as out:
                out.write(image)
        self._parts[run_id] = target
        if self._replace or len(self._parts) >= MERGE_EVERY:
            # replacing another config's file: do it at the first run, not before (a sweep
            # that fails before it has a run leaves the old file as it was)
            self.merge()

    def merge(self) -> None:
        """Merge the parts into the main file: write a new main file beside it, rename it
        over the old one, then delete the merged parts."""
        self._need_writer()
        if not self._parts and not self._replace and self.file is not None:
            return
        if (not self._parts and self._replace and self._path.exists()
                and not _is_empty_hdf5(self._path)):
            return  # another config's store goes when the first new run comes, not before
        parts = dict(self._parts)
        # a copied run takes about its part's size again (data and metadata); twice that
        # leaves room for HDF5's own bookkeeping
        growth = 2 * sum(p.stat().st_size for p in parts.values()) + (1 << 18)
        try:
            with self._rewritten(growth) as f:
                runs = f.require_group("runs")
                replaced = [rid for rid in parts if rid in runs]
                for run_id in replaced:
                    del runs[run_id]
                for run_id, part in sorted(parts.items()):
                    with _h5(part, "r") as src:
                        f.copy(src["runs"][run_id], runs, name=run_id)
                    # a part has no dimension scales (an older one has them, pointing at
                    # the part file's addresses): label the copy's dimensions here
                    _name_dimensions(runs[run_id])
                if replaced and "classification" in f:
                    # a classification describes the runs it saw: rows of replaced runs go
                    table = _read_classification(f["classification"])
                    units = _classification_units(f["classification"])
                    _write_classification(f, table[~table["run_id"].astype(str).isin(replaced)],
                                          units)
        except BaseException:
            self._refresh()
            raise
        self._replace = False
        if parts:
            log.info("merged %d run(s) into %s", len(parts), self._path)
        for part in list(parts.values()) + self._foreign_parts:
            with contextlib.suppress(OSError):
                part.unlink()
        with contextlib.suppress(OSError):
            parts_folder(self._path).rmdir()  # only if empty
        self._refresh(check=False)

    @contextlib.contextmanager
    def _rewritten(self, growth: int) -> Iterator[h5py.File]:
        """A writable copy of the main file (a new one when replacing), renamed over the main
        file once the caller is done with it; `growth` bytes are reserved for what the caller
        adds (see _in_memory for why)."""
        copy_from = None if (self._replace or self.file is None) else self._path
        self._close_main()
        if copy_from is None:  # a new file: built in memory, written out whole
            f = _in_memory()
            try:
                f.attrs.update(self._new_attrs)
                f.create_group("runs")
                yield f
                _write_image(f, self._path)
            finally:
                f.close()
            return
        with _written_aside(self._path) as tmp:
            shutil.copyfile(copy_from, tmp)
            _reserve(tmp, tmp.stat().st_size + growth)
            with _h5(tmp, "r+") as f:
                yield f

    def _need_writer(self) -> None:
        if not self.writable:
            raise StoreError(f"{self._path} is open for reading only")

    def histories(self, columns=None, run_ids=None) -> pd.DataFrame:
        """The time histories of many runs stacked in one long table, ready for groupby or
        seaborn: one row per (run, history row) with run_id, the run's parameters and status,
        and the history columns asked for (all by default; a run lacking one gets NaN)."""
        frames = []
        for rid in run_ids if run_ids is not None else self.run_ids():
            with self._run_group(rid) as g:
                history = g["history"]
                names = [_plain(c) for c in history.attrs.get("columns", list(history))]
                wanted = names if columns is None else list(columns)
                frame = pd.DataFrame({c: history[c][()] if c in history else np.nan
                                      for c in wanted} if wanted else {},
                                     index=pd.RangeIndex(len(history["time"]), name="row"))
                params = self._prefixed(g, rid, PARAM_PREFIX)
                status = _plain(g.attrs["status"], f"{self._path}: run {rid} status")
            frames.append(frame.reset_index().assign(run_id=rid, status=status, **params))
        if not frames:
            return pd.DataFrame(columns=["run_id", "row", "status"])
        table = pd.concat(frames, ignore_index=True)
        first = ["run_id", "row", "status"]
        return table[first + [c for c in table.columns if c not in first]]

    # --- tables ---------------------------------------------------------------------------

    def write_classification(self, df: pd.DataFrame,
                             units: dict[str, tuple[str, str]] | None = None) -> None:
        """Store a per-run table (must have a run_id column), replacing any earlier one.

        One 1-D dataset per column under /classification, in column order (also listed in
        its "columns" attribute). Numbers and booleans keep their dtype (pandas nullable
        integers become float with NaN); everything else is stored as UTF-8 strings, with
        missing values as "". `units`: column → (unit, meaning), stored as the dataset's
        attributes `units` and `long_name`.
        """
        if "run_id" not in df.columns:
            raise ValueError(f"classification table needs a run_id column; it has "
                             f"{list(df.columns)}")
        self._need_writer()
        self.merge()  # runs and the table that describes them in one file
        try:
            with self._rewritten(2 * int(df.memory_usage(deep=True).sum()) + (1 << 18)) as f:
                _write_classification(f, df, units or {})
        finally:
            self._refresh()

    def write_boundaries(self, df: pd.DataFrame, units: dict[str, tuple[str, str]],
                         settings: dict) -> None:
        """Store the traced boundaries (rodphase.boundaries.lines) under /boundaries, one
        1-D dataset per column (with its `units` and `long_name`), replacing earlier ones;
        `settings` (what made them) as the group's attributes."""
        self._need_writer()
        self.merge()
        try:
            with self._rewritten(2 * int(df.memory_usage(deep=True).sum()) + (1 << 18)) as f:
                if "boundaries" in f:
                    del f["boundaries"]
                g = f.create_group("boundaries", track_order=True)
                for name in df.columns:
                    g.create_dataset(str(name), data=_column_array(df[name]))
                    unit, meaning = units.get(str(name), ("", ""))
                    g[str(name)].attrs["units"] = unit
                    if meaning:
                        g[str(name)].attrs["long_name"] = meaning
                g.attrs["columns"] = [str(c) for c in df.columns]
                for key, value in settings.items():
                    g.attrs[key] = value
        finally:
            self._refresh()

    def boundaries(self) -> pd.DataFrame | None:
        """The stored boundaries table (write_boundaries), or None; its settings in attrs."""
        if self.file is None or "boundaries" not in self.file:
            return None
        g = self.file["boundaries"]
        table = _read_classification(g)
        table.attrs.update({k: _plain(v) for k, v in g.attrs.items() if k != "columns"})
        return table

    def classification(self) -> pd.DataFrame | None:
        if self.file is None or "classification" not in self.file:
            return None
        with self._damaged("the classification table"):
            return _read_classification(self.file["classification"])

    def table(self, classification: pd.DataFrame | None = None) -> pd.DataFrame:
        """One row per run: run_id, params, status, message, wall_time, steps, and the
        classification columns (the stored ones, or `classification` if given). A
        classification column that repeats a column of the runs with the same values is
        left out; one with the same name and other values gets the suffix "_classified"."""
        rows = []
        for rid in self.run_ids():
            with self._run_group(rid) as g:
                a = g.attrs
                where = f"{self._path}: run {rid}"
                row = {"run_id": rid} | self._prefixed(g, rid, PARAM_PREFIX)
                row.update(status=_plain(a["status"], where),
                           message=_plain(a["message"], f"{where} message"),
                           wall_time=float(a["wall_time"]), steps=int(a["steps"]))
            rows.append(row)
        table = pd.DataFrame(rows, columns=None if rows else
                             ["run_id", "status", "message", "wall_time", "steps"])
        classified = self.classification() if classification is None else classification
        if classified is not None:
            classified = classified.astype({"run_id": str})
            shared = table.merge(classified, on="run_id", how="inner", suffixes=("", "__c"))
            repeated = [c for c in classified.columns if c != "run_id" and c in table.columns
                        and _same(shared[c], shared[c + "__c"])]
            table = table.merge(classified.drop(columns=repeated), on="run_id", how="left",
                                suffixes=("", "_classified"))
        return table


# ----------------------------------------------------------------------------- layout

# units of the per-run arrays ("1": dimensionless or an index); history columns: HISTORY_UNITS
ARRAY_UNITS = {"positions": "m", "directors": "1", "radii": "m", "rest_lengths": "m",
               "velocities": "m/s", "angular_velocities": "rad/s", "clamp_frames": "1"}
# written since a run can start from a stored state: the final state's rates (a store written
# before them has none, and a state read from it is at rest) and the clamps' frames before
# their rotation (without them a continued run takes its clamps from the end elements)
RESTART_ARRAYS = ("velocities", "angular_velocities", "clamp_frames")
# Each array's dimensions, named by HDF5 dimension scales so that netCDF readers (xarray
# through h5netcdf) see named dimensions instead of phony_dim_N. Scales of the run group
# serve its subgroups too; `time` is the history's own column and a copy in snapshots/.
DIMENSIONS = {"positions": ("node", "xyz"), "directors": ("element", "director", "xyz"),
              "radii": ("element",), "rest_lengths": ("element",),
              "velocities": ("node", "xyz"), "angular_velocities": ("element", "xyz"),
              "clamp_frames": ("clamp", "director", "xyz"),
              "snapshots/positions": ("time", "node", "xyz"),
              "snapshots/d1": ("time", "element", "xyz"), "snapshots/rows": ("time",)}


def _write_array(group: h5py.Group, name: str, data, *, units: str,
                 per_snapshot: bool = False) -> h5py.Dataset:
    data = np.asarray(data)
    if per_snapshot and data.size:
        # one chunk per snapshot: a movie frame is one chunk read, and gzip pays off on
        # slowly varying rods
        ds = group.create_dataset(name, data=data, chunks=(1,) + data.shape[1:],
                                  compression="gzip", compression_opts=4, shuffle=True)
    elif data.dtype.kind in "iuf" and data.ndim:
        # the same dataset and attribute as the high-level calls make (contiguous, same
        # properties, a variable-length UTF-8 `units`) at less than half the cost: a run has
        # some 37 arrays, and a sweep of short runs spends most of its storing time here
        space = h5py.h5s.create_simple(data.shape)
        dsid = h5py.h5d.create(group.id, name.encode(), h5py.h5t.py_create(data.dtype), space)
        if data.size:
            dsid.write(h5py.h5s.ALL, h5py.h5s.ALL, np.ascontiguousarray(data))
        attr = h5py.h5a.create(dsid, b"units", _TEXT_FILE_TYPE, h5py.h5s.create(h5py.h5s.SCALAR))
        attr.write(np.array(units, dtype=_TEXT), mtype=_TEXT_MEMORY_TYPE)
        return h5py.Dataset(dsid)
    else:
        ds = group.create_dataset(name, data=data)
    ds.attrs["units"] = units
    return ds


_TEXT = h5py.string_dtype()  # what h5py stores a Python str attribute as
_TEXT_FILE_TYPE = h5py.h5t.py_create(_TEXT, logical=True)
_TEXT_MEMORY_TYPE = h5py.h5t.py_create(_TEXT)


def _name_dimensions(g: h5py.Group, fresh: bool = False) -> None:
    """Attach the run group's dimension scales to its arrays (again, after a copy: the
    references are file addresses, and HDF5's copy does not re-point them). `fresh`: the
    group was just written and has no references yet.

    Low-level calls on object ids (h5py.h5o, h5py.h5ds): the high-level lookups and proxies
    cost several times what HDF5 does, and a sweep names the dimensions of every run it
    merges."""
    from h5py import h5a, h5ds, h5o

    gid = g.id
    members = set(gid)  # names, as bytes
    history, snapshots = h5o.open(gid, b"history"), h5o.open(gid, b"snapshots")
    snapshot_members = set(snapshots)
    # a run written before clamp_frames has no `clamp` scale
    scales = {name: h5o.open(gid, name.encode())
              for name in ("node", "element", "director", "xyz", "clamp")
              if name.encode() in members}
    times = {"history": h5o.open(history, b"time"), "snapshots": h5o.open(snapshots, b"time")}
    labelled = []  # (dataset id, scale ids by axis)
    for name, dims in DIMENSIONS.items():
        where, _, leaf = name.rpartition("/")
        if leaf.encode() not in (snapshot_members if where else members):
            continue
        ds = h5o.open(snapshots if where else gid, leaf.encode())
        labelled.append((ds, [times["snapshots"] if d == "time" else scales[d] for d in dims]))
    labelled += [(h5o.open(history, name), [times["history"]]) for name in history
                 if name != b"time"]
    if not fresh:
        for ds, _ in labelled:
            if h5a.exists(ds, b"DIMENSION_LIST"):
                h5a.delete(ds, b"DIMENSION_LIST")
        for ds in list(scales.values()) + list(times.values()):
            if h5a.exists(ds, b"REFERENCE_LIST"):
                h5a.delete(ds, b"REFERENCE_LIST")
    for ds, axes in labelled:
        for axis, scale in enumerate(axes):
            h5ds.attach_scale(ds, scale, axis)


def _fill_run(g: h5py.Group, params: dict, result: RunResult, timings: dict,
              diagnostics: str, dimensions: bool = True) -> None:
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

    n = len(result.rest_lengths)
    for name, values in (("node", np.arange(n + 1)), ("element", np.arange(n)),
                         ("director", np.arange(1, 4)), ("xyz", np.arange(3))):
        _write_array(g, name, values, units="1").make_scale(name)
    if result.clamp_frames is not None:
        _write_array(g, "clamp", np.arange(2), units="1").make_scale("clamp")  # 0 start, 1 end
    for name in ("positions", "directors", "radii", "rest_lengths") + RESTART_ARRAYS:
        if getattr(result, name) is not None:
            _write_array(g, name, getattr(result, name), units=ARRAY_UNITS[name])
    history = g.create_group("history", track_order=True)
    time = np.asarray(result.history.get("time", np.zeros(0)))
    for name, column in result.history.items():
        _write_array(history, name, column, units=history_unit(name))
    history.attrs["columns"] = list(result.history)
    if "time" not in history:
        _write_array(history, "time", time, units="s")
    history["time"].make_scale("time")
    snapshots = g.create_group("snapshots")
    rows = result.snapshot_history_rows
    _write_array(snapshots, "time", time[rows] if len(time) else time[:0],
                 units="s").make_scale("time")
    _write_array(snapshots, "rows", rows, units="1")  # the history row of each snapshot
    _write_array(snapshots, "positions", result.snapshot_positions, units="m", per_snapshot=True)
    _write_array(snapshots, "d1", result.snapshot_d1, units="1", per_snapshot=True)
    if dimensions:
        _name_dimensions(g, fresh=True)


def run_image(run_id: str, params: dict, result: RunResult, timings: dict,
              config_hash: str) -> bytes:
    """The bytes of one run's part file (OUT.h5.parts/RUN_ID.h5), built in memory: no disk
    is touched, so a worker may build it and the writer only write it (Store.write_part).

    A part carries no dimension scales: the merge copies the run into OUT.h5 and names its
    dimensions there, once (names attached in the part would point into the part's file
    and have to be taken off and attached again after the copy)."""
    _check_id(run_id)
    # indented: h5dump, HDFView and h5py show it as readable text (json.loads reads both)
    diagnostics = json.dumps(result.diagnostics, default=_json_default, indent=1,
                             sort_keys=True)  # fail before building
    f = _in_memory()
    try:
        f.attrs.update(format=FORMAT, format_version=FORMAT_VERSION, config_hash=config_hash)
        _fill_run(f.create_group("runs").create_group(run_id), params, result, timings,
                  diagnostics, dimensions=False)
        f.flush()
        return f.id.get_file_image()
    finally:
        f.close()


def _write_classification(f: h5py.File, df: pd.DataFrame, units: dict) -> None:
    if "classification" in f:
        del f["classification"]
    g = f.create_group("classification", track_order=True)
    key = g.create_dataset("run_id", data=_column_array(df["run_id"]))
    key.make_scale("run_id")  # the table's one dimension, named for netCDF readers
    for name in df.columns:
        if name != "run_id":
            g.create_dataset(str(name), data=_column_array(df[name])).dims[0].attach_scale(key)
        if str(name) in units:
            unit, meaning = units[str(name)]
            g[str(name)].attrs["units"] = unit
            if meaning:
                g[str(name)].attrs["long_name"] = meaning
    g.attrs["columns"] = [str(c) for c in df.columns]


def _classification_units(g: h5py.Group) -> dict[str, tuple[str, str]]:
    """column → (unit, meaning) of a stored classification (those that have a unit)."""
    return {name: (_plain(ds.attrs["units"]), _plain(ds.attrs.get("long_name", "")))
            for name, ds in g.items() if "units" in ds.attrs}


def _read_classification(g: h5py.Group) -> pd.DataFrame:
    columns = [_plain(c, "classification columns") for c in g.attrs.get("columns", list(g))]
    data = {}
    for name in columns:
        ds = g[name]
        data[name] = ds.asstr()[()] if h5py.check_string_dtype(ds.dtype) else ds[()]
    return pd.DataFrame(data)


def _same(a: pd.Series, b: pd.Series) -> bool:
    """Equal values, NaN equal to NaN, numbers compared as numbers."""
    try:
        return bool(np.all((a.to_numpy() == b.to_numpy()) | (pd.isna(a).to_numpy()
                                                             & pd.isna(b).to_numpy())))
    except (TypeError, ValueError):
        return False


def _column_array(column: pd.Series) -> np.ndarray:
    if pd.api.types.is_bool_dtype(column) and not column.hasnans:
        return column.to_numpy(dtype=bool)
    if pd.api.types.is_numeric_dtype(column) and not pd.api.types.is_bool_dtype(column):
        if column.hasnans or pd.api.types.is_float_dtype(column):
            return column.to_numpy(dtype=np.float64, na_value=np.nan)
        return column.to_numpy(dtype=np.int64)
    text = ["" if pd.isna(v) else str(v) for v in column]
    return np.array(text, dtype=h5py.string_dtype())


# ----------------------------------------------------------------------------- opening

def _open_main(path: Path, check_layout: bool = True) -> h5py.File:
    """The main file, read-only, checked to be a rodphase store; NotAStore if not."""
    try:
        file = _h5(path, "r")
    except OSError as exc:
        reason = str(exc).split("(")[-1].rstrip(")") if "(" in str(exc) else str(exc)
        raise NotAStore(f"{path} cannot be read as HDF5 ({reason}): give a file written by "
                        "rodphase run or rodphase sweep") from None
    try:
        try:
            version = _plain(file.attrs.get("format_version"), f"{path}: format_version")
            declared = _plain(file.attrs.get("format"), f"{path}: format")
            has_runs = "runs" in file and isinstance(file["runs"], h5py.Group)
        except (KeyError, TypeError, ValueError, OSError, RuntimeError) as exc:
            raise NotAStore(f"{path}: its attributes cannot be read ({type(exc).__name__}: "
                            f"{_short(exc)}): the file is damaged or was not written by "
                            "rodphase") from None
        if declared != FORMAT or not has_runs:
            raise NotAStore(f"{path} is an HDF5 file but not a rodphase store (no format "
                            f"'{FORMAT}' attribute or /runs group): give a file written by "
                            "rodphase run or rodphase sweep")
        if version not in READABLE_VERSIONS:
            raise NotAStore(f"{path} is a rodphase store of format_version {version}; this "
                            f"rodphase reads {', '.join(map(str, READABLE_VERSIONS))}")
        if check_layout:
            try:
                _check_layout(file, str(path))
            except (KeyError, TypeError, ValueError, OSError, RuntimeError) as exc:
                raise NotAStore(f"{path}: its layout cannot be read ({type(exc).__name__}: "
                                f"{_short(exc)}): the file is damaged or was not written by "
                                "rodphase") from None
    except BaseException:
        file.close()
        raise
    return file


def provenance() -> dict:
    """What made the results besides the config: versions of Python and the numerical
    libraries, the platform, and the git commit of rodphase when run from a checkout
    ("+dirty" with uncommitted changes), so that a number can be traced to the code."""
    import platform
    import subprocess

    import numba
    import scipy

    from ._version import __version__

    commit = "unknown (not a git checkout)"
    source = Path(__file__).resolve().parent.parent
    if (source / ".git").exists():
        try:
            def git(*args):
                return subprocess.run(["git", "-C", str(source), *args], capture_output=True,
                                      text=True, timeout=10, check=True).stdout.strip()

            commit = git("rev-parse", "HEAD")
            if git("status", "--porcelain", "--untracked-files=no"):
                commit += "+dirty"
        except (OSError, subprocess.SubprocessError):
            pass
    return {"rodphase": __version__, "git_commit": commit, "python": platform.python_version(),
            "numpy": np.__version__, "numba": numba.__version__, "scipy": scipy.__version__,
            "h5py": h5py.__version__, "hdf5": h5py.version.hdf5_version,
            "pandas": pd.__version__, "platform": platform.platform()}


def _declares_store(path: Path) -> bool:
    """Whether `path` is HDF5 with rodphase's format attribute (a store, if a damaged one:
    --force may replace it; nothing else)."""
    try:
        with _h5(path, "r") as f:
            return _plain(f.attrs.get("format")) == FORMAT
    except (OSError, RuntimeError, ValueError, KeyError, TypeError, StoreError):
        return False


def _is_empty_hdf5(path: Path) -> bool:
    try:
        with _h5(path, "r") as f:
            return not len(f) and not len(f.attrs)
    except (OSError, RuntimeError, ValueError, KeyError):  # damaged: not empty, not a store
        return False


def open_store(path, *, config_text: str, config_hash: str, version: str, kind: str,
               replace: bool = False, earlier: dict[str, int] | None = None) -> Store:
    """Open the store at `path` to add runs: create it, or resume it if it holds the same
    config. Takes the writer lock (StoreBusy if another process writes it).

    A store of another config raises StoreMismatch; with replace=True it is replaced, but
    only once the first new run is durable (nothing is deleted before then). `earlier`
    ({hash: engine revision}, config.earlier_hashes) names the case of the same config
    written by an earlier engine revision, whose runs are of other physics."""
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
    path = Path(path)
    if path.is_dir():
        raise StoreError(f"{path} is a folder: give the path of an .h5 file")
    lock = _WriterLock(path).acquire()
    try:
        new_attrs = dict(format=FORMAT, format_version=FORMAT_VERSION, rodphase_version=version,
                         kind=kind, config_yaml=config_text, config_hash=config_hash,
                         created=datetime.now(timezone.utc).isoformat(timespec="seconds"),
                         provenance=json.dumps(provenance()))
        other, empty = None, path.exists() and _is_empty_hdf5(path)
        if path.exists() and not empty:
            try:
                with Store(path) as existing:
                    held = existing.attrs.get("config_hash")
            except NotAStore as exc:
                held, other = None, str(exc)
            if other and not (_declares_store(path) or path.stat().st_size == 0):
                # `-o typo.yaml`: advising --force (or obeying it) would put a store in place
                # of the user's own file
                raise NotAStore(other.split(": give a file")[0] + ": --force replaces only a "
                                "rodphase store, and this file is not one; nothing was "
                                "changed: give another output file (or move this one away)")
            if held != config_hash and not replace:
                revision = (earlier or {}).get(held)
                if revision is not None:
                    from .config import ENGINE_REVISION, ENGINE_REVISIONS

                    raise StoreMismatch(
                        f"{path} holds results of this config from an earlier rodphase (engine "
                        f"revision {revision}; this one is {ENGINE_REVISION}: "
                        f"{ENGINE_REVISIONS[ENGINE_REVISION]}), whose runs are of other "
                        "physics and are not resumed; use another output file, or --force to "
                        "replace it")
                raise (NotAStore if other else StoreMismatch)(
                    other.replace("give a file written by rodphase run or rodphase sweep",
                                  "use another output file, or --force to replace it")
                    if other else
                    f"{path} holds results of a different config (stored hash {held}, this "
                    f"config {config_hash}); use another output file, or --force to replace it")
            replacing = held != config_hash
        else:
            replacing = empty  # an empty HDF5 file (say from a tool that made the name)
        _remove_temporaries(path)
        store = Store(path, lock=lock, new_attrs=new_attrs, replace=replacing)
        if store.file is None and (empty or not replacing):
            store.merge()  # a new store exists (empty) from the start: readers can open it
        return store
    except BaseException:
        lock.release()
        raise


def _remove_temporaries(path: Path) -> None:
    """Temporary files left by a killed writer (only the lock holder writes them)."""
    leftovers = list(path.parent.glob(f".{path.name}.*.tmp"))
    folder = parts_folder(path)
    if folder.is_dir():
        leftovers += list(folder.glob(".*.tmp"))
    for tmp in leftovers:
        with contextlib.suppress(OSError):
            tmp.unlink()


def read_store(path) -> Store:
    """Open an existing store read-only (its unmerged parts included); NotAStore if `path`
    is not a rodphase store. Safe while another process writes it."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path} does not exist")
    return Store(path)


def edit_store(path) -> Store:
    """Open an existing store to store its classification (takes the writer lock:
    StoreBusy while a sweep writes it); NotAStore if it is not one."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path} does not exist")
    read_store(path).close()  # refuse a foreign file before taking its lock
    lock = _WriterLock(path).acquire()
    try:
        store = Store(path, lock=lock)
        store._new_attrs = store.attrs
        return store
    except BaseException:
        lock.release()
        raise


def read_table(path) -> pd.DataFrame:
    """The per-run table of the store at `path` (see Store.table)."""
    with read_store(path) as store:
        return store.table()


def read_histories(path, columns=None, run_ids=None) -> pd.DataFrame:
    """The time histories of the store at `path` as one long table (see Store.histories)."""
    with read_store(path) as store:
        return store.histories(columns, run_ids)


def write_table_csv(table, path) -> Path:
    """Write a per-run table (a DataFrame, or the path of a store) as CSV; return the path."""
    if not isinstance(table, pd.DataFrame):
        table = read_table(table)
    from .tabulate import column_units

    path = Path(path)
    table.to_csv(path, index=False, float_format="%.10g")
    # the CSV itself stays plain (pd.read_csv reads it as before); its columns' units and
    # meanings go beside it, as CSV on the Web (W3C) metadata: PATH-metadata.json
    described = column_units(table.columns)
    metadata = {"@context": "http://www.w3.org/ns/csvw", "url": path.name,
                "tableSchema": {"columns": [
                    {"name": name, "titles": name, "dc:description": meaning,
                     "unit": unit or None} for name, (unit, meaning) in described.items()],
                    "primaryKey": "run_id"}}
    Path(f"{path}-metadata.json").write_text(json.dumps(metadata, indent=1,
                                                        ensure_ascii=False) + "\n")
    return path
