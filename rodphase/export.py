"""Rod shapes for renderers: legacy VTK polydata that ParaView, VisIt or PyVista read.

One file holds one rod as a polyline through its nodes, with per-node point data `radius`
(m; the mean of the neighbouring elements' current radii) and `arc_length` (s/L, 0 at the
start, 1 at the end). ParaView's Tube filter with "vary radius by scalar" on `radius` draws
the filament as a shaded tube of its real thickness; numbered files (rod_0000.vtk, ...) open
as a time series.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def node_radii(element_radii: np.ndarray) -> np.ndarray:
    """(n+1,) radius at each node from the (n,) element radii."""
    r = np.asarray(element_radii, float)
    return np.concatenate([r[:1], 0.5 * (r[1:] + r[:-1]), r[-1:]])


def write_vtk(path, positions: np.ndarray, radii: np.ndarray, *, title: str = "rodphase rod") -> Path:
    """Write one rod: nodes (n+1, 3) in m, element radii (n,) in m."""
    x = np.asarray(positions, float)
    if x.ndim != 2 or x.shape[1] != 3 or len(x) < 2:
        raise ValueError(f"positions must have shape (n+1, 3), got {x.shape}")
    r = node_radii(radii)
    if len(r) != len(x):
        raise ValueError(f"{len(radii)} element radii for {len(x)} nodes")
    steps = np.linalg.norm(np.diff(x, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(steps)])
    s = s / s[-1] if s[-1] > 0 else s
    n = len(x)
    lines = [
        "# vtk DataFile Version 3.0", title.replace("\n", " ")[:255], "ASCII",
        "DATASET POLYDATA", f"POINTS {n} double",
        *(f"{a:.10g} {b:.10g} {c:.10g}" for a, b, c in x),
        f"LINES 1 {n + 1}", " ".join(map(str, [n, *range(n)])),
        f"POINT_DATA {n}", "SCALARS radius double 1", "LOOKUP_TABLE default",
        *(f"{v:.10g}" for v in r),
        "SCALARS arc_length double 1", "LOOKUP_TABLE default",
        *(f"{v:.10g}" for v in s),
    ]
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")
    return path


def write_vtk_series(stem, snapshot_positions: np.ndarray, radii: np.ndarray) -> list[Path]:
    """One file per snapshot, STEM_0000.vtk, ...: a time series for ParaView. The radii are
    the final ones (snapshots store no radii; they change only with stretch or growth)."""
    stem = Path(stem)
    stem = stem.with_suffix("") if stem.suffix == ".vtk" else stem
    return [write_vtk(stem.with_name(f"{stem.name}_{k:04d}.vtk"), frame, radii)
            for k, frame in enumerate(np.asarray(snapshot_positions, float))]
