#!/usr/bin/env python
"""Where did a run's link go? Each link jump of a twist_under_load point, located.

    python studies/self_passage.py --twist-density 2.556 --extension 1.265 [--elements 80]
        [--interval 1e-3] [--set KEY=VALUE ...]

The runner books every change of Lk that the clamps did not put in as an escape (a strand
passing around an end). A strand can also pass through the rod itself where contact does not
act. This runs the point (the shipped scene twist_under_load with the Fig 3 settings) once
at the usual history interval to find the jumps, then again with a history row every
--interval seconds up to just after the last of them, and for each jump compares the
Gauss writhe of every pair of the rod's own segments (Klenin & Langowski's solid angle) in
the rows before and after it. A crossing of two segments changes the rod's own writhe by
about ±2 in one row (in one pair, or split between the pairs of a shared node); a jump
in which the twist jumps by about ±1 instead is a twist wrap (a director turned by more
than half a turn against its neighbour's about the centreline: Tw = Σ of those angles, each
in (−π, π]); one that neither makes crossed the closure beyond an end, and for it the script
also prints each end's tilt from the axis and the node nearest to its closing ray. Prints
one line per jump: time, ΔLk, ΔWr of the rod alone, the pair that changed most, its
distance along the rod and whether it lies inside the contact exclusion (where neighbours
never repel), and the verdict.
"""

from __future__ import annotations

import argparse
import math
import sys

import numpy as np

from rodphase import config as C
from rodphase import runner
from rodphase.rod.simulate import time_step
from rodphase.scenes import SCENES, build


def pair_writhe(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(i, j, w) over the segment pairs i < j − 1 of the polyline x (m+1, 3): w is the pair's
    share of the writhe, both orders counted (2 Ω / 4π, Klenin & Langowski 2000)."""
    i, j = np.triu_indices(len(x) - 1, k=2)
    p1, p2, p3, p4 = x[i], x[i + 1], x[j], x[j + 1]
    r13, r14, r23, r24 = p3 - p1, p4 - p1, p3 - p2, p4 - p2

    def unit(v):
        norm = np.linalg.norm(v, axis=1)
        return v / np.where(norm > 0, norm, 1.0)[:, None]

    n1, n2 = unit(np.cross(r13, r14)), unit(np.cross(r14, r24))
    n3, n4 = unit(np.cross(r24, r23)), unit(np.cross(r23, r13))

    def asin_dot(a, b):
        return np.arcsin(np.clip(np.sum(a * b, axis=1), -1.0, 1.0))

    omega = asin_dot(n1, n2) + asin_dot(n2, n3) + asin_dot(n3, n4) + asin_dot(n4, n1)
    sign = np.sign(np.sum(np.cross(p4 - p3, p2 - p1) * r13, axis=1))
    return i, j, 2.0 * omega * sign / (4.0 * math.pi)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--twist-density", type=float, required=True, help="Phi*a (rest)")
    parser.add_argument("--extension", type=float, required=True, help="L/L0")
    parser.add_argument("--elements", type=int, default=80)
    parser.add_argument("--interval", type=float, default=1e-3, help="s between fine rows")
    parser.add_argument("--set", dest="sets", action="append", default=[],
                        help="KEY=VALUE, e.g. loading.quasi_static_below=0")
    args = parser.parse_args(argv)
    overrides = [("rod.elements", args.elements), ("loading.force_multiple", None),
                 ("loading.twist_density", args.twist_density),
                 ("loading.extension", args.extension), ("loading.quasi_static_below", 0.8),
                 ("output.snapshots", "all")]
    overrides += [C.parse_override(item) for item in args.sets]
    cfg = C.load_scene("twist_under_load", overrides, SCENES)
    coarse = runner.run(build(cfg), topology=True)
    jumps = np.flatnonzero(runner.link_escapes(coarse.history))
    print(f"{coarse.status}: {len(jumps)} link jump(s) at t = "
          + ", ".join(f"{coarse.history['time'][k]:.2f} s" for k in jumps))
    if not len(jumps):
        return 0
    last = coarse.history["time"][jumps[-1]] + 0.01
    fine_cfg = C.load_scene("twist_under_load",
                            overrides + [("output.history_interval", args.interval)], SCENES)
    problem = build(fine_cfg)
    dt, _ = time_step(problem)
    fine = runner.run(problem, max_steps=int(last / dt) + 1, topology=True)
    h, shapes = fine.history, fine.snapshot_positions
    rows = {int(r): k for k, r in enumerate(fine.snapshot_history_rows)}
    exclusion = math.ceil(problem.contact.exclusion * problem.rod.radius / problem.rod.element_length)
    for k in np.flatnonzero(runner.link_escapes(h)):
        if k - 1 not in rows or k not in rows:
            continue
        i, j, before = pair_writhe(shapes[rows[k - 1]])
        _, _, after = pair_writhe(shapes[rows[k]])
        change = after - before
        m = int(np.argmax(np.abs(change)))
        where = ("inside" if j[m] - i[m] <= exclusion else "outside") + \
            f" the contact exclusion ({exclusion} elements)"
        # a crossing may fall on a node two segments share, splitting its ±2 between pairs:
        # the rod's own writhe jumping in one row is the test, the pair only says where
        twist_jump = h["twist"][k] - h["twist"][k - 1]
        if abs(change.sum()) > 1.0:
            kind = "self-passage"
        elif abs(twist_jump) > 0.5:
            kind = (f"twist wrap (Tw jumped {twist_jump:+.2f}: somewhere a director turned by "
                    "more than half a turn against its neighbour's, measured about the "
                    "centreline; a sheared or under-resolved rod)")
        else:
            kind = "around an end (neither the rod's own writhe nor its twist jumped)"
        print(f"t = {h['time'][k]:.4f} s: ΔLk {h['link'][k] - h['link'][k - 1]:+.2f}, "
              f"ΔWr of the rod {change.sum():+.2f}; largest pair change {change[m]:+.2f} at "
              f"elements {i[m]} and {j[m]} ({j[m] - i[m]} apart, {where}): {kind}")
        if kind.startswith("around an end"):
            for line in near_the_ends(shapes[rows[k - 1]], shapes[rows[k]], problem, exclusion):
                print("    " + line)
    return 0


def near_the_ends(before: np.ndarray, after: np.ndarray, problem, exclusion: int) -> list[str]:
    """What passed an end between two rows: per end, the tilt of its end element from the
    axis (the writhe's closure is a ray along the end tangent), and the node that came
    nearest to that ray (outside the end element itself) in the later row: its element,
    its height beyond the end node along the axis, its distance from the axis line (the end
    body is a cylinder of body_radius about that line beyond the end), and whether it lies
    within the contact exclusion of the end, where the body does not push it."""
    axis = np.asarray(problem.ends.axis, dtype=float)
    axis = axis / np.linalg.norm(axis)
    body = problem.ends.body_radius * problem.rod.radius
    lines = []
    n = len(after) - 1
    for name, end, inward, side in (("start", 0, 1, -1.0), ("end", n, n - 1, 1.0)):
        out = side * axis
        tilts = []
        for x in (before, after):
            tangent = x[end] - x[inward]
            tangent /= np.linalg.norm(tangent)
            tilts.append(math.degrees(math.acos(np.clip(tangent @ out, -1.0, 1.0))))
        tangent = after[end] - after[inward]
        tangent /= np.linalg.norm(tangent)
        r = after - after[end]
        along = r @ tangent
        off_ray = np.linalg.norm(r - np.outer(along, tangent), axis=1)
        off_ray[along <= 0.0] = np.inf  # behind the end node: not beside its ray
        off_ray[[end, inward]] = np.inf
        if not np.isfinite(off_ray).any():
            lines.append(f"{name}: end element {tilts[0]:.1f} -> {tilts[1]:.1f} deg from the "
                         "axis; no node beyond the end along its ray")
            continue
        nearest = int(np.argmin(off_ray))
        height = float(r[nearest] @ out)
        from_axis = float(np.linalg.norm(r[nearest] - height * out))
        exempt = abs(nearest - end) <= exclusion
        lines.append(
            f"{name}: end element {tilts[0]:.1f} -> {tilts[1]:.1f} deg from the axis; nearest "
            f"node to its ray: {nearest} ({abs(nearest - end)} from the end, "
            f"{'inside' if exempt else 'outside'} the exclusion), "
            f"{off_ray[nearest] / problem.rod.radius:.2f} a from the ray, "
            f"{height / problem.rod.radius:+.2f} a beyond the end along the axis, "
            f"{from_axis / problem.rod.radius:.2f} a from the axis line "
            f"(body radius {body / problem.rod.radius:.2f} a)")
    return lines


if __name__ == "__main__":
    sys.exit(main())
