"""The rod at rest: its static residual, stiffness and stability, on the kernel's own physics.

A state (x, Q) of a Problem at given control values is an equilibrium when the loads the
explicit kernel would compute for it at rest (v = w = 0) vanish on its free degrees of
freedom. `loads_at_rest` composes exactly the pieces `kernel.advance` composes in a step
(internal_loads or its neo-Hookean twin, the clamp couples, the external loads), so there
is one copy of every law. Self-contact is added when the model has it (static_model(...,
contact=True)): the kernel's own pair, fold and end-body springs at v = 0
(`contact_loads`), where its dashpot and friction vanish, over the candidate pairs of the
state.

What contact does to Newton's method (measured on the kernel's settled Fig 2b solenoid at
n = 64, the state tests/test_static.py builds): the loads with contact are smooth at the
scale of a Newton step (the remainder of their linearisation grows as the step squared, no
kinks), but it equals the linear change already at 1e-3 of a full step. The full step is
0.4 rest radii and 0.35 rad: the kernel's hold stops at a residual of 1e-3 of the force
scale, and the equilibrium lies that far away along a soft mode (the loops sliding along
each other, ω² ≈ 20 s⁻²). Moving along it to first order presses the stiff pair springs
(10 E per unit overlap and length) at second order, and those forces swamp the soft
mode's. Freezing the closest-point parameters of the pairs leaves the remainder as it is
(within 0.3 %): it is the springs' geometry, not the segments' parametrisation. Newton
with a line search, with a trust region of 0.1 radii, and pseudo-transient continuation
(implicit damped steps: they do not grow past the explicit kernel's step, 5e-5 s) all
crawl from that state (9.7e-4 → 9.2e-4 of the force scale in 60 steps), and a penalty
0.01 to 0.3 times as stiff does not converge either (Newton finds no descent after 13 to
31 steps). And there may be no equilibrium to find: the same solenoid held 40 s with a
tolerance of 1e-7 stops at a residual of 1.3e-5 that then slowly grows, Newton from there
stays at 1.3e-5, and the stability test finds one mode of ω² = −0.38 s⁻² (the loops
creep). The Fig 2a plectoneme at n = 64 held 40 s is the same: the kernel's residual
stops at 5.4e-6 and slowly grows, its stiffness has an eigenvalue at zero (ω² = −0.006
s⁻², within the test's noise floor: neutral, the strands sliding on each other), and
Newton stays at 5.5e-6. Frictionless contact leaves these shapes on a slow drift, not at
an isolated equilibrium. What is left of the residual lies along one or two soft modes:
`solve_beside_soft_modes` leaves the eigen-directions of the mass-weighted stiffness nearest
zero out of the Newton step, and from the kernel's settled solenoid and plectoneme (n = 64 and 80)
the rest converges to 1e-8 in 9-13 steps while the state moves by 0.013-0.033 radii; the force
left along the soft modes is reported (docs/history/performance.md, "A static corrector beside
the soft modes"). Stepped in twist from there (`twisted_further` as the predictor), the
corrector follows such a shape for 0 to 0.1 of Φa only: the shape takes up twist along the
modes the corrector leaves out (docs/history/performance.md, "A twist continuation beside the soft
modes").

Unknowns (`StaticModel.unknowns`):
    the free position components of the nodes (held components are not unknowns), then a
    small body rotation δφ_i of every element in its material frame, applied as the kernel
    turns frames: Q_i ← exp(−[δφ_i]×)·Q_i. Their conjugate loads are the nodal forces (lab) and
    the element torques (material frame), the pairing whose product is the power the kernel's
    kick uses.

The stiffness K = −∂(loads)/∂(unknowns) comes from central differences, all columns whose
loads cannot overlap taken at once (a distance colouring of the rod's band: a node or an
element reaches loads at most REACH blocks away). The dynamics near an equilibrium is
M·ü = −K·u (M: node masses, and the rotary inertia over e as the kick scales it), so the
eigenvalues λ of M⁻¹K are ω²: a real λ < 0 is a mode that grows (divergence).

What the stability test can and cannot prove (`stability`):
- The paper's law is not the gradient of an energy, so K is not symmetric. If the symmetric
  part of M^{-1/2}·K·M^{-1/2} is positive definite (its Cholesky factorization exists), every
  eigenvalue of M⁻¹K has a positive real part: the state is stable against divergence. That
  is sufficient, not necessary: on the twisted straight rod an axial–twist coupling makes the
  whole symmetric part indefinite from ~0.7 of the onset on, where the rod is still stable.
- Otherwise the eigenvalues of M⁻¹K decide: a real part below zero is a growing mode. The six
  nearest zero come first (shift-invert Arnoldi on a sparse LU: milliseconds), since near
  zero is where a mode crosses as a control moves slowly, which is how a twisted rod loses
  stability (its critical pair of helical modes crosses zero together, so det K does not
  change sign: count eigenvalues, never read a determinant); if none of them grows, all the
  eigenvalues are computed (dense: 0.1 s at 478 unknowns, seconds at 958), since a state
  far past an onset has its growing modes far from zero. It does not see flutter (a complex
  pair whose damped growth the kernel's damping could allow): none is known in these scenes.
- With contact, the symmetric test takes a dense Cholesky factorization (the pairs couple
  blocks far apart along the rod, so K is not banded in rod order). Contact switches off
  across a pair's touching point: the test speaks for the pairs that touch at the state.
  It is local: a stable state can still be left by a finite push (the subcritical snap
  of a solenoid).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import scipy.linalg

from . import kernel as k
from ._jit import njit
from .contact import DASHPOT_ROWS, add_body_forces, build_pairs, contact_forces_in, fold_forces
from .model import spread_twist
from .neo_hookean import N_WORK as N_WORK_NEO_HOOKEAN
from .neo_hookean import clamp_couple_neo_hookean, internal_loads_neo_hookean

# a node's position or an element's frame changes loads at most this many blocks away
# (block b = node b and element b): element lengths feed the Voronoi dilatations on both sides
REACH = 3


@njit(cache=True)
def loads_at_rest(x, Q, rod, ends, incompressible, neo_hookean, now, force, torque):
    """Forces (3, n+1) on nodes [N, lab] and torques (3, n) on elements [N m, material frame]
    of the state (x, Q) at rest, with the control values `now` (N_TABLES,) indexed as the
    kernel's tables (T_*). The composition of one kernel step's loads without contact."""
    n = Q.shape[2]
    v = np.zeros((3, n + 1))
    w = np.zeros((3, n))
    dilatation = np.ones(n)
    lengths = rod.rest_length.copy()
    energies = np.zeros(4)
    work = np.zeros((max(k.N_WORK, N_WORK_NEO_HOOKEAN), n))
    clamp = np.empty((3, 3))
    couple = np.empty(8)
    f_stiff = now[k.T_STIFFNESS]
    f_radius = now[k.T_RADIUS]
    r2 = f_radius * f_radius
    fb = f_stiff * r2 * r2
    f_radius_inv = 1.0 / f_radius
    if neo_hookean:
        internal_loads_neo_hookean(x, v, Q, w, rod.rest_length, rod.rest_voronoi, rod.inertia,
                                   rod.shear_stiffness, rod.bend_stiffness, rod.rest_curvature,
                                   rod.rest_shear, rod.local_mask, f_stiff * r2, fb, r2 * r2,
                                   f_radius_inv, now[k.T_LOCAL_TWIST], force, torque,
                                   dilatation, lengths, energies, work, couple)
    else:
        k.internal_loads(x, v, Q, w, rod.rest_length, rod.rest_voronoi, rod.inertia,
                         rod.shear_stiffness, rod.bend_stiffness, rod.rest_curvature,
                         rod.rest_shear, rod.local_mask, incompressible, f_stiff * r2, fb,
                         r2 * r2, f_radius_inv, now[k.T_LOCAL_TWIST], force, torque, dilatation,
                         lengths, energies, work)
    axis = ends.axis
    rc = rod.rest_curvature
    bs = rod.bend_stiffness
    if ends.start_frame_held:
        if neo_hookean:
            k.rotated_frame(ends.start_frame, axis, now[k.T_START_ROTATION], clamp)
            clamp_couple_neo_hookean(clamp, Q[:, :, 0], 0, x, rod.rest_length, rc[0, 0],
                                     rc[1, 0], f_radius_inv * rc[2, 0], fb * bs[0, 0],
                                     fb * bs[1, 0], fb * bs[2, 0], False, torque, force,
                                     energies, couple)
        else:
            k._start_clamp_couple(Q, rod, ends.start_frame, axis, now[k.T_START_ROTATION],
                                  dilatation, f_radius_inv, fb, incompressible, torque,
                                  energies, clamp, couple)
    if ends.end_frame_held:
        if neo_hookean:
            k.rotated_frame(ends.end_frame, axis, now[k.T_END_ROTATION], clamp)
            clamp_couple_neo_hookean(Q[:, :, n - 1], clamp, n - 1, x, rod.rest_length,
                                     rc[0, n - 2], rc[1, n - 2], f_radius_inv * rc[2, n - 2],
                                     fb * bs[0, n - 2], fb * bs[1, n - 2], fb * bs[2, n - 2],
                                     True, torque, force, energies, couple)
        else:
            k._end_clamp_couple(Q, rod, ends.end_frame, axis, now[k.T_END_ROTATION],
                                dilatation, f_radius_inv, fb, incompressible, torque,
                                energies, clamp, couple)
    k._external_loads(x, rod.node_mass, r2, now[k.T_END_FORCE], ends.force_direction,
                      ends.gravity, now[k.T_LOCAL_PULL], ends.segment_first, ends.segment_last,
                      force)


@njit(cache=True)
def _gather(force, torque, free, out):
    """The loads on the unknowns: forces on the free position components, then torques."""
    m = free.shape[1]
    n = torque.shape[1]
    for j in range(m):
        out[j] = force[free[0, j], free[1, j]]
    for i in range(n):
        for c in range(3):
            out[m + 3 * i + c] = torque[c, i]


@njit(cache=True)
def contact_loads(x, rod, ends, now, incompressible, thinning_force, fold, exclusion, pairs,
                  n_pairs, force):
    """Add the self-contact forces of the state x at rest to force (3, n+1): the kernel's
    own pair springs (contact.contact_forces_in, at v = 0, where its dashpot and friction
    vanish) over the candidate `pairs`, its fold springs (contact.fold_forces) if `fold`,
    and the end bodies' (contact.add_body_forces) where `ends` has them, as kernel._contact_
    loads composes them. The radii follow the element lengths as the kernel's do (a0/√e when
    incompressible), and the pair springs pull along thinning elements if `thinning_force`
    (Contact.thinning_force). Returns the number of touching pairs, folds and nodes."""
    n = x.shape[1] - 1
    lengths = np.empty(n)
    dilatation = np.empty(n)
    for i in range(n):
        d0 = x[0, i + 1] - x[0, i]
        d1 = x[1, i + 1] - x[1, i]
        d2 = x[2, i + 1] - x[2, i]
        lengths[i] = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        dilatation[i] = lengths[i] / rod.rest_length[i]
    radius = np.empty(n)
    k._radii(rod.rest_radius, dilatation, now[k.T_RADIUS], incompressible, radius)
    at_rest = np.zeros((3, n + 1))
    touching, _, _, _, _ = contact_forces_in(
        x, at_rest, radius, pairs, n_pairs, rod.contact_k, rod.contact_c, now[k.T_STIFFNESS],
        0.0, 1.0, 1.0 if incompressible and thinning_force else 0.0, force,
        np.empty((DASHPOT_ROWS, 0)), False,
        np.empty((3, n)), np.empty(n), np.empty(n))
    if fold:
        folded, _, _, _ = fold_forces(x, radius, lengths, rod.rest_length, exclusion,
                                      rod.contact_k, now[k.T_STIFFNESS],
                                      np.empty(exclusion + 1),
                                      np.empty(n + 1, dtype=np.int64), force)
        touching += folded
    for which in range(2):  # 0: the start's body, beyond node 0; 1: the end's
        if ends.end_body if which == 1 else ends.start_body:
            on_body, _, _, _ = add_body_forces(
                x, at_rest, radius, rod.contact_k, rod.contact_c, now[k.T_STIFFNESS], which * n,
                2.0 * which - 1.0, ends.axis, ends.body_radius, exclusion, force,
                np.empty((DASHPOT_ROWS, 0)), 0, False)
            touching += on_body
    return touching


@njit(cache=True)
def residual(x, Q, rod, ends, incompressible, neo_hookean, now, free, out):
    """out (m + 3n,): the loads on the unknowns of state (x, Q) at rest (zero at equilibrium)."""
    n = Q.shape[2]
    force = np.zeros((3, n + 1))
    torque = np.zeros((3, n))
    loads_at_rest(x, Q, rod, ends, incompressible, neo_hookean, now, force, torque)
    _gather(force, torque, free, out)


@njit(cache=True)
def stiffness(x, Q, rod, ends, incompressible, neo_hookean, now, free, block_of, columns,
              stride, h_position, h_rotation, K):
    """K (N, N) = −∂(loads on the unknowns)/∂(unknowns) at (x, Q), by central differences;
    only the columns where `columns` (N,) is true (the others are left zero).

    Columns are taken `stride` blocks apart at once (block_of (N,): each unknown's block);
    with stride ≥ 2·REACH + 1 their loads do not overlap, and a column keeps only the rows
    within REACH blocks of its own. stride > the number of blocks gives the plain dense
    difference, one column at a time. x and Q are not changed (copies are perturbed).
    """
    N = block_of.shape[0]
    m = free.shape[1]
    n = Q.shape[2]
    blocks = n + 1
    plus = np.empty(N)
    minus = np.empty(N)
    force = np.zeros((3, n + 1))
    torque = np.zeros((3, n))
    for r in range(N):
        for c in range(N):
            K[r, c] = 0.0
    step = np.zeros((3, n + 1))
    turn = np.zeros((3, n))
    chosen = np.zeros(N, dtype=np.bool_)
    for kind in range(6):  # position component or rotation component, one per column group
        for first in range(min(stride, blocks)):
            # the unknowns of this colour: kind `kind` in blocks first, first + stride, ...
            step[:, :] = 0.0
            turn[:, :] = 0.0
            chosen[:] = False
            for j in range(N):
                if (block_of[j] - first) % stride != 0 or not columns[j]:
                    continue
                if j < m and kind == free[0, j]:
                    step[free[0, j], free[1, j]] = h_position
                    chosen[j] = True
                elif j >= m and kind == 3 + (j - m) % 3:
                    turn[(j - m) % 3, (j - m) // 3] = h_rotation
                    chosen[j] = True
            if not chosen.any():
                continue
            # ± the steps; frames turned as the kernel's drift turns them (exp(∓[φ]×)·Q,
            # exactly the identity where φ = 0)
            xp = x + step
            xm = x - step
            Qp = Q.copy()
            Qm = Q.copy()
            k.rotate_frames(Qp, turn, 1.0)
            k.rotate_frames(Qm, turn, -1.0)
            loads_at_rest(xp, Qp, rod, ends, incompressible, neo_hookean, now, force, torque)
            _gather(force, torque, free, plus)
            loads_at_rest(xm, Qm, rod, ends, incompressible, neo_hookean, now, force, torque)
            _gather(force, torque, free, minus)
            for j in range(N):
                if not chosen[j]:
                    continue
                b = block_of[j]
                h = h_position if j < m else h_rotation
                for r in range(N):
                    if stride <= blocks and abs(block_of[r] - b) > REACH:
                        continue
                    K[r, j] = -(plus[r] - minus[r]) / (2.0 * h)


@dataclasses.dataclass(frozen=True)
class StaticModel:
    """A Problem's rod, ends and control values, as the static functions take them.

    free (2, m) int64: (component, node) of each free position unknown; block_of (N,): the
    block (node b / element b) of each unknown, N = m + 3n; mass (N,): the inertia each
    unknown has in the kernel's kick [kg for positions, kg m² for rotations, the latter over
    the element's dilatation e for the paper's incompressible law, set by `masses`].
    """

    rod: k.RodProperties
    ends: k.Boundary
    incompressible: bool
    neo_hookean: bool
    now: np.ndarray
    free: np.ndarray
    block_of: np.ndarray
    length_scale: float  # m: the element length, for finite-difference steps
    # self-contact as the kernel has it (contact.enabled): the pair springs between elements
    # more than `exclusion` apart, the fold springs inside it if `fold`; skin [m]: how far
    # beyond touching a pair is listed (the kernel's Verlet skin)
    contact: bool = False
    fold: bool = False
    exclusion: int = 1
    skin: float = 0.0
    thinning_force: bool = True  # the pair springs' pull along thinning elements

    @property
    def unknowns(self) -> int:
        return self.block_of.shape[0]

    @property
    def positions(self) -> int:
        return self.free.shape[1]


def static_model(rod: k.RodProperties, ends: k.Boundary, now: np.ndarray, *,
                 incompressible: bool, neo_hookean: bool, contact: bool = False,
                 fold: bool = False, exclusion: int = 1, skin: float = 0.0,
                 thinning_force: bool = True) -> StaticModel:
    """The unknowns of a rod held by `ends`: every node component not held, every frame.
    With `contact`, the loads include self-contact (see StaticModel)."""
    n = rod.rest_length.shape[0]
    free = []
    for i in range(n + 1):
        for c in range(3):
            held = (i == 0 and ends.start_held[c]) or (i == n and ends.end_held[c])
            if not held:
                free.append((c, i))
    free = np.array(free, dtype=np.int64).T.reshape(2, -1).copy()
    block_of = np.concatenate([free[1], np.repeat(np.arange(n), 3)]).astype(np.int64)
    return StaticModel(rod, ends, bool(incompressible), bool(neo_hookean),
                       np.asarray(now, dtype=float), free, block_of,
                       float(np.mean(rod.rest_length)), bool(contact), bool(fold),
                       int(exclusion), float(skin), bool(thinning_force))


def loads(model: StaticModel, x: np.ndarray, Q: np.ndarray,
          pairs: np.ndarray | None = None) -> np.ndarray:
    """(N,) loads on the unknowns of the state (x (3, n+1), Q (3, 3, n)) at rest, self-contact
    included if the model has it (over `pairs` (2, P), default the candidates of x)."""
    out = np.empty(model.unknowns)
    residual(x, Q, model.rod, model.ends, model.incompressible, model.neo_hookean, model.now,
             model.free, out)
    if model.contact:
        force = contact_force(model, x, pairs)
        out[:model.positions] += force[model.free[0], model.free[1]]
    return out


def candidate_pairs(model: StaticModel, x: np.ndarray) -> np.ndarray:
    """(2, P) the element pairs that could touch near x: more than `exclusion` apart along
    the rod, midpoints within two radii, an element and the skin (as the kernel lists them)."""
    lengths = np.linalg.norm(np.diff(x, axis=1), axis=0)
    radius = contact_radii(model, lengths)
    cutoff = 2.2 * radius.max() + lengths.max() + model.skin
    pairs, count = build_pairs(np.ascontiguousarray(x), model.exclusion, cutoff,
                               np.empty((2, 4 * len(lengths)), dtype=np.int64))
    return np.ascontiguousarray(pairs[:, :count])


def contact_radii(model: StaticModel, lengths: np.ndarray) -> np.ndarray:
    """(n,) the current radii [m] of elements this long, as the kernel's contact takes them."""
    radius = model.rod.rest_radius * model.now[k.T_RADIUS]
    if model.incompressible:
        radius = radius / np.sqrt(lengths / model.rod.rest_length)
    return radius


def contact_force(model: StaticModel, x: np.ndarray,
                  pairs: np.ndarray | None = None) -> np.ndarray:
    """(3, n+1) the self-contact forces on the nodes at rest (zero without contact)."""
    x = np.ascontiguousarray(x, dtype=float)
    force = np.zeros_like(x)
    if model.contact:
        pairs = candidate_pairs(model, x) if pairs is None else pairs
        contact_loads(x, model.rod, model.ends, model.now, model.incompressible,
                      model.thinning_force, model.fold, model.exclusion, pairs, pairs.shape[1],
                      force)
    return force


def _ends_with_bodies(model: StaticModel) -> list[int]:
    n = model.rod.rest_length.shape[0]
    return [end for end, on in ((0, model.ends.start_body), (n, model.ends.end_body)) if on]


def _near_body(model: StaticModel, x: np.ndarray, end: int) -> np.ndarray:
    """The nodes that could touch the body at node `end` (contact.add_body_forces' cylinder
    on the axis beyond it) within the skin: not behind its cap by more than a radius and the
    skin, not farther from its axis than its radius, a rod's and the skin."""
    lengths = np.linalg.norm(np.diff(x, axis=1), axis=0)
    widest = contact_radii(model, lengths).max()
    side = 1.0 if end else -1.0
    relative = x - x[:, end:end + 1]
    along = side * (np.asarray(model.ends.axis) @ relative)
    across = np.linalg.norm(relative - np.outer(side * np.asarray(model.ends.axis), along), axis=0)
    margin = widest + model.skin
    return np.flatnonzero((along > -margin) & (across < model.ends.body_radius + margin))


def contact_stiffness(model: StaticModel, x: np.ndarray) -> np.ndarray:
    """(N, N) −∂(contact loads)/∂(unknowns) at x: non-zero in the position unknowns only
    (contact forces act on nodes and depend on nodes). Central differences, the nodes
    coloured so that two nodes of one colour never reach a common node: node a reaches the
    nodes of every candidate pair one of its elements is in, (folds) the nodes within
    `exclusion` of it, and (end bodies) the end node if it is near a body; the two nodes of
    the most stretched element reach everything (its radius bounds every fold). The
    candidate pairs of x are kept for every perturbation."""
    N = model.unknowns
    K = np.zeros((N, N))
    if not model.contact:
        return K
    x = np.ascontiguousarray(x, dtype=float)
    n = x.shape[1] - 1
    pairs = candidate_pairs(model, x)
    # reach[a, b]: moving node a changes the contact force on node b (boolean arrays: with
    # Python sets a call took 54-65 ms at n = 80, with these 14-15 ms, docs/history/performance.md)
    nodes = np.arange(n + 1)
    if model.fold:
        reach = np.abs(nodes[:, None] - nodes[None, :]) <= model.exclusion + 1
    else:
        reach = np.eye(n + 1, dtype=bool)
    quads = np.stack([pairs[0], pairs[0] + 1, pairs[1], pairs[1] + 1], axis=1)  # (P, 4)
    reach[quads[:, :, None], quads[:, None, :]] = True
    if model.fold and model.incompressible:
        # the fold bound takes the smallest radius over the rod (contact.fold_forces), that of
        # the most stretched element: its two nodes reach every fold, wherever it is
        thinnest = int(np.argmax(np.linalg.norm(np.diff(x, axis=1), axis=0)
                                 / model.rod.rest_length))
        reach[thinnest:thinnest + 2, :] = True
    # a node near an end body is pushed by it, with the reaction on the end node that
    # carries the body; the node's radius follows its two elements, so its neighbours too
    for end in _ends_with_bodies(model):
        near = _near_body(model, x, end)
        pushed = np.unique(np.concatenate([near, np.maximum(near - 1, 0),
                                           np.minimum(near + 1, n)]))
        for a in pushed:
            reach[a, [max(a - 1, 0), a, min(a + 1, n), end]] = True
        reach[end, pushed] = True
        reach[end, end] = True
    # greedy colouring in node order: a node takes the first colour none of the nodes it
    # shares a reached node with has taken
    shares = (reach.astype(np.int64) @ reach.T.astype(np.int64)) > 0
    colour = np.full(n + 1, -1)
    for a in range(n + 1):
        taken = colour[shares[a] & (colour >= 0)]
        free_colours = np.setdiff1d(np.arange(n + 2), taken)
        colour[a] = free_colours[0]
    index = np.full((3, n + 1), -1)  # the unknown of each free position component
    index[model.free[0], model.free[1]] = np.arange(model.positions)
    h = 1e-6 * model.length_scale
    for c in range(colour.max() + 1):
        members = np.flatnonzero(colour == c)
        for comp in range(3):
            step = np.zeros_like(x)
            step[comp, members] = h
            difference = (contact_force(model, x + step, pairs)
                          - contact_force(model, x - step, pairs)) / (2.0 * h)
            for a in members:
                column = index[comp, a]
                if column < 0:
                    continue
                reached = np.flatnonzero(reach[a])
                rows = index[:, reached]
                ok = rows >= 0
                K[rows[ok], column] = -difference[:, reached][ok]
    return K


def stiffness_matrix(model: StaticModel, x: np.ndarray, Q: np.ndarray, *,
                     dense: bool = False, columns: np.ndarray | None = None) -> np.ndarray:
    """K (N, N) = −∂loads/∂unknowns at (x, Q). Central differences of step 1e-6 of the
    element length and 1e-6 rad: truncation ~1e-12 and round-off ~1e-10 of the loads' scale.
    `dense` takes one column at a time (a check of the colouring); `columns` (indices) only
    those columns, the others left zero."""
    N = model.unknowns
    K = np.empty((N, N))
    n = Q.shape[2]
    stride = n + 2 if dense else 2 * REACH + 1
    wanted = np.ones(N, dtype=np.bool_)
    if columns is not None:
        wanted[:] = False
        wanted[columns] = True
    stiffness(np.ascontiguousarray(x), np.ascontiguousarray(Q), model.rod, model.ends,
              model.incompressible, model.neo_hookean, model.now, model.free, model.block_of,
              wanted, stride, 1e-6 * model.length_scale, 1e-6, K)
    if model.contact:
        contact = contact_stiffness(model, x)
        K[:, wanted] += contact[:, wanted]
    return K


def masses(model: StaticModel, x: np.ndarray) -> np.ndarray:
    """(N,) the inertia of each unknown as the kernel's kick applies it."""
    rod = model.rod
    n = rod.rest_length.shape[0]
    r2 = model.now[k.T_RADIUS] ** 2
    node = rod.node_mass[model.free[1]] * r2
    e = np.linalg.norm(np.diff(x, axis=1), axis=0) / rod.rest_length
    factor = e if (model.incompressible and not model.neo_hookean) else np.ones(n)
    rotary = (rod.inertia * r2 * r2 / factor[None, :]).T.reshape(-1)
    return np.concatenate([node, rotary])


def mass_weighted(model: StaticModel, x: np.ndarray, K: np.ndarray,
                  unknowns: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(A, scale): A = M^{-1/2}·K·M^{-1/2} [1/s²], whose eigenvalues are the squared
    frequencies of the undamped motions about the state (negative: a mode that grows), and
    scale = M^{-1/2} (M: `masses` at x). With `unknowns`, the block of those rows and columns
    of K only (the lateral block of the straight rod, rod/onset.py). The one place the
    stability test, the onset and the corrector scale K: their eigenvalues must agree."""
    scale = 1.0 / np.sqrt(masses(model, x))
    if unknowns is not None:
        scale = scale[unknowns]
        K = K[np.ix_(unknowns, unknowns)]
    return K * scale[:, None] * scale[None, :], scale


def rod_order(block_of: np.ndarray) -> tuple[np.ndarray, int]:
    """(order, width): the unknowns sorted by block (rod order, in which the stiffness is
    banded: an unknown reaches REACH blocks) and the half bandwidth that follows."""
    order = np.argsort(block_of, kind="stable")
    blocks = block_of[order]
    reach = np.searchsorted(blocks, blocks + REACH, side="right") - 1 - np.arange(len(order))
    return order, int(reach.max())


def symmetric_band(A: np.ndarray, width: int) -> np.ndarray:
    """The symmetric part of A (in rod order) in LAPACK's upper banded storage
    ((width + 1, N): row width − d holds diagonal d), for cholesky_banded and eig_banded."""
    band = np.zeros((width + 1, A.shape[0]))
    for d in range(width + 1):
        band[width - d, d:] = 0.5 * (np.diagonal(A, d) + np.diagonal(A, -d))
    return band


@dataclasses.dataclass(frozen=True)
class Stability:
    """What `stability` found for one state.

    stable: no eigenvalue of M⁻¹K with a negative real part (or the symmetric test passed);
    unstable_modes: how many have one, among the NEAR_ZERO nearest zero when one of those
    does (a lower bound then), else among all; lowest: the smallest real part among those
    looked at [1/s², ω²];
    by: "symmetric part" (a Cholesky factorization proved it) or "eigenvalues";
    mode: (n+1, 3) node displacement of the most unstable mode (largest row norm 1), None when
    stable; mode_rotation: (n, 3) its frame rotations (material, rad per unit of mode).
    """

    stable: bool
    unstable_modes: int
    lowest: float
    by: str
    mode: np.ndarray | None = None
    mode_rotation: np.ndarray | None = None


def stability(model: StaticModel, x: np.ndarray, Q: np.ndarray,
              K: np.ndarray | None = None) -> Stability:
    """Is the rest state (x, Q) stable? See the module docstring for what this proves.

    An eigenvalue counts as negative below −1e-9 of the largest diagonal entry of M⁻¹K (the
    finite-difference noise of K is ~1e-10 of its scale)."""
    if K is None:
        K = stiffness_matrix(model, x, Q)
    A, scale = mass_weighted(model, x, K)
    order, width = rod_order(model.block_of)
    try:
        if model.contact:  # pairs couple nodes far apart: not banded in rod order
            np.linalg.cholesky(0.5 * (A + A.T))
        else:  # banded in rod order: O(N·width²), a millisecond where a dense one takes 100
            scipy.linalg.cholesky_banded(symmetric_band(A[np.ix_(order, order)], width),
                                         check_finite=False)
        return Stability(True, 0, math.nan, "symmetric part")
    except np.linalg.LinAlgError:
        pass
    floor = -1e-9 * float(np.abs(np.diagonal(A)).max())
    values, vectors = _eigenvalues_near_zero(A, K.shape[0])
    if not np.any(values.real < floor):
        # none of those nearest zero grows: a mode far below zero still could (a state far
        # past an onset), so every eigenvalue is looked at (seconds at 958 unknowns, rare)
        values, vectors = scipy.linalg.eig(A, check_finite=False)
    negative = np.flatnonzero(values.real < floor)
    lowest = float(values.real.min())
    if not len(negative):
        return Stability(True, 0, lowest, "eigenvalues")
    worst = int(np.argmin(values.real))
    vector = (_fixed_phase(vectors[:, worst]) * scale).real
    n = Q.shape[2]
    m = model.positions
    mode = np.zeros((n + 1, 3))
    mode[model.free[1], model.free[0]] = vector[:m]
    rotation = vector[m:].reshape(n, 3)
    size = np.linalg.norm(mode, axis=1).max()
    if size > 0:
        mode, rotation = mode / size, rotation / size
    return Stability(False, int(len(negative)), lowest, "eigenvalues", mode, rotation)


# eigenvalues of M⁻¹K asked for when the symmetric test fails: the critical pair of a twisted
# rod and a few more, so that a pair is counted whole
NEAR_ZERO = 6


# ARPACK starts from a random vector unless given one, and its eigenvectors (their phase, and
# the basis it picks in a degenerate pair's plane) follow that start: the stability push of a
# hold took its direction from them, so the same run ended straight in one process and as a
# solenoid in another (issue #46). A fixed, generic start makes every solve a function of A.
ARNOLDI_START_SEED = 46


def _arnoldi_start(size: int) -> np.ndarray:
    """(size,) the fixed start vector of every Arnoldi solve: seeded normal entries, so that
    it has a component on any mode (a constant vector can miss one by symmetry)."""
    return np.random.default_rng(ARNOLDI_START_SEED).standard_normal(size)


def _fixed_phase(vector: np.ndarray) -> np.ndarray:
    """An eigenvector with its arbitrary phase (sign, for a real one) fixed: turned so that
    its largest entry is real and positive. Its real part is then the same direction whichever
    solver, start or thread count produced it."""
    largest = vector[int(np.argmax(np.abs(vector)))]
    return vector * (abs(largest) / largest) if largest != 0 else vector


def _eigenvalues_near_zero(A: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray]:
    """The NEAR_ZERO eigenvalues of A nearest zero and their vectors: shift-invert Arnoldi on
    a sparse LU (A is banded in rod order; O(N) per solve), or every eigenvalue of a small A.
    Near zero is where a mode goes unstable as a control moves; a mode far below zero grows
    fast, and the kernel's probe sees it."""
    if size <= 4 * NEAR_ZERO:
        return scipy.linalg.eig(A, check_finite=False)
    from scipy.sparse import csc_matrix
    from scipy.sparse.linalg import eigs

    return eigs(csc_matrix(A), k=NEAR_ZERO, sigma=0.0, which="LM", tol=1e-10,
                v0=_arnoldi_start(size))


def displaced(x: np.ndarray, Q: np.ndarray, mode: np.ndarray, rotation: np.ndarray,
              size: float) -> tuple[np.ndarray, np.ndarray]:
    """(x, Q) moved by `size` along a mode of `stability` (mode (n+1, 3), rotation (n, 3)):
    nodes by size·mode, frames by exp(−[size·rotation_i]×), as the kernel turns them."""
    from scipy.spatial.transform import Rotation

    turns = Rotation.from_rotvec(-size * np.asarray(rotation, float)).as_matrix()  # (n, 3, 3)
    Q = np.ascontiguousarray(np.einsum("irs,sci->rci", turns, Q))
    return np.ascontiguousarray(x + size * mode.T), Q


def twisted_further(x: np.ndarray, Q: np.ndarray, angle: float) -> tuple[np.ndarray, np.ndarray]:
    """(x, Q) with `angle` [rad] more twist spread evenly along the rod: element i's frame
    turned about its own d3 by angle·(i + ½)/n (model.spread_twist, as straight_state);
    the nodes stay. The predictor of a step in the end rotation: a turned end's twist
    spreads along the whole rod, evenly on the straight branch (this is its equilibrium at
    the new rotation, tests/test_static.py) and nearly so on a coiled one (measured on Fig
    2b's solenoid, n = 64, +0.025 in Φa: a residual of 0.062 of the force scale against 7.9
    with the frames left as they were)."""
    n = Q.shape[2]
    turn = np.zeros((n, 3))
    turn[:, 2] = spread_twist(angle, n)
    return displaced(x, Q, np.zeros((n + 1, 3)), turn, 1.0)


@dataclasses.dataclass(frozen=True)
class Solution:
    """What `solve` found (it reports, it does not raise: a caller decides what a failed
    Newton solve means, a fold or a jump).

    x (3, n+1), Q (3, 3, n): the last iterate; success: the residual fell below the tolerance;
    residual: its largest free nodal force or element torque per element length, over the
    force scale; iterations: Newton steps taken; message: why it stopped.
    """

    x: np.ndarray
    Q: np.ndarray
    success: bool
    residual: float
    iterations: int
    message: str


def residual_norm(model: StaticModel, r: np.ndarray) -> float:
    """The kernel's residual measure [N]: the largest free nodal force and element torque per
    element length (as kernel._guards takes it), of the loads r (N,)."""
    m = model.positions
    n = (model.unknowns - m) // 3
    force = np.zeros((3, n + 1))
    force[model.free[0], model.free[1]] = r[:m]
    torque = r[m:].reshape(n, 3)
    return float(max(np.linalg.norm(force, axis=0).max(),
                     (np.linalg.norm(torque, axis=1) / model.rod.rest_length).max()))


def step_along(model: StaticModel, x: np.ndarray, Q: np.ndarray,
               du: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(x, Q) moved by du (N,): the free position components by their entries, the frames
    turned by their rotation vectors as the kernel turns them."""
    m = model.positions
    n = Q.shape[2]
    mode = np.zeros((n + 1, 3))
    mode[model.free[1], model.free[0]] = du[:m]
    return displaced(x, Q, mode, du[m:].reshape(n, 3), 1.0)


def newton_step(model: StaticModel, K: np.ndarray, r: np.ndarray, order: np.ndarray,
                width: int) -> np.ndarray:
    """du (N,) with K·du = r. Without contact K is banded in rod order (banded LU); contact
    couples nodes far apart along the rod, and a sparse LU (SuperLU, its own fill-reducing
    ordering) takes the band and the pairs' blocks together."""
    if model.contact:
        from scipy.sparse import csc_matrix
        from scipy.sparse.linalg import splu

        return splu(csc_matrix(K)).solve(r)
    K = K[np.ix_(order, order)]
    band = np.zeros((2 * width + 1, len(order)))
    for d in range(-width, width + 1):  # ab[width + i - j, j] = K[i, j]
        band[width - d, max(d, 0):len(order) + min(d, 0)] = np.diagonal(K, d)
    du_ordered = scipy.linalg.solve_banded((width, width), band, r[order], check_finite=False)
    du = np.empty_like(du_ordered)
    du[order] = du_ordered
    return du


def solve(model: StaticModel, x: np.ndarray, Q: np.ndarray, *, force_scale: float,
          tolerance: float = 1e-8, max_iterations: int = 50) -> Solution:
    """Newton's method for the rest state nearest (x, Q): K·du = loads, banded LU in rod order
    (an unknown reaches REACH blocks), with a backtracking line search on the residual
    (halving up to 30 times). Converged when residual_norm < tolerance × force_scale."""
    order, width = rod_order(model.block_of)  # K is banded in rod order
    x, Q = np.ascontiguousarray(x, dtype=float), np.ascontiguousarray(Q, dtype=float)
    r = loads(model, x, Q)
    norm = residual_norm(model, r)
    for iteration in range(max_iterations + 1):
        if norm < tolerance * force_scale:
            return Solution(x, Q, True, norm / force_scale, iteration, "converged")
        if iteration == max_iterations:
            break
        try:
            du = newton_step(model, stiffness_matrix(model, x, Q), r, order, width)
        except (np.linalg.LinAlgError, ValueError, RuntimeError) as error:
            return Solution(x, Q, False, norm / force_scale, iteration,
                            f"singular stiffness ({error}): a fold or a bifurcation")
        scale = 1.0
        for _ in range(30):
            x_try, Q_try = step_along(model, x, Q, scale * du)
            r_try = loads(model, x_try, Q_try)
            norm_try = residual_norm(model, r_try)
            if np.isfinite(norm_try) and norm_try < norm:
                break
            scale *= 0.5
        else:
            m = model.positions
            if (np.abs(du[:m]).max(initial=0.0) < 1e-12 * model.length_scale * len(du)
                    and np.abs(du[m:]).max(initial=0.0) < 1e-12 * len(du)):
                # the Newton step is round-off of the loads (E·A·1e-16 can exceed a small
                # tolerance × a small load): the state is the solution to working precision
                return Solution(x, Q, True, norm / force_scale, iteration,
                                "converged to round-off (residual at the loads' round-off)")
            return Solution(x, Q, False, norm / force_scale, iteration,
                            "no step along the Newton direction lowers the residual")
        x, Q, r, norm = x_try, Q_try, r_try, norm_try
    return Solution(x, Q, False, norm / force_scale, max_iterations,
                    f"not converged in {max_iterations} Newton steps")


def _real_basis(vectors: np.ndarray, count: int) -> np.ndarray:
    """(N, count) an orthonormal real basis of the span of `vectors` (N, k), complex ones
    taken with their conjugates (a complex pair spans a real plane)."""
    both = np.concatenate([vectors.real, vectors.imag], axis=1)
    U, s, _ = np.linalg.svd(both, full_matrices=False)
    return U[:, :count]


@dataclasses.dataclass(frozen=True)
class SoftFactorization:
    """The factorized Newton system of `solve_beside_soft_modes` at one state, reusable at
    states nearby (chord iterations, the next step of a continuation).

    With A = M^{-1/2}·K·M^{-1/2} (M: `masses`), right (N, k) and left (N, k): orthonormal
    real bases of the eigenvectors of A and of Aᵀ for its k eigenvalues nearest zero, `values`
    (k,) [1/s², complex for a pair]. The bordered system [A left; rightᵀ 0]·(y, μ) = (g, 0)
    has a unique solution when the rest of A is regular: y is the Newton step (mass-weighted)
    with no component along the soft modes, for the loads g with the part along `left`
    (which A cannot balance) taken off by μ.
    """

    root_mass: np.ndarray
    right: np.ndarray
    left: np.ndarray
    values: np.ndarray
    bordered: object  # scipy.sparse.linalg.SuperLU of the bordered matrix

    def split(self, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(outside, along): the loads r (N,) outside and along the soft directions."""
        g = r / self.root_mass
        along = self.left @ (self.left.T @ g)
        return (g - along) * self.root_mass, along * self.root_mass

    def merit(self, r: np.ndarray) -> float:
        """The mass-weighted 2-norm of the loads outside the soft directions."""
        g = r / self.root_mass
        return float(np.linalg.norm(g - self.left @ (self.left.T @ g)))

    def step(self, r: np.ndarray) -> np.ndarray:
        """du (N,): the Newton step for the loads r beside the soft modes."""
        kept = len(self.root_mass)
        rhs = np.concatenate([r / self.root_mass, np.zeros(self.right.shape[1])])
        return self.bordered.solve(rhs)[:kept] / self.root_mass


def soft_factorization(model: StaticModel, x: np.ndarray, Q: np.ndarray,
                       soft_modes: int) -> SoftFactorization:
    """The bordered Newton system beside the `soft_modes` eigenvalues of A nearest zero at
    (x, Q), factorized (SuperLU). The soft directions by shift-invert Arnoldi on a sparse LU
    of A (of A and of Aᵀ: K is not symmetric); a dense eigensolver for a small A."""
    from scipy.sparse import bmat, csc_matrix
    from scipy.sparse.linalg import LinearOperator, eigs, splu

    A, scale = mass_weighted(model, x, stiffness_matrix(model, x, Q))
    root_mass = 1.0 / scale
    A = csc_matrix(A)
    N = A.shape[0]
    if N <= 4 * (soft_modes + 2):
        values, left, right = scipy.linalg.eig(A.toarray(), left=True, right=True)
        nearest = np.argsort(np.abs(values))[:soft_modes]
        values, right, left = values[nearest], right[:, nearest], left[:, nearest]
    else:
        # near zero, A's LU (shift 0) is the shift-invert operator of both A and Aᵀ
        lu = splu(A)
        inverse = LinearOperator((N, N), matvec=lu.solve, dtype=float)
        inverse_t = LinearOperator((N, N), matvec=lambda b: lu.solve(b, trans="T"),
                                   dtype=float)
        values, right = eigs(A, k=soft_modes, sigma=0.0, OPinv=inverse, which="LM", tol=1e-8,
                             v0=_arnoldi_start(N))
        _, left = eigs(A.T.tocsc(), k=soft_modes, sigma=0.0, OPinv=inverse_t, which="LM",
                       tol=1e-8, v0=_arnoldi_start(N))
    right, left = _real_basis(right, soft_modes), _real_basis(left, soft_modes)
    bordered = splu(bmat([[A, csc_matrix(left)], [csc_matrix(right.T), None]], format="csc"))
    order = np.argsort(-np.abs(values))  # smallest last
    return SoftFactorization(root_mass, right, left, values[order], bordered)


@dataclasses.dataclass(frozen=True)
class SoftSolution:
    """What `solve_beside_soft_modes` found.

    x (3, n+1), Q (3, 3, n): the last iterate; success: the residual outside the soft
    directions fell below the tolerance; residual: that residual (the kernel's measure, over
    the force scale); soft_residual: the residual left along the soft directions (same
    measure): the force that would still move the state along them, slowly (the creep of a
    coil or braid held by frictionless contact); soft_values: the eigenvalues of the
    mass-weighted stiffness M^{-1/2}·K·M^{-1/2} [1/s²] that were left out, smallest in
    magnitude last (complex for a pair); iterations: Newton steps taken; factorizations:
    how many of them formed and factorized the stiffness (the others reused it: chord
    steps); factorization: the last one, for a caller to start the next solve from; message:
    why it stopped.
    """

    x: np.ndarray
    Q: np.ndarray
    success: bool
    residual: float
    soft_residual: float
    soft_values: np.ndarray
    iterations: int
    factorizations: int
    factorization: SoftFactorization
    message: str


# a chord step (a reused factorization) is kept when it cuts the merit at least this much;
# otherwise the stiffness is formed again at the current state (a fresh Newton step
# converges quadratically near the solution, a chord step linearly at the rate its
# factorization's age allows)
CHORD_CONTRACTION = 0.5


def solve_beside_soft_modes(model: StaticModel, x: np.ndarray, Q: np.ndarray, *,
                            soft_modes: int, force_scale: float, tolerance: float = 1e-8,
                            max_iterations: int = 30,
                            factorization: SoftFactorization | None = None) -> SoftSolution:
    """Newton's method on every direction but the `soft_modes` eigen-directions of the
    mass-weighted stiffness A = M^{-1/2}·K·M^{-1/2} nearest zero.

    Why: a shape the kernel settles under frictionless self-contact is not an isolated
    equilibrium. What is left of its residual lies along one or two soft directions
    (eigenvalues of A from −5 to 500 s⁻² where its largest is ~1e8: the loops creep or
    slide), and plain Newton (`solve`) takes huge steps along them and stalls. Left out, the
    rest converges quadratically, and what remains is a force along the soft modes alone,
    reported (`soft_residual`), not hidden (measured: docs/history/performance.md, "A static
    corrector beside the soft modes").

    Each step solves the bordered system of `soft_factorization` (sparse LU) for the loads.
    A step from a factorization of an earlier state (a chord step: `factorization` given, or
    the last one reused) is kept when it cuts the merit (the mass-weighted 2-norm of the
    loads outside the soft directions) by CHORD_CONTRACTION; otherwise the stiffness is
    formed again. A fresh step is line-searched (halving) on that merit: a Newton direction
    lowers the 2-norm, not necessarily the kernel's max norm.
    """
    if not 0 < soft_modes < model.unknowns:
        raise ValueError(f"soft_modes: {soft_modes} (allowed: 1 to {model.unknowns - 1})")
    x, Q = np.ascontiguousarray(x, dtype=float), np.ascontiguousarray(Q, dtype=float)
    factorizations = 0
    fresh = factorization is None
    if fresh:
        factorization = soft_factorization(model, x, Q, soft_modes)
        factorizations = 1
    iteration = 0
    r = loads(model, x, Q)
    while True:
        outside, along = factorization.split(r)
        norm = residual_norm(model, outside) / force_scale
        soft = residual_norm(model, along) / force_scale

        def report(success: bool, message: str) -> SoftSolution:
            return SoftSolution(x, Q, success, norm, soft, factorization.values, iteration,
                                factorizations, factorization, message)

        if norm < tolerance:
            return report(True, "converged")
        if iteration == max_iterations:
            return report(False, f"not converged in {max_iterations} Newton steps")
        merit = factorization.merit(r)
        du = factorization.step(r)
        if not fresh:  # a chord step: kept if it contracts, else the stiffness anew
            x_try, Q_try = step_along(model, x, Q, du)
            r_try = loads(model, x_try, Q_try)
            merit_try = factorization.merit(r_try)
            if np.isfinite(merit_try) and merit_try < CHORD_CONTRACTION * merit:
                x, Q, r = x_try, Q_try, r_try
                iteration += 1
                continue
            factorization = soft_factorization(model, x, Q, soft_modes)
            factorizations += 1
            fresh = True
            continue
        scale = 1.0
        for _ in range(30):
            x_try, Q_try = step_along(model, x, Q, scale * du)
            r_try = loads(model, x_try, Q_try)
            merit_try = factorization.merit(r_try)
            if np.isfinite(merit_try) and merit_try < merit:
                break
            scale *= 0.5
        else:
            return report(False, "no step along the Newton direction lowers the residual")
        x, Q, r = x_try, Q_try, r_try
        iteration += 1
        fresh = False  # the next step reuses this factorization while it contracts
