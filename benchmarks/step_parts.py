#!/usr/bin/env python
"""Where a Fig 3 step goes, and what a Newton iteration on the same rod would cost.

    python benchmarks/step_parts.py [--point 2.447,1.056] [--elements 80] [--write docs/history/performance.md]

Issue #16 asks for Fig 3 in 20 s. Most of its CPU is the twist ramp of the runs that buckle
into plectonemes, at 80 elements with self-contact. This script takes one such run (by
default Fig 3's point Φa = 2.447, L/L0 = 1.056 of configs/fig3_paper.yaml, a plectoneme):

1. runs it to its end as a sweep would, and once more with contact off (the same protocol,
   the rod then passes through itself: only its cost per step is used), for the cost of a
   whole step with and without contact and how often the two contact lists were rebuilt;
2. times, on the run's final state (CPU time, best of 7 repeats of many calls, compiled
   first), each contact part the kernel runs per step: the force loop over the near list
   (at the smallest margin, 0.01 rest radii, and at 0.1), the implicit dashpots of the
   touching pairs, the fold pass, and the two list rebuilds (the near list from the
   candidates, the candidates from the grid), the latter two weighted by how often the run
   rebuilt them;
3. sizes one Newton iteration of a quasi-static path on that state (lever 1 of #16): the
   Jacobian's sparsity (each node and element is a block of 3 unknowns; internal forces
   couple blocks two nodes apart, each touching pair its four nodes), the number of force
   evaluations a coloured finite-difference Jacobian needs (greedy distance-2 colouring),
   and the time of a sparse LU (scipy's SuperLU), of the lowest eigenvalue by shift-invert
   Lanczos (scipy's eigsh) and of a banded Cholesky factorisation after a reverse
   Cuthill-McKee ordering (it exists exactly when the matrix is positive definite: a
   stability test) on a symmetric, positive definite matrix with that pattern. A force
   evaluation is taken to cost a whole step with contact, an upper bound.

Prints Markdown; --write replaces the step_parts block of the given file.
"""

from __future__ import annotations

import os

for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse
import datetime
import time
from pathlib import Path

import numpy as np
from numba import njit

import rodphase
from rodphase import sweep as S
from rodphase.rod import contact as K
from rodphase.rod.simulate import _rod_arrays
from rodphase.runner import run_scene
from rodphase.scenes import build
from rodphase.studytools import machine, write_block

REPEATS = 7


@njit(cache=False)
def _force_loop(calls, x, v, radius, near, n_near, k, c, force, dashpots, seg, inv_square, lever):
    touching = 0
    for _ in range(calls):
        touching = K.contact_forces_in(x, v, radius, near, n_near, k, c, 1.0, 0.0, 1e-4, 1.0,
                                       force, dashpots, True, seg, inv_square, lever)[4]
    return touching


@njit(cache=False)
def _dashpot_loop(calls, v, inv_mass, dashpots, noted, dt):
    for _ in range(calls):
        K.apply_dashpots(v, inv_mass, dashpots, noted, dt)


@njit(cache=False)
def _fold_loop(calls, x, radius, lengths, rest_length, exclusion, k, reach, next_tight, force):
    pushed = 0
    for _ in range(calls):
        pushed = K.fold_forces(x, radius, lengths, rest_length, exclusion, k, 1.0, reach,
                               next_tight, force)[0]
    return pushed


@njit(cache=False)
def _near_loop(calls, x, radius, pairs, n_pairs, margin, near):
    count = 0
    for _ in range(calls):
        count = K.near_pairs(x, radius, pairs, n_pairs, margin, near)
    return count


@njit(cache=False)
def _grid_loop(calls, x, exclusion, cutoff, pairs):
    count = 0
    for _ in range(calls):
        count = K.build_pairs(x, exclusion, cutoff, pairs)[1]
    return count


def best_us(loop, calls, *args) -> float:
    """µs per call: CPU time of `calls` calls, best of REPEATS (after one compiling call)."""
    loop(1, *args)
    best = np.inf
    for _ in range(REPEATS):
        t0 = time.process_time()
        loop(calls, *args)
        best = min(best, time.process_time() - t0)
    return 1e6 * best / calls


def run_point(point: dict, elements: int, extra: list[str]):
    _, scene = rodphase.load_sweep("fig3_paper")
    cfg = rodphase.load(S.scene_for(scene, point), [f"rod.elements={elements}", *extra])
    t0 = time.process_time()
    result = run_scene(cfg)
    return cfg, result, time.process_time() - t0


def colours(blocks: int, neighbours: list[set]) -> int:
    """Greedy distance-2 colouring of the block graph: two blocks that share a neighbour (or
    are neighbours) need different colours, so that one force evaluation per colour and
    unknown in a block fills the Jacobian's columns without overlap."""
    colour = np.full(blocks, -1)
    for b in range(blocks):
        taken = set()
        for a in neighbours[b]:
            for c in neighbours[a]:
                if colour[c] >= 0:
                    taken.add(colour[c])
        c = 0
        while c in taken:
            c += 1
        colour[b] = c
    return int(colour.max()) + 1


def newton_sizes(n: int, touching_pairs: np.ndarray) -> dict:
    """Sparsity, colours and linear-algebra times of the rod's Jacobian (see the docstring)."""
    import scipy.sparse as sp
    from scipy.linalg import cholesky_banded
    from scipy.sparse.csgraph import reverse_cuthill_mckee
    from scipy.sparse.linalg import eigsh, splu

    # blocks: nodes 0..n, then elements 0..n-1 (3 unknowns each: displacement, rotation)
    blocks = 2 * n + 1

    def node(i):
        return i

    def element(e):
        return n + 1 + e

    neighbours = [set([b]) for b in range(blocks)]

    def link(a, b):
        neighbours[a].add(b)
        neighbours[b].add(a)

    # internal: element e's strain (nodes e, e+1, frame e) and the curvature at its ends
    # (frames e-1..e+1, the lengths of elements e-1..e+1) reach nodes e-1..e+2, elements e-1..e+1
    for e in range(n):
        members = [node(i) for i in range(max(e - 1, 0), min(e + 2, n) + 1)]
        members += [element(f) for f in range(max(e - 1, 0), min(e + 1, n - 1) + 1)]
        for a in members:
            for b in members:
                link(a, b)
    for i, j in touching_pairs:
        members = [node(i), node(i + 1), node(j), node(j + 1)]
        for a in members:
            for b in members:
                link(a, b)
    count = colours(blocks, neighbours)
    rows, cols = [], []
    for a in range(blocks):
        for b in neighbours[a]:
            for p in range(3):
                for q in range(3):
                    rows.append(3 * a + p)
                    cols.append(3 * b + q)
    size = 3 * blocks
    rng = np.random.default_rng(0)
    values = rng.standard_normal(len(rows))
    pattern = sp.csc_matrix((values, (rows, cols)), shape=(size, size))
    # symmetric and diagonally dominant: a stand-in with the Hessian's pattern and a
    # factorisation of the same fill-in
    matrix = (pattern + pattern.T) + sp.identity(size) * (2.0 * abs(values).sum() / size * 60)
    matrix = matrix.tocsc()

    def timed(fn, calls):
        fn()
        best = np.inf
        for _ in range(5):
            t0 = time.process_time()
            for _ in range(calls):
                fn()
            best = min(best, (time.process_time() - t0) / calls)
        return 1e3 * best

    lu_ms = timed(lambda: splu(matrix), 20)
    eig_ms = timed(lambda: eigsh(matrix, k=1, sigma=0.0, which="LM"), 5)
    # A Cholesky factorisation exists exactly when a symmetric matrix is positive definite:
    # on a stable branch it is the stability test and the Newton solve at once. Banded,
    # after a reverse Cuthill-McKee ordering brings the contact couplings near the diagonal.
    order = reverse_cuthill_mckee(matrix.tocsr(), symmetric_mode=True)
    banded = matrix.tocsr()[order][:, order].tocoo()
    width = int(np.max(np.abs(banded.row - banded.col)))
    upper = np.zeros((width + 1, size))
    keep = banded.col >= banded.row
    upper[width + banded.row[keep] - banded.col[keep], banded.col[keep]] = banded.data[keep]
    cholesky_ms = timed(lambda: cholesky_banded(upper), 20)
    return {"unknowns": size, "nonzeros": matrix.nnz, "colours": count, "lu_ms": lu_ms,
            "eig_ms": eig_ms, "bandwidth": width, "cholesky_ms": cholesky_ms}


def measure(point: dict, elements: int, log) -> dict:
    log(f"running the point {point} at n = {elements} ...")
    cfg, result, cpu = run_point(point, elements, [])
    d = result.diagnostics
    log(f"  {result.status}, {d['steps']} steps, {cpu:.2f} s CPU")
    _, free, free_cpu = run_point(point, elements, ["physics.self_contact=false"])
    free_steps = free.diagnostics["steps"]

    problem = build(cfg)
    arrays = _rod_arrays(problem)
    n = elements
    x = np.ascontiguousarray(result.positions.T)
    v = np.ascontiguousarray(result.velocities.T)
    radius = np.ascontiguousarray(result.radii)
    a0 = problem.rod.radius
    lengths = np.linalg.norm(np.diff(x, axis=1), axis=0)
    k = arrays["contact_k"]
    c = arrays["contact_c"]
    exclusion = int(np.ceil(problem.contact.exclusion * a0 / problem.rod.element_length))
    skin = problem.contact.skin * a0
    cutoff = 2.0 * 1.1 * radius.max() + lengths.max() + skin
    pairs = np.empty((2, 16 * n + 64), dtype=np.int64)
    pairs, n_pairs = K.build_pairs(x, exclusion, cutoff, pairs)
    near = np.empty_like(pairs)
    seg, inv_square, lever = np.empty((3, n)), np.empty(n), np.empty(n)
    dashpots = np.empty((K.DASHPOT_ROWS, pairs.shape[1] + 2 * (n + 1)))
    force = np.zeros_like(x)
    dt = d["dt"]
    inv_mass = 1.0 / arrays["node_mass"]

    parts = {}
    for margin in (problem.contact.near_skin, 0.1):
        n_near = K.near_pairs(x, radius, pairs, n_pairs, margin * a0, near)
        us = best_us(_force_loop, 20000, x, v, radius, near, n_near, k, c, force, dashpots, seg,
                     inv_square, lever)
        parts[f"force loop, near list at {margin:g} a ({n_near} pairs)"] = us
    noted = _force_loop(1, x, v, radius, near, n_near, k, c, force, dashpots, seg, inv_square,
                        lever)
    parts[f"implicit dashpots ({noted} touching pairs)"] = best_us(
        _dashpot_loop, 20000, v.copy(), inv_mass, dashpots, noted, dt)
    reach = np.empty(exclusion + 1)
    next_tight = np.empty(n + 1, dtype=np.int64)
    parts["fold pass"] = best_us(_fold_loop, 20000, x, radius, lengths,
                                 arrays["rest_length"], exclusion, k, reach, next_tight, force)
    near_us = best_us(_near_loop, 5000, x, radius, pairs, n_pairs, 0.1 * a0, near)
    grid_us = best_us(_grid_loop, 5000, x, exclusion, cutoff, pairs)
    near_every = d["steps"] / max(d["near_rebuilds"], 1)
    grid_every = d["steps"] / max(d["rebuilds"], 1)
    parts[f"near list rebuild ({near_us:.1f} µs, every {near_every:.0f} steps)"] = \
        near_us / near_every
    parts[f"candidate list rebuild ({grid_us:.1f} µs for {n_pairs} pairs, every "
          f"{grid_every:.0f} steps)"] = grid_us / grid_every

    # the touching pairs are the ones the force loop noted for the implicit dashpot
    touching = np.stack([dashpots[0, :noted], dashpots[2, :noted]], axis=1).astype(np.int64)
    newton = newton_sizes(n, touching)
    return {"point": point, "elements": n, "status": result.status, "steps": d["steps"],
            "cpu": cpu, "step_us": 1e6 * cpu / d["steps"],
            "free_step_us": 1e6 * free_cpu / free_steps, "parts": parts, "newton": newton,
            "dt": dt, "touching": len(touching)}


def report(m: dict, info: dict) -> str:
    lines = [
        f"Fig 3's point Φa = {m['point']['twist_density']:g}, L/L0 = "
        f"{m['point']['extension']:g} at n = {m['elements']} ({m['status']}, "
        f"{m['steps']} steps of {m['dt']:.3g} s after contact woke, {m['touching']} touching "
        "pairs at its end).",
        "",
        "| per step | µs |",
        "|---|---|",
        f"| whole step with contact (the run: CPU / steps) | {m['step_us']:.2f} |",
        f"| whole step, contact off (same protocol) | {m['free_step_us']:.2f} |",
    ]
    for name, us in m["parts"].items():
        lines.append(f"| {name} | {us:.2f} |")
    nw = m["newton"]
    evals = 3 * nw["colours"]
    force_ms = evals * m["step_us"] / 1e3
    lines += [
        "",
        f"One Newton iteration on this state: {nw['unknowns']} unknowns, {nw['nonzeros']} "
        f"nonzeros; the coloured finite-difference Jacobian takes {nw['colours']} colours × 3 "
        f"= {evals} force evaluations (≤ {force_ms:.2f} ms at a whole step each); sparse LU "
        f"{nw['lu_ms']:.2f} ms; lowest eigenvalue (shift-invert) {nw['eig_ms']:.2f} ms; "
        f"banded Cholesky after reverse Cuthill-McKee ordering (bandwidth {nw['bandwidth']}), "
        f"which exists exactly when the matrix is positive definite, {nw['cholesky_ms']:.2f} ms. "
        f"The dynamic ramp covers 0.1 turns (0.2 s at 0.5 turns/s) in "
        f"{0.2 / m['dt']:.0f} steps, {0.2 / m['dt'] * m['step_us'] / 1e3:.1f} ms.",
        "",
        f"{info['cpu']}, {info['nproc']} CPUs, load {info['load'][0]:.2f} "
        f"{info['load'][1]:.2f} {info['load'][2]:.2f} at the end; "
        f"{datetime.datetime.now():%Y-%m-%d %H:%M}. Parts: CPU time, best of {REPEATS}, "
        "one process, one thread.",
    ]
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--point", default="2.446956,1.056435",
                        help="Φa (rest), L/L0 of a Fig 3 point")
    parser.add_argument("--elements", type=int, default=80)
    parser.add_argument("--write", type=Path, default=None, help="Markdown file to update")
    args = parser.parse_args(argv)
    phi, extension = (float(v) for v in args.point.split(","))
    m = measure({"twist_density": phi, "extension": extension}, args.elements, print)
    text = report(m, machine())
    print(text)
    if args.write:
        write_block(args.write, "step_parts", text)
        from rodphase.studytools import record_current

        record_current("step_cost_fig3", f"{m['step_us']:.2f} µs with contact, "
                       f"{m['free_step_us']:.2f} µs without", source="`make bench-step-parts`")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
