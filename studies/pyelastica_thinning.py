"""PyElastica 1.0's rod self-contact with rodphase's thinning force added (issue #49).

rodphase's contact (rodphase/rod/contact.py, `contact_forces_in` with `thinning`) adds the
rest of the gradient of ½kδ² for an incompressible rod: the overlap δ = a_i + a_j − d depends
on the element lengths through the radii a = a0·√(l0/l), so ∂δ/∂l_i = −a_i/(2 l_i) and the
pair pushes the two nodes of each of its elements apart along the element by k·δ·a/(2l).

PyElastica 1.0 also thins its radius (cosserat_rod.py: radius = √(volume / length / π)), but
its `_calculate_contact_forces_self_rod` keeps only the normal force. `ThinningSelfContact`
is `RodSelfContact(k, nu)` with that one term added, so that the authors' code can be run
with the same contact energy as rodphase: a like-for-like comparison of the SolenoidsCase.

The pair loop below is PyElastica's own (same skip, same bounding test, same closest points,
same 4/3 and 2/3 split at the rod's ends, same unclipped dashpot); only the last block, the
thinning term, is new. Written anew for this study; the algorithm is PyElastica's.
"""

from __future__ import annotations

import numpy as np
from numba import njit

import elastica as ea
from elastica._linalg import _batch_product_k_ik_to_ik
from elastica.contact_utils import _dot_product, _find_min_dist, _norm


@njit(cache=True)
def _closest(x, e, i, j):
    """PyElastica's `_find_min_dist(x_i, e_i, x_j, e_j)`, first return value (the vector from
    the closest point of segment i to that of segment j), in scalars: every sum and product in
    PyElastica's order, so the result is bit-identical (checked in tests), without the 3-vectors
    it allocates (most of its cost per step in a solenoid)."""
    x10, x11, x12 = x[0, i], x[1, i], x[2, i]
    e10, e11, e12 = e[0, i], e[1, i], e[2, i]
    x20, x21, x22 = x[0, j], x[1, j], x[2, j]
    e20, e21, e22 = e[0, j], e[1, j], e[2, j]
    e1e1 = 0.0 + e10 * e10 + e11 * e11 + e12 * e12
    e1e2 = 0.0 + e10 * e20 + e11 * e21 + e12 * e22
    e2e2 = 0.0 + e20 * e20 + e21 * e21 + e22 * e22
    x1e1 = 0.0 + x10 * e10 + x11 * e11 + x12 * e12
    x1e2 = 0.0 + x10 * e20 + x11 * e21 + x12 * e22
    x2e1 = 0.0 + e10 * x20 + e11 * x21 + e12 * x22
    x2e2 = 0.0 + x20 * e20 + x21 * e21 + x22 * e22
    s = 0.0
    t = 0.0
    parallel = abs(1.0 - e1e2**2 / (e1e1 * e2e2)) < 1e-6
    if parallel:
        t = (x2e1 - x1e1) / e1e1
        t = max(0.0, min(t, 1.0))
        s = (x1e2 + t * e1e2 - x2e2) / e2e2
        s = max(0.0, min(s, 1.0))
    else:
        s = (e1e1 * (x1e2 - x2e2) + e1e2 * (x2e1 - x1e1)) / (e1e1 * e2e2 - (e1e2) ** 2)
        t = (e1e2 * s + x2e1 - x1e1) / e1e1
        if (s < 0.0) or (s > 1.0) or (t < 0.0) or (t > 1.0):
            pt = (x2e1 - x1e1) / e1e1
            s = 0.0
            t = max(0.0, min(pt, 1.0))
            a0 = x10 + e10 * t - x20
            a1 = x11 + e11 * t - x21
            a2 = x12 + e12 * t - x22
            best = np.sqrt(0.0 + a0 * a0 + a1 * a1 + a2 * a2)
            pt = (x2e1 + e1e2 - x1e1) / e1e1
            pt = max(0.0, min(pt, 1.0))
            a0 = x10 + e10 * pt - x20 - e20
            a1 = x11 + e11 * pt - x21 - e21
            a2 = x12 + e12 * pt - x22 - e22
            d = np.sqrt(0.0 + a0 * a0 + a1 * a1 + a2 * a2)
            if d < best:
                s = 1.0
                t = pt
                best = d
            ps = (x1e2 - x2e2) / e2e2
            ps = max(0.0, min(ps, 1.0))
            a0 = x20 + ps * e20 - x10
            a1 = x21 + ps * e21 - x11
            a2 = x22 + ps * e22 - x12
            d = np.sqrt(0.0 + a0 * a0 + a1 * a1 + a2 * a2)
            if d < best:
                s = ps
                t = 0.0
                best = d
            ps = (x1e2 + e1e2 - x2e2) / e2e2
            ps = max(0.0, min(ps, 1.0))
            a0 = x20 + ps * e20 - x10 - e10
            a1 = x21 + ps * e21 - x11 - e11
            a2 = x22 + ps * e22 - x12 - e12
            d = np.sqrt(0.0 + a0 * a0 + a1 * a1 + a2 * a2)
            if d < best:
                s = ps
                t = 1.0
    return (x20 + s * e20 - x10 - t * e10, x21 + s * e21 - x11 - t * e11,
            x22 + s * e22 - x12 - t * e12)


@njit(cache=True)
def self_contact_with_thinning(x, radius, length, tangent, velocity, external_forces,
                               contact_k, contact_nu, thinning):
    """PyElastica's self-contact force plus `thinning` × k·γ·a/(2l) along each touching
    element (x: the n element start points (3, n); velocity, external_forces (3, n+1)).
    With thinning 0 its forces equal PyElastica's bit for bit (tests/test_crosscheck_pyelastica.py)."""
    n = x.shape[1]
    edge = _batch_product_k_ik_to_ik(length, tangent)
    for i in range(n):
        skip = int(1 + np.ceil(0.8 * np.pi * radius[i] / length[i]))
        for j in range(i - skip, -1, -1):
            radii_sum = radius[i] + radius[j]
            length_sum = length[i] + length[j]
            # PyElastica's bounding test, |x_i − x_j| ≥ radii + lengths, in scalars: the same
            # sum in the same order, without the 3-vector it allocates per pair
            total = 0.0
            for k in range(3):
                dk = x[k, i] - x[k, j]
                total += dk * dk
            if np.sqrt(total) >= radii_sum + length_sum:
                continue
            d0, d1, d2 = _closest(x, edge, i, j)
            distance = np.sqrt(0.0 + d0 * d0 + d1 * d1 + d2 * d2)
            d0 /= distance
            d1 /= distance
            d2 /= distance
            gamma = radii_sum - distance
            if gamma < -1e-5:
                continue
            mask = (gamma > 0.0) * 1.0
            spring = contact_k * gamma
            r0 = 0.5 * ((velocity[0, i] + velocity[0, i + 1]) - (velocity[0, j] + velocity[0, j + 1]))
            r1 = 0.5 * ((velocity[1, i] + velocity[1, i + 1]) - (velocity[1, j] + velocity[1, j + 1]))
            r2 = 0.5 * ((velocity[2, i] + velocity[2, i + 1]) - (velocity[2, j] + velocity[2, j + 1]))
            dashpot = contact_nu * (0.0 + r0 * d0 + r1 * d1 + r2 * d2)
            scale = 0.5 * mask * (dashpot + spring)
            net0 = scale * d0
            net1 = scale * d1
            net2 = scale * d2
            if i == n - 1:
                external_forces[0, i] -= net0 * 4 / 3
                external_forces[1, i] -= net1 * 4 / 3
                external_forces[2, i] -= net2 * 4 / 3
                external_forces[0, i + 1] -= net0 * 2 / 3
                external_forces[1, i + 1] -= net1 * 2 / 3
                external_forces[2, i + 1] -= net2 * 2 / 3
            else:
                external_forces[0, i] -= net0
                external_forces[1, i] -= net1
                external_forces[2, i] -= net2
                external_forces[0, i + 1] -= net0
                external_forces[1, i + 1] -= net1
                external_forces[2, i + 1] -= net2
            if j == 0:
                external_forces[0, j] += net0 * 2 / 3
                external_forces[1, j] += net1 * 2 / 3
                external_forces[2, j] += net2 * 2 / 3
                external_forces[0, j + 1] += net0 * 4 / 3
                external_forces[1, j + 1] += net1 * 4 / 3
                external_forces[2, j + 1] += net2 * 4 / 3
            else:
                external_forces[0, j] += net0
                external_forces[1, j] += net1
                external_forces[2, j] += net2
                external_forces[0, j + 1] += net0
                external_forces[1, j + 1] += net1
                external_forces[2, j + 1] += net2
            if gamma > 0.0 and thinning != 0.0:
                # the new term: the pair's spring k·γ (the whole pair's, as rodphase's) times
                # ∂γ/∂l = −a/(2l), pushing each element's two nodes apart along its tangent
                gi = thinning * spring * radius[i] / (2.0 * length[i])
                gj = thinning * spring * radius[j] / (2.0 * length[j])
                for k in range(3):
                    external_forces[k, i] -= gi * tangent[k, i]
                    external_forces[k, i + 1] += gi * tangent[k, i]
                    external_forces[k, j] -= gj * tangent[k, j]
                    external_forces[k, j + 1] += gj * tangent[k, j]


@njit(cache=True)
def pairs_within_reach(x, radius, length, tangent, margin):
    """Element pairs (PyElastica's skip) closer than radii_sum + margin: 0 means that no
    contact force could have acted on this state."""
    n = x.shape[1]
    edge = _batch_product_k_ik_to_ik(length, tangent)
    count = 0
    for i in range(n):
        skip = int(1 + np.ceil(0.8 * np.pi * radius[i] / length[i]))
        for j in range(i - skip, -1, -1):
            distance_vector, _, _ = _find_min_dist(x[..., i], edge[..., i], x[..., j], edge[..., j])
            if _norm(distance_vector) < radius[i] + radius[j] + margin:
                count += 1
    return count


class ThinningSelfContact(ea.RodSelfContact):
    """`RodSelfContact(k, nu)` plus the thinning force (`thinning` = 1.0 as rodphase's
    incompressible rod; 0.0 gives PyElastica's force exactly), acting from `active_from`
    seconds on.

    Before a twisted rod buckles no pair is within reach and the contact force is exactly
    zero, but PyElastica still pays its O(n²) pair loop every step (~14× the step without
    contact at n = 100). `active_from` skips that loop while the rod is straight; at the
    switch-on the pairs within reach + a/10 are counted and printed, and must be 0 for the run
    to equal one with contact throughout."""

    def __init__(self, k: float, nu: float, thinning: float = 1.0, active_from: float = 0.0) -> None:
        super().__init__(k, nu)
        self.thinning = float(thinning)
        self.active_from = float(active_from)
        self.checked = active_from <= 0.0
        self.pairs_at_switch_on = None

    def apply_contact(self, system_one, system_two, time=np.float64(0.0)) -> None:
        if time < self.active_from:
            return
        if not self.checked:
            self.checked = True
            self.pairs_at_switch_on = int(pairs_within_reach(
                system_one.position_collection[..., :-1], system_one.radius, system_one.lengths,
                system_one.tangents, 0.1 * float(np.mean(system_one.radius))))
            print(f"contact on at t={time:.3f} s: {self.pairs_at_switch_on} pairs within "
                  f"reach + a/10 (must be 0)", flush=True)
        self_contact_with_thinning(
            system_one.position_collection[..., :-1], system_one.radius, system_one.lengths,
            system_one.tangents, system_one.velocity_collection, system_one.external_forces,
            self.k, self.nu, self.thinning)
