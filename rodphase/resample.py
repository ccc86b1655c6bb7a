"""A rod's shape at twice the elements: what a run that went under-resolved goes on from.

One job, no I/O: from the nodes (n+1, 3) and the d1 directors (n, 3) of a snapshot, the nodes
(2n+1, 3) and directors (2n, 3, 3) (rows d1 d2 d3) of the same rod with every element split in
two. The old nodes are kept exactly; the new ones lie on a cubic spline through them (by arc
length), so the curvature does not alternate between old and new nodes. Each new element's
frame is the old frames interpolated at its centre (the geodesic between the two nearest old
frames), turned by the smallest rotation that puts d3 on the new element's tangent: the
twist about the centreline is carried over, and shear starts from zero (a snapshot keeps d1
only; a rod in the paper's model relaxes its shear within a few of its fastest periods).
"""

from __future__ import annotations

import numpy as np


def _frames(positions: np.ndarray, d1: np.ndarray) -> np.ndarray:
    """(n, 3, 3) unsheared frames, rows d1 d2 d3: d3 the element tangent, d1 the given d1
    with its tangential part removed."""
    t = np.diff(positions, axis=0)
    t /= np.linalg.norm(t, axis=1)[:, None]
    e1 = d1 - np.sum(d1 * t, axis=1)[:, None] * t
    e1 /= np.linalg.norm(e1, axis=1)[:, None]
    return np.stack([e1, np.cross(t, e1), t], axis=1)


def _align(frames: np.ndarray, tangents: np.ndarray) -> np.ndarray:
    """The frames turned by the smallest rotation that takes each d3 to its tangent."""
    d3 = frames[:, 2]
    axis = np.cross(d3, tangents)
    sin = np.linalg.norm(axis, axis=1)
    cos = np.sum(d3 * tangents, axis=1)
    out = frames.copy()
    turn = sin > 1e-15
    if np.any(turn):
        from scipy.spatial.transform import Rotation

        rotvec = axis[turn] / sin[turn, None] * np.arctan2(sin[turn], cos[turn])[:, None]
        rotation = Rotation.from_rotvec(rotvec)
        for row in range(3):
            out[turn, row] = rotation.apply(frames[turn, row])
    # exact orthonormality after the rotation's round-off: d3 the tangent, d2 = d3 × d1
    e1 = out[:, 0] - np.sum(out[:, 0] * tangents, axis=1)[:, None] * tangents
    e1 /= np.linalg.norm(e1, axis=1)[:, None]
    return np.stack([e1, np.cross(tangents, e1), tangents], axis=1)


def doubled(positions: np.ndarray, d1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Nodes (2n+1, 3) and directors (2n, 3, 3) of the rod with nodes `positions` (n+1, 3) and
    directors d1 (n, 3), every element split in two (see the module docstring)."""
    from scipy.interpolate import CubicSpline
    from scipy.spatial.transform import Rotation, Slerp

    positions = np.asarray(positions, float)
    d1 = np.asarray(d1, float)
    n = len(d1)
    if positions.shape != (n + 1, 3) or n < 2:
        raise ValueError(f"positions must be (n+1, 3) and d1 (n, 3) with n >= 2; got "
                         f"{positions.shape} and {d1.shape}")
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(positions, axis=0), axis=1))])
    spline = CubicSpline(arc, positions, axis=0)
    nodes = np.empty((2 * n + 1, 3))
    nodes[0::2] = positions
    nodes[1::2] = spline(0.5 * (arc[1:] + arc[:-1]))
    # new element 2j has its centre a quarter of an old element before old element j's
    # centre, 2j + 1 a quarter after: in units of old elements, centres at j ∓ 1/4
    old = Rotation.from_matrix(np.transpose(_frames(positions, d1), (0, 2, 1)))
    centres = np.clip(np.repeat(np.arange(n, dtype=float), 2) + np.tile([-0.25, 0.25], n),
                      0.0, n - 1.0)
    between = np.transpose(Slerp(np.arange(n, dtype=float), old)(centres).as_matrix(), (0, 2, 1))
    tangents = np.diff(nodes, axis=0)
    tangents /= np.linalg.norm(tangents, axis=1)[:, None]
    return nodes, _align(between, tangents)
