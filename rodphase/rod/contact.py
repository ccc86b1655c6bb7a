"""Self-contact of a rod: O(n) candidate search and penalty forces between capsules.

Each element is a capsule (segment plus current radius). Candidate pairs come from a
hashed uniform grid of element midpoints and are kept as a Verlet list that is rebuilt
only when some node has moved far enough (a quarter of the skin) that a pair outside
the list could have come into contact. The force loop runs over a second, shorter list
(`near_pairs`: the candidates within a small margin of touching), rebuilt from the first
when a gap could have closed by that margin. All arrays are structure-of-arrays: (3, n).
"""

import numpy as np

from ._jit import FASTMATH as _FASTMATH
from ._jit import njit


@njit(cache=True, inline="always")
def _cell_hash(ix, iy, iz, mask):
    # Large odd multipliers spread neighbouring cells over the table; collisions only cost
    # a wasted distance test because each candidate's own cell is compared exactly.
    return ((ix * 73856093) ^ (iy * 19349663) ^ (iz * 83492791)) & mask


@njit(cache=True, fastmath=_FASTMATH, inline="always")
def build_pairs(x, exclusion, cutoff, pairs):
    """Candidate element pairs (i, j), j > i + exclusion, with midpoint distance < cutoff.

    x: (3, n+1) node positions. pairs: (2, capacity) int64 buffer, grown when too small.
    Returns (pairs, count). Cost O(n) for a rod whose local density is bounded, which a
    rod with self-contact guarantees (capsules cannot overlap much).
    """
    n = x.shape[1] - 1
    mid = np.empty((3, n))
    for i in range(n):
        for c in range(3):
            mid[c, i] = 0.5 * (x[c, i] + x[c, i + 1])
    inv_h = 1.0 / cutoff
    cell = np.empty((3, n), dtype=np.int64)
    table_size = 1
    while table_size < 2 * n:
        table_size *= 2
    mask = table_size - 1
    bucket = np.empty(n, dtype=np.int64)
    start = np.zeros(table_size + 1, dtype=np.int64)
    for i in range(n):
        for c in range(3):
            cell[c, i] = np.int64(np.floor(mid[c, i] * inv_h))
        b = _cell_hash(cell[0, i], cell[1, i], cell[2, i], mask)
        bucket[i] = b
        start[b + 1] += 1
    for b in range(table_size):
        start[b + 1] += start[b]
    fill = start[:-1].copy()
    order = np.empty(n, dtype=np.int64)
    for i in range(n):
        b = bucket[i]
        order[fill[b]] = i
        fill[b] += 1

    cut2 = cutoff * cutoff
    count = 0
    while True:
        count = 0
        overflow = False
        capacity = pairs.shape[1]
        for i in range(n):
            cx = cell[0, i]
            cy = cell[1, i]
            cz = cell[2, i]
            for dx in range(-1, 2):
                for dy in range(-1, 2):
                    for dz in range(-1, 2):
                        b = _cell_hash(cx + dx, cy + dy, cz + dz, mask)
                        for k in range(start[b], start[b + 1]):
                            j = order[k]
                            if j <= i + exclusion:
                                continue
                            if cell[0, j] != cx + dx or cell[1, j] != cy + dy or cell[2, j] != cz + dz:
                                continue
                            d0 = mid[0, i] - mid[0, j]
                            d1 = mid[1, i] - mid[1, j]
                            d2 = mid[2, i] - mid[2, j]
                            if d0 * d0 + d1 * d1 + d2 * d2 < cut2:
                                if count < capacity:
                                    pairs[0, count] = i
                                    pairs[1, count] = j
                                else:
                                    overflow = True
                                count += 1
        if not overflow:
            return pairs, count
        pairs = np.empty((2, 2 * count + 16), dtype=np.int64)


@njit(cache=True, fastmath=_FASTMATH, inline="always")
def closest_parameters(r0, r1, r2, u0, u1, u2, w0, w1, w2, inv_uu, inv_ww):
    """Parameters (s, t) in [0, 1] of the closest points p + s·u and q + t·w of two segments.

    r = p − q; inv_uu = 1/|u|² and inv_ww = 1/|w|², passed in because a caller looping over
    pairs can compute them once per element.
    """
    a = u0 * u0 + u1 * u1 + u2 * u2
    e = w0 * w0 + w1 * w1 + w2 * w2
    b = u0 * w0 + u1 * w1 + u2 * w2
    c = u0 * r0 + u1 * r1 + u2 * r2
    f = w0 * r0 + w1 * r1 + w2 * r2
    denom = a * e - b * b
    if denom > 1e-12 * a * e:
        s = min(max((b * f - c * e) / denom, 0.0), 1.0)
    else:
        s = 0.0  # parallel segments: any point of the overlap is a closest point
    t = (b * s + f) * inv_ww
    if t < 0.0:
        t = 0.0
        s = min(max(-c * inv_uu, 0.0), 1.0)
    elif t > 1.0:
        t = 1.0
        s = min(max((b - c) * inv_uu, 0.0), 1.0)
    return s, t


@njit(cache=True, fastmath=_FASTMATH, inline="always")
def near_pairs(x, radius, pairs, n_pairs, margin, near):
    """The listed pairs whose capsules are less than `margin` apart (gap = distance − r_i − r_j).

    The second level of the Verlet list: the candidate list (`build_pairs`) is ~10× longer
    than the pairs in contact (its cutoff must cover midpoints, half-lengths and a skin), so
    the force loop runs over this short list instead, rebuilt from the long one whenever the
    gaps could have closed by `margin`: a segment-to-segment distance changes by at most the
    sum of the two segments' largest node displacements. near: (2, ≥ n_pairs) int64 buffer.
    Returns the number of near pairs, written to near[:, :count] in list order.
    """
    n = radius.shape[0]
    # Each capsule lies within its reach (radius + half length) of its midpoint: one cheap
    # distance test rejects most listed pairs before the closest-point computation.
    mid = np.empty((3, n))
    reach = np.empty(n)
    for i in range(n):
        u0 = x[0, i + 1] - x[0, i]
        u1 = x[1, i + 1] - x[1, i]
        u2 = x[2, i + 1] - x[2, i]
        mid[0, i] = x[0, i] + 0.5 * u0
        mid[1, i] = x[1, i] + 0.5 * u1
        mid[2, i] = x[2, i] + 0.5 * u2
        reach[i] = radius[i] + 0.5 * np.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
    count = 0
    for p in range(n_pairs):
        i = pairs[0, p]
        j = pairs[1, p]
        m0 = mid[0, i] - mid[0, j]
        m1 = mid[1, i] - mid[1, j]
        m2 = mid[2, i] - mid[2, j]
        r = reach[i] + reach[j] + margin
        if m0 * m0 + m1 * m1 + m2 * m2 >= r * r:
            continue
        u0 = x[0, i + 1] - x[0, i]
        u1 = x[1, i + 1] - x[1, i]
        u2 = x[2, i + 1] - x[2, i]
        w0 = x[0, j + 1] - x[0, j]
        w1 = x[1, j + 1] - x[1, j]
        w2 = x[2, j + 1] - x[2, j]
        r0 = x[0, i] - x[0, j]
        r1 = x[1, i] - x[1, j]
        r2 = x[2, i] - x[2, j]
        s, t = closest_parameters(r0, r1, r2, u0, u1, u2, w0, w1, w2,
                                  1.0 / (u0 * u0 + u1 * u1 + u2 * u2),
                                  1.0 / (w0 * w0 + w1 * w1 + w2 * w2))
        d0 = r0 + s * u0 - t * w0
        d1 = r1 + s * u1 - t * w1
        d2 = r2 + s * u2 - t * w2
        gap = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2) - radius[i] - radius[j]
        if gap < margin:
            near[0, count] = i
            near[1, count] = j
            count += 1
    return count


# Rows of the dashpot buffer that the contact loops fill when the dashpot is implicit: each
# column is one touching pair, the nodes (i, i+1) and (j, j+1) it acts on with weights
# (1 − s, s) and (1 − t, t), its unit normal (from j towards i), its dashpot [N s/m] and its
# spring force [N] (the most the dashpot may pull the pair together by).
DASHPOT_ROWS = 9


@njit(cache=True, fastmath=_FASTMATH, inline="always")
def _note_dashpot(dashpots, count, i, s, j, t, n0, n1, n2, c, spring):
    dashpots[0, count] = i
    dashpots[1, count] = s
    dashpots[2, count] = j
    dashpots[3, count] = t
    dashpots[4, count] = n0
    dashpots[5, count] = n1
    dashpots[6, count] = n2
    dashpots[7, count] = c
    dashpots[8, count] = spring


@njit(cache=True, fastmath=_FASTMATH, inline="always")
def apply_dashpots(v, inv_mass, dashpots, count, dt):
    """The noted contact dashpots as impulses on the velocities after the kick: backward Euler.

    For each pair, in turn (Gauss–Seidel, so a node in several contacts sees the impulses
    already given), the dashpot force c·v_n acts with the normal relative velocity v_n at the
    end of the step; with the pair's inverse mass w = Σ weight²/m over its four nodes that is
    v_n ← v_n / (1 + c·dt·w), an impulse −c·dt·v_n/(1 + c·dt·w). It can only shrink |v_n|,
    never reverse it, and removes kinetic energy ((β − β²/2)·v_n²/w with β < 1), so it imposes
    no limit on dt whatever c is. As the explicit dashpot it may push apart but pulls the pair
    together by no more than its spring pushes (impulse ≥ −spring·dt).
    inv_mass: (n+1,) 1/m of the nodes, scaled as the kick scales them.
    """
    for k in range(count):
        i = np.int64(dashpots[0, k])
        s = dashpots[1, k]
        j = np.int64(dashpots[2, k])
        t = dashpots[3, k]
        n0 = dashpots[4, k]
        n1 = dashpots[5, k]
        n2 = dashpots[6, k]
        a0 = 1.0 - s
        b0 = 1.0 - t
        vn = ((a0 * v[0, i] + s * v[0, i + 1] - b0 * v[0, j] - t * v[0, j + 1]) * n0
              + (a0 * v[1, i] + s * v[1, i + 1] - b0 * v[1, j] - t * v[1, j + 1]) * n1
              + (a0 * v[2, i] + s * v[2, i + 1] - b0 * v[2, j] - t * v[2, j + 1]) * n2)
        w = (a0 * a0 * inv_mass[i] + s * s * inv_mass[i + 1] + b0 * b0 * inv_mass[j]
             + t * t * inv_mass[j + 1])
        cdt = dashpots[7, k] * dt
        impulse = max(-cdt * vn / (1.0 + cdt * w), -dashpots[8, k] * dt)
        pi0 = a0 * impulse * inv_mass[i]
        pi1 = s * impulse * inv_mass[i + 1]
        pj0 = b0 * impulse * inv_mass[j]
        pj1 = t * impulse * inv_mass[j + 1]
        v[0, i] += pi0 * n0
        v[1, i] += pi0 * n1
        v[2, i] += pi0 * n2
        v[0, i + 1] += pi1 * n0
        v[1, i + 1] += pi1 * n1
        v[2, i + 1] += pi1 * n2
        v[0, j] -= pj0 * n0
        v[1, j] -= pj0 * n1
        v[2, j] -= pj0 * n2
        v[0, j + 1] -= pj1 * n0
        v[1, j + 1] -= pj1 * n1
        v[2, j + 1] -= pj1 * n2


@njit(cache=True, fastmath=_FASTMATH, inline="always")
def add_contact_forces(x, v, radius, pairs, n_pairs, stiffness, damping, scale, friction,
                       slip_speed, thinning, force):
    """Add penalty contact forces of the listed pairs to `force` (3, n+1), dashpot explicit.

    See `contact_forces`; this is it with the dashpot in the force.
    """
    touching, worst, worst_element, energy, _ = contact_forces(
        x, v, radius, pairs, n_pairs, stiffness, damping, scale, friction, slip_speed,
        thinning, force, np.empty((DASHPOT_ROWS, 0)), False)
    return touching, worst, worst_element, energy


@njit(cache=True, fastmath=_FASTMATH, inline="always")
def contact_forces(x, v, radius, pairs, n_pairs, stiffness, damping, scale, friction,
                   slip_speed, thinning, force, dashpots, implicit):
    """`contact_forces_in` with its per-element buffers made here."""
    n = radius.shape[0]
    return contact_forces_in(x, v, radius, pairs, n_pairs, stiffness, damping, scale, friction,
                             slip_speed, thinning, force, dashpots, implicit, np.empty((3, n)),
                             np.empty(n), np.empty(n))


@njit(cache=True, fastmath=_FASTMATH, inline="always")
def contact_forces_in(x, v, radius, pairs, n_pairs, stiffness, damping, scale, friction,
                      slip_speed, thinning, force, dashpots, implicit, seg, inv_square, lever):
    """Add penalty contact forces of the listed pairs to `force` (3, n+1).

    Normal force per pair: max(0, k·δ − c·δ̇) along the line of closest approach, with δ the
    overlap of the two capsules (sum of current radii minus distance). The pair's spring and
    dashpot are `stiffness[i]` and `damping[i]`, (n,) arrays indexed by the pair's first
    element (they are set per element length), multiplied by `scale` (stiffness) and √scale
    (dashpot) so that contact follows a modulus ramp. Optional regularised Coulomb friction
    opposes the relative sliding velocity of the two closest points. Forces act at the
    closest points and are split linearly between the two nodes of each element.

    With `thinning` (1.0 for an incompressible rod, whose radius is a0/√e), the overlap also
    depends on the two elements' lengths; the spring then pulls each element's nodes apart
    along it by k·δ·a/(2l), the rest of the gradient of ½kδ². Without that term contact does
    work on a stretching rod and can pump energy into it.

    With `implicit`, the dashpot is left out of the force and each touching pair is noted
    in `dashpots` (DASHPOT_ROWS, ≥ n_pairs) for `apply_dashpots` after the kick; the normal
    force (and friction's bound) is then the spring's alone.

    seg (3, n), inv_square (n,), lever (n,): buffers for the per-element pass below, which
    the kernel keeps from step to step (three allocations a step fewer).

    Returns (number of touching pairs, largest overlap / smaller radius, its element index,
    the spring energy Σ ½·k·δ², pairs noted in `dashpots`).
    """
    n = radius.shape[0]
    noted = 0
    damping_scale = np.sqrt(scale)
    # Per element, once (a vectorised O(n) pass): the segment vector, 1/|u|² and the
    # thinning lever a/(2|u|²). The pair loop then divides only for the line of closest
    # approach and its unit normal, and takes a square root only for pairs that touch.
    for i in range(n):
        u0 = x[0, i + 1] - x[0, i]
        u1 = x[1, i + 1] - x[1, i]
        u2 = x[2, i + 1] - x[2, i]
        seg[0, i] = u0
        seg[1, i] = u1
        seg[2, i] = u2
        inv_square[i] = 1.0 / (u0 * u0 + u1 * u1 + u2 * u2)
        lever[i] = 0.5 * thinning * radius[i] * inv_square[i]
    energy = 0.0
    touching = 0
    worst = 0.0
    worst_element = -1
    for p in range(n_pairs):
        i = pairs[0, p]
        j = pairs[1, p]
        u0 = seg[0, i]
        u1 = seg[1, i]
        u2 = seg[2, i]
        w0 = seg[0, j]
        w1 = seg[1, j]
        w2 = seg[2, j]
        r0 = x[0, i] - x[0, j]
        r1 = x[1, i] - x[1, j]
        r2 = x[2, i] - x[2, j]
        s, t = closest_parameters(r0, r1, r2, u0, u1, u2, w0, w1, w2, inv_square[i], inv_square[j])
        d0 = r0 + s * u0 - t * w0
        d1 = r1 + s * u1 - t * w1
        d2 = r2 + s * u2 - t * w2
        reach = radius[i] + radius[j]
        dist2 = d0 * d0 + d1 * d1 + d2 * d2
        if dist2 >= reach * reach or dist2 <= 0.0:
            continue
        dist = np.sqrt(dist2)
        overlap = reach - dist
        touching += 1
        spring = scale * stiffness[i] * overlap
        energy += 0.5 * spring * overlap
        smaller = min(radius[i], radius[j])
        if overlap > worst * smaller:  # overlap / smaller > worst, without dividing
            worst = overlap / smaller
            worst_element = i
        inv = 1.0 / dist
        n0 = d0 * inv
        n1 = d1 * inv
        n2 = d2 * inv
        rv0 = (1.0 - s) * v[0, i] + s * v[0, i + 1] - (1.0 - t) * v[0, j] - t * v[0, j + 1]
        rv1 = (1.0 - s) * v[1, i] + s * v[1, i + 1] - (1.0 - t) * v[1, j] - t * v[1, j + 1]
        rv2 = (1.0 - s) * v[2, i] + s * v[2, i + 1] - (1.0 - t) * v[2, j] - t * v[2, j + 1]
        vn = rv0 * n0 + rv1 * n1 + rv2 * n2
        if implicit:
            _note_dashpot(dashpots, noted, i, s, j, t, n0, n1, n2, damping_scale * damping[i],
                          spring)
            noted += 1
            fn = spring
        else:
            fn = spring - damping_scale * damping[i] * vn
            if fn <= 0.0:
                continue  # a dashpot may push apart, never pull together
        f0 = fn * n0
        f1 = fn * n1
        f2 = fn * n2
        if friction > 0.0:
            t0 = rv0 - vn * n0
            t1 = rv1 - vn * n1
            t2 = rv2 - vn * n2
            vt = np.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
            # Regularised Coulomb: viscous below the slip speed so that sticking does not chatter.
            slide = friction * fn / max(vt, slip_speed)
            f0 -= slide * t0
            f1 -= slide * t1
            f2 -= slide * t2
        # the overlap's dependence on the element lengths (radii a0/√e); lever is 0 without thinning
        gi = spring * lever[i]
        gj = spring * lever[j]
        force[0, i] += (1.0 - s) * f0 - gi * u0
        force[1, i] += (1.0 - s) * f1 - gi * u1
        force[2, i] += (1.0 - s) * f2 - gi * u2
        force[0, i + 1] += s * f0 + gi * u0
        force[1, i + 1] += s * f1 + gi * u1
        force[2, i + 1] += s * f2 + gi * u2
        force[0, j] -= (1.0 - t) * f0 + gj * w0
        force[1, j] -= (1.0 - t) * f1 + gj * w1
        force[2, j] -= (1.0 - t) * f2 + gj * w2
        force[0, j + 1] -= t * f0 - gj * w0
        force[1, j + 1] -= t * f1 - gj * w1
        force[2, j + 1] -= t * f2 - gj * w2
    return touching, worst, worst_element, energy, noted


@njit(cache=True, fastmath=_FASTMATH, inline="always")
def add_body_forces(x, v, radius, stiffness, damping, scale, end, side, axis, body_radius,
                    exclusion, force, dashpots, noted, implicit):
    """Contact of the rod with the rigid body that a held end is fixed to.

    The body is a semi-infinite solid cylinder of radius `body_radius` on the rod's axis line,
    starting at node `end` (0 or n) with a flat cap and running away from the rod
    (direction side·axis, side = −1 at the start, +1 at the end): the loading rod or the
    weight's hanger of the experiment. Each node is a sphere of the current radius of its
    elements; the penalty law is that of the rod's own contact (spring `stiffness`, dashpot
    `damping` of the node's elements, times `scale` and √scale). The reaction acts on node
    `end`, which carries the body. Nodes within `exclusion` elements of `end` are the rod's
    own end and never touch it. With `implicit` the dashpot is noted in `dashpots` from
    column `noted` on, as in `contact_forces` (a node is the end of an element with weight 1).

    Returns (touching nodes, largest overlap / radius, spring energy Σ ½·k·δ², the count of
    noted dashpots).
    """
    n = radius.shape[0]
    u0 = side * axis[0]
    u1 = side * axis[1]
    u2 = side * axis[2]
    damping_scale = np.sqrt(scale)
    touching = 0
    worst = 0.0
    energy = 0.0
    for i in range(n + 1):
        if (end == 0 and i <= exclusion) or (end != 0 and i >= end - exclusion):
            continue
        lo = max(i - 1, 0)
        hi = min(i, n - 1)
        a = 0.5 * (radius[lo] + radius[hi])
        r0 = x[0, i] - x[0, end]
        r1 = x[1, i] - x[1, end]
        r2 = x[2, i] - x[2, end]
        h = r0 * u0 + r1 * u1 + r2 * u2
        if h < -a:
            continue  # behind the cap by more than a radius: the common case, cheap
        q0 = r0 - h * u0
        q1 = r1 - h * u1
        q2 = r2 - h * u2
        r = np.sqrt(q0 * q0 + q1 * q1 + q2 * q2)
        if r >= body_radius + a:
            continue
        if h >= 0.0 and r <= body_radius:
            # inside the body: leave by the nearer face (side or cap)
            if body_radius - r < h and r > 0.0:
                overlap = a + body_radius - r
                n0 = q0 / r
                n1 = q1 / r
                n2 = q2 / r
            else:
                overlap = a + h
                n0 = -u0
                n1 = -u1
                n2 = -u2
        else:
            # outside: the closest point of the body is on its side, its cap or its rim
            rc = min(r, body_radius)
            hc = max(h, 0.0)
            scale_q = rc / r if r > 0.0 else 0.0
            d0 = r0 - scale_q * q0 - hc * u0
            d1 = r1 - scale_q * q1 - hc * u1
            d2 = r2 - scale_q * q2 - hc * u2
            dist = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            if dist >= a or dist <= 0.0:
                continue
            overlap = a - dist
            n0 = d0 / dist
            n1 = d1 / dist
            n2 = d2 / dist
        touching += 1
        k = scale * 0.5 * (stiffness[lo] + stiffness[hi])
        c = damping_scale * 0.5 * (damping[lo] + damping[hi])
        spring = k * overlap
        energy += 0.5 * spring * overlap
        if overlap > worst * a:
            worst = overlap / a
        if implicit:
            # node i as an end of an element (weight 1), against node `end` likewise
            _note_dashpot(dashpots, noted, min(i, n - 1), 1.0 if i == n else 0.0,
                          min(end, n - 1), 1.0 if end == n else 0.0, n0, n1, n2, c, spring)
            noted += 1
            fn = spring
        else:
            vn = ((v[0, i] - v[0, end]) * n0 + (v[1, i] - v[1, end]) * n1
                  + (v[2, i] - v[2, end]) * n2)
            fn = spring - c * vn
            if fn <= 0.0:
                continue
        force[0, i] += fn * n0
        force[1, i] += fn * n1
        force[2, i] += fn * n2
        force[0, end] -= fn * n0
        force[1, end] -= fn * n1
        force[2, end] -= fn * n2
    return touching, worst, energy, noted


# a node is "tight" (fold_forces looks at the node pairs across it) when it turns by more than
# this fraction of the angle a circle of the rod's radius turns over the node's arc
FOLD_TIGHT = 0.8


@njit(cache=True, fastmath=_FASTMATH, inline="always")
def fold_forces(x, radius, lengths, rest_length, exclusion, stiffness, scale, reach, next_tight,
                force):
    """Contact inside the exclusion: a fold tighter than the rod cannot pass through itself.

    Pairs of elements fewer than `exclusion` apart along the rod never meet in
    `contact_forces` (as capsules they always overlap). But a loop pulled tighter than the
    rod's own radius can close on itself, and its strands then cross: link is lost by a
    self-passage, which no real filament can do. Here the nodes k and k + q, 2 <= q <=
    exclusion, are held apart by the chord of the tightest fold a rod of radius a can make
    over the rest arc s between them, a circle of radius a:

        d_min(s) = 2a·sin(min(s / 2a, π/2)).

    By Schur's comparison theorem a curve whose curvature nowhere exceeds 1/a has a chord
    over an arc s <= πa at least that of the circle, so loops of radius >= a never feel it
    (the rest arc is no longer than the current one on a rod that is not compressed, and a
    shorter arc only lowers d_min). Strands that cross come within about half an element of
    each other, far inside d_min, so for elements shorter than a radius no crossing gets
    through (a rod at n = 80 in Fig 3's box has 0.5 a).

    Per q one bound is used, the most permissive over the rod: the shortest rest arc of q
    elements and the smallest current radius (d_min grows with both), so the test is a
    squared distance against a number. The spring k·(d_min − d) acts along the line between
    the two nodes: it is the gradient of ½·k·(d_min − d)², d_min fixed, so it conserves
    momentum, angular momentum and (undamped) energy. It carries no dashpot. An earlier form
    between segments with d_min over the current arc fed itself (a push stretched the arc it
    grew with) and ran away in a twisted solenoid at n = 140.

    The same comparison says a pair can only be pushed if some node between them turns
    faster than 1/a: only pairs across a "tight" node, one turning by more than FOLD_TIGHT
    (0.8) of the angle a circle of radius a turns over its arc, are looked at. Without that
    the loop ran over every pair inside the exclusion, n·πa/l0 of them, O(n²): 2.3 µs a step
    at n = 140 and about 11 at n = 300. On random curves bent at 0.7-1.3/a every pushed pair
    had a node turning at least 0.96 of the circle's; tests/test_fold.py checks the skip
    against a scan of every pair.

    lengths are the current element lengths; reach (exclusion + 1,) float64 (squared
    distances) and next_tight (n + 1,) int64 are work buffers. Returns (pairs pushed, largest (d_min − d) / radius, its first
    node's element, spring energy Σ ½·k·(d_min − d)²).
    """
    n = rest_length.shape[0]
    touching = 0
    worst = 0.0
    worst_element = -1
    energy = 0.0
    a = radius[0]
    shortest = rest_length[0]
    for i in range(1, n):
        a = min(a, radius[i])
        shortest = min(shortest, rest_length[i])
    # next_tight[m]: the first tight node at or after node m (n + 1: none); node m joins
    # elements m - 1 and m, and the end nodes never turn
    next_tight[n] = n + 1
    for m in range(n - 1, 0, -1):
        turn = FOLD_TIGHT * 0.5 * (lengths[m - 1] + lengths[m]) / max(radius[m - 1], radius[m])
        q2 = turn * turn
        # cos(turn) from above (Taylor to 4th order), so the test errs towards "tight"
        cos_limit = 1.0 - 0.5 * q2 + q2 * q2 / 24.0
        dot = ((x[0, m] - x[0, m - 1]) * (x[0, m + 1] - x[0, m])
               + (x[1, m] - x[1, m - 1]) * (x[1, m + 1] - x[1, m])
               + (x[2, m] - x[2, m - 1]) * (x[2, m + 1] - x[2, m]))
        next_tight[m] = m if dot < cos_limit * lengths[m - 1] * lengths[m] else next_tight[m + 1]
    next_tight[0] = next_tight[1]
    top = min(exclusion, n)
    for q in range(2, top + 1):
        half = q * shortest / (2.0 * a)
        d_min = 2.0 * a * (np.sin(half) if half < 0.5 * np.pi else 1.0)
        reach[q] = d_min * d_min
    for k in range(n - 1):
        # the pair (k, k + q) has the nodes k + 1 .. k + q - 1 between it: one must be tight
        for q in range(max(2, next_tight[k + 1] - k + 1), min(top, n - k) + 1):
            d0 = x[0, k + q] - x[0, k]
            d1 = x[1, k + q] - x[1, k]
            d2 = x[2, k + q] - x[2, k]
            dist2 = d0 * d0 + d1 * d1 + d2 * d2
            limit = reach[q]
            if dist2 >= limit or dist2 <= 0.0:
                continue
            d_min = np.sqrt(limit)
            dist = np.sqrt(dist2)
            overlap = d_min - dist
            spring = scale * stiffness[k] * overlap
            touching += 1
            energy += 0.5 * spring * overlap
            if overlap > worst * a:
                worst = overlap / a
                worst_element = k
            f = spring / dist
            force[0, k] -= f * d0
            force[1, k] -= f * d1
            force[2, k] -= f * d2
            force[0, k + q] += f * d0
            force[1, k + q] += f * d1
            force[2, k + q] += f * d2
    return touching, worst, worst_element, energy
