"""Link, twist and writhe of a discrete ribbon: centreline nodes plus the d1 director per segment.

All three are in turns. Open curves are closed as in Klenin & Langowski, Biopolymers 54 (2000)
307: straight extensions along the end tangents, with d1 carried along them unchanged.
Writhe and link are exact sums, over pairs of straight pieces, of the Gauss double integral
(the signed solid angle of Klenin & Langowski eqs. 13-16).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba import njit, prange

__all__ = [
    "EDGE_OFFSET_FRACTION",
    "PARALLEL_MIN_PAIRS",
    "link",
    "topology_history",
    "twist",
    "writhe",
]

#: Ribbon edge offset for `link`, as a fraction of the shortest segment. Must stay well below
#: the segment length and the distance between strands so that the edge never passes
#: through the centreline; for a rod with self-contact (segments <= a, strands >= 2a apart)
#: 0.1 leaves a margin of 10 or more.
EDGE_OFFSET_FRACTION = 0.1

#: Work (segment pairs, ~15 ns each) below which a call runs on one thread. Waking numba's
#: other threads usually takes microseconds, but on the 2-core VM this was measured on it
#: stalled for a scheduler slice (~24 ms) in up to half of the calls, so threads only pay
#: for work of tens of ms: frames above ~1200 pieces, or histories of many frames. Set it
#: to 0 to thread every call on a dedicated machine.
PARALLEL_MIN_PAIRS = 2_000_000

_TWO_PI = 2.0 * math.pi
_FOUR_PI = 4.0 * math.pi


# --------------------------------------------------------------------------- geometry kernels


@njit(cache=True, error_model="numpy", inline="always")
def _turn(Zr, Zi, wind, zr, zi):
    """Multiply the running phase Z by z, counting crossings of the negative real axis.

    arg z lies in (-pi, pi), so a step that starts in the upper half-plane and turns
    counter-clockwise into the lower one has passed angle pi, and conversely. Branch-free:
    the sign of z is random from pair to pair and mispredicted branches cost more than the
    arithmetic.
    """
    nr = Zr * zr - Zi * zi
    ni = Zr * zi + Zi * zr
    up = (zi > 0.0) & (Zi >= 0.0) & (ni < 0.0)
    down = (zi < 0.0) & (Zi < 0.0) & (ni >= 0.0)
    return nr, ni, wind + np.int64(up) - np.int64(down)


@njit(cache=True, error_model="numpy")
def _phase_sum(zr, zi, j0, j1):
    """Sum of arg(zr + i zi) over j0..j1-1, with one atan2 per call rather than per pair.

    Two interleaved products shorten the multiply chain that bounds the speed. Every 32
    factors each product is rescaled to |Z| = 1: a factor has modulus below 17, and only a
    nearly degenerate pair has one much below 1, so 32 factors can neither over- nor
    underflow.
    """
    ar = 1.0
    ai = 0.0
    aw = 0
    br = 1.0
    bi = 0.0
    bw = 0
    j = j0
    while j < j1:
        stop = min(j + 64, j1)
        while j + 1 < stop:
            ar, ai, aw = _turn(ar, ai, aw, zr[j], zi[j])
            br, bi, bw = _turn(br, bi, bw, zr[j + 1], zi[j + 1])
            j += 2
        if j < stop:
            ar, ai, aw = _turn(ar, ai, aw, zr[j], zi[j])
            j += 1
        sa = abs(ar) + abs(ai)
        sb = abs(br) + abs(bi)
        if sa > 0.0:
            ar /= sa
            ai /= sa
        if sb > 0.0:
            br /= sb
            bi /= sb
    return math.atan2(ai, ar) + math.atan2(bi, br) + _TWO_PI * (aw + bw)


@njit(cache=True, error_model="numpy")
def _soa(P, closed):
    """Coordinates as three 1-D arrays; a closed curve gets node 0 again at the end."""
    m = P.shape[0]
    mm = m + 1 if closed else m
    x = np.empty(mm)
    y = np.empty(mm)
    z = np.empty(mm)
    for a in range(mm):
        b = a if a < m else 0
        x[a] = P[b, 0]
        y[a] = P[b, 1]
        z[a] = P[b, 2]
    return x, y, z


@njit(cache=True, error_model="numpy", inline="always")
def _fill(px, py, pz, a, qx, qy, qz, lo, hi, inf0, inf1, w0, w1, dx, dy, dz, ok):
    """Unit vectors from node a of P to nodes lo..hi-1 of Q; ok = 0 where they coincide.

    Node 0 and the last node may lie at infinity along w0 / w1 (the outward end directions):
    the direction towards a node at infinity is its outward direction, and from it the
    opposite. Between two nodes at infinity it is the one towards b, a vertex of the same
    great-circle edge of the quadrilateral, so the area is unchanged.
    """
    last = qx.shape[0] - 1
    if (inf0 and a == 0) or (inf1 and a == last):
        if a == 0:
            sx = -w0[0]
            sy = -w0[1]
            sz = -w0[2]
        else:
            sx = -w1[0]
            sy = -w1[1]
            sz = -w1[2]
        for b in range(lo, hi):
            dx[b] = sx
            dy[b] = sy
            dz[b] = sz
            ok[b] = 1.0
    else:
        ax = px[a]
        ay = py[a]
        az = pz[a]
        # Branch-free so that LLVM vectorises it: most of the time goes to sqrt and divide.
        for b in range(lo, hi):
            x = qx[b] - ax
            y = qy[b] - ay
            z = qz[b] - az
            r2 = x * x + y * y + z * z
            inv = 1.0 / math.sqrt(r2)
            good = r2 > 0.0
            inv = inv if good else 0.0
            dx[b] = x * inv
            dy[b] = y * inv
            dz[b] = z * inv
            ok[b] = 1.0 if good else 0.0
    if inf0 and lo == 0:
        dx[0] = w0[0]
        dy[0] = w0[1]
        dz[0] = w0[2]
        ok[0] = 1.0
    if inf1 and hi > last:
        dx[last] = w1[0]
        dy[last] = w1[1]
        dz[last] = w1[2]
        ok[last] = 1.0


@njit(cache=True, error_model="numpy", inline="always")
def _quads(d0x, d0y, d0z, ok0, d1x, d1y, d1z, ok1, j0, j1, zr, zi):
    """Half-area phase of the spherical quadrilateral of each piece pair j0..j1-1.

    Vertices: A = node a0 -> node j, B = a0 -> j+1, C = a1 -> j+1, D = a1 -> j. Split into
    triangles ABC + ACD, each from Van Oosterom & Strackee, IEEE Trans. Biomed. Eng. 30
    (1983) 125: tan(Omega/2) = a.(b x c) / (1 + a.b + b.c + c.a). Two disjoint straight
    pieces are separated by a plane, so ABCD lies in an open hemisphere and its half-area
    lies in (-pi, pi): the product of the two triangles' complex numbers carries it exactly.
    This replaces the asin form of Klenin & Langowski eqs. 13-16, which loses half the digits
    for nearly coplanar pairs (most pairs of a nearly straight rod).
    """
    for j in range(j0, j1):
        ax = d0x[j]
        ay = d0y[j]
        az = d0z[j]
        bx = d0x[j + 1]
        by = d0y[j + 1]
        bz = d0z[j + 1]
        cx = d1x[j + 1]
        cy = d1y[j + 1]
        cz = d1z[j + 1]
        dx = d1x[j]
        dy = d1y[j]
        dz = d1z[j]
        ab = ax * bx + ay * by + az * bz
        bc = bx * cx + by * cy + bz * cz
        ca = cx * ax + cy * ay + cz * az
        cd = cx * dx + cy * dy + cz * dz
        da = dx * ax + dy * ay + dz * az
        # a.(b x c) and a.(c x d) share a x c.
        acx = ay * cz - az * cy
        acy = az * cx - ax * cz
        acz = ax * cy - ay * cx
        n1 = -(acx * bx + acy * by + acz * bz)
        n2 = acx * dx + acy * dy + acz * dz
        r1 = 1.0 + ab + bc + ca
        r2 = 1.0 + ca + cd + da
        # A coincident vertex means the pieces touch: the integral is singular there, and
        # for pieces that merely share an end it is zero (they are coplanar).
        g = ok0[j] * ok0[j + 1] * ok1[j] * ok1[j + 1]
        re = r1 * r2 - n1 * n2
        im = r1 * n2 + n1 * r2
        # (0, 0) only for antipodal vertices, i.e. touching pieces: no area either.
        g = g if (re != 0.0 or im != 0.0) else 0.0
        zr[j] = g * re + (1.0 - g)
        zi[j] = g * im


@njit(cache=True, error_model="numpy")
def _rows(P, Q, r0, r1, self_pairs, closed, inf0, inf1, w0, w1):
    """Sum over rows r0..r1-1 of the solid angles between piece i of P and pieces of Q.

    self_pairs: P is Q and each unordered pair of non-neighbouring pieces counts once
    (writhe); otherwise all pairs (link).
    """
    px, py, pz = _soa(P, closed)
    qx, qy, qz = _soa(Q, closed)
    nc = px.shape[0]
    npieces = nc - 1
    d0x = np.empty(nc)
    d0y = np.empty(nc)
    d0z = np.empty(nc)
    ok0 = np.empty(nc)
    d1x = np.empty(nc)
    d1y = np.empty(nc)
    d1z = np.empty(nc)
    ok1 = np.empty(nc)
    zr = np.empty(nc)
    zi = np.empty(nc)
    total = 0.0
    fresh = True
    for i in range(r0, r1):
        if self_pairs:
            # Neighbouring pieces share a node: coplanar, no contribution.
            j0 = i + 2
            j1 = npieces - 1 if (closed and i == 0) else npieces
            lo = i + 2
        else:
            # The two rays at the same end are parallel: the integrand vanishes, but their
            # quadrilateral has antipodal vertices, where the phase is arbitrary.
            j0 = 1 if (inf0 and i == 0) else 0
            j1 = npieces - 1 if (inf1 and i == npieces - 1) else npieces
            lo = 0
        if j0 >= j1:
            fresh = True
            continue
        # Row i+1 starts where row i ends: reuse the directions from node i+1.
        if fresh:
            _fill(px, py, pz, i, qx, qy, qz, lo, nc, inf0, inf1, w0, w1, d0x, d0y, d0z, ok0)
        else:
            d0x, d1x = d1x, d0x
            d0y, d1y = d1y, d0y
            d0z, d1z = d1z, d0z
            ok0, ok1 = ok1, ok0
        _fill(px, py, pz, i + 1, qx, qy, qz, lo, nc, inf0, inf1, w0, w1, d1x, d1y, d1z, ok1)
        fresh = False
        # Views starting at j0: with a loop start known to be 0, LLVM's vectorised loop ran
        # twice as fast as with start j0 (measured).
        nj = j1 - j0
        _quads(
            d0x[j0:],
            d0y[j0:],
            d0z[j0:],
            ok0[j0:],
            d1x[j0:],
            d1y[j0:],
            d1z[j0:],
            ok1[j0:],
            0,
            nj,
            zr,
            zi,
        )
        total += 2.0 * _phase_sum(zr, zi, 0, nj)
    return total


@njit(cache=True, error_model="numpy")
def _npieces(P, closed):
    return P.shape[0] if closed else P.shape[0] - 1


@njit(cache=True, error_model="numpy")
def _writhe_serial(P, closed, inf0, inf1, w0, w1):
    s = _rows(P, P, 0, _npieces(P, closed), True, closed, inf0, inf1, w0, w1)
    # Each unordered pair once: 2 Omega / (4 pi). The quadrilateral is traversed against
    # the orientation of the Gauss integrand, hence the sign.
    return -s / _TWO_PI


@njit(cache=True, error_model="numpy")
def _balanced_bounds(npieces, nchunks, self_pairs):
    """Row boundaries giving each chunk about the same number of pairs."""
    bounds = np.empty(nchunks + 1, dtype=np.int64)
    bounds[0] = 0
    if not self_pairs:
        for c in range(1, nchunks + 1):
            bounds[c] = (npieces * c) // nchunks
        return bounds
    # Row i of the writhe has about npieces - i pairs.
    total = npieces * (npieces + 1) / 2.0
    acc = 0.0
    c = 1
    for i in range(npieces):
        acc += npieces - i
        while c < nchunks and acc >= total * c / nchunks:
            bounds[c] = i + 1
            c += 1
    while c <= nchunks:
        bounds[c] = npieces
        c += 1
    return bounds


@njit(cache=True, error_model="numpy", parallel=True)
def _pairs_parallel(P, Q, self_pairs, closed, inf0, inf1, w0, w1, nchunks):
    """Raw solid-angle sum of _rows, in row chunks of equal work on numba's threads.

    One parallel function for writhe and link: each costs several seconds to compile.
    _rows gets self_pairs as a literal, so numba compiles one version per value; with a
    runtime flag its loops ran twice slower (measured).
    """
    bounds = _balanced_bounds(_npieces(P, closed), nchunks, self_pairs)
    parts = np.zeros(nchunks)
    for c in prange(nchunks):
        if self_pairs:
            parts[c] = _rows(P, P, bounds[c], bounds[c + 1], True, closed, inf0, inf1, w0, w1)
        else:
            parts[c] = _rows(P, Q, bounds[c], bounds[c + 1], False, closed, inf0, inf1, w0, w1)
    return parts.sum()


@njit(cache=True, error_model="numpy")
def _link_serial(P, Q, closed, inf0, inf1, w0, w1):
    s = _rows(P, Q, 0, _npieces(P, closed), False, closed, inf0, inf1, w0, w1)
    return -s / _FOUR_PI


# --------------------------------------------------------------------------- ribbon preparation


@njit(cache=True, error_model="numpy")
def _clean(points, normals, closed, with_normals):
    """Drop zero-length segments; unit tangents and d1 projected on the normal plane."""
    n_pts = points.shape[0]
    nseg = n_pts if closed else n_pts - 1
    lengths = np.empty(nseg)
    total = 0.0
    for k in range(nseg):
        k1 = k + 1 if k + 1 < n_pts else 0
        x = points[k1, 0] - points[k, 0]
        y = points[k1, 1] - points[k, 1]
        z = points[k1, 2] - points[k, 2]
        lengths[k] = math.sqrt(x * x + y * y + z * z)
        total += lengths[k]
    # Relative threshold: a repeated point left by a mesher or an integrator is zero to
    # round-off of the coordinates, not exactly.
    tol = 1e-13 * total
    nv = 0
    for k in range(nseg):
        if lengths[k] > tol:
            nv += 1
    nn = nv if closed else nv + 1
    nodes = np.empty((nn, 3))
    t = np.empty((nv, 3))
    u = np.zeros((nv, 3))
    c = 0
    for k in range(nseg):
        if lengths[k] <= tol:
            continue
        if c == 0 or closed:
            for j in range(3):
                nodes[c, j] = points[k, j]
        if not closed:
            k1 = k + 1 if k + 1 < n_pts else 0
            for j in range(3):
                nodes[c + 1, j] = points[k1, j]
        c += 1
    min_len = np.inf
    c = 0
    for k in range(nseg):
        if lengths[k] <= tol:
            continue
        c1 = c + 1 if c + 1 < nn else 0
        x = nodes[c1, 0] - nodes[c, 0]
        y = nodes[c1, 1] - nodes[c, 1]
        z = nodes[c1, 2] - nodes[c, 2]
        ln = math.sqrt(x * x + y * y + z * z)
        if ln == 0.0:
            # Only when merging moved a closed curve's last node onto its first: keep the
            # original segment's direction.
            k1 = k + 1 if k + 1 < n_pts else 0
            x = points[k1, 0] - points[k, 0]
            y = points[k1, 1] - points[k, 1]
            z = points[k1, 2] - points[k, 2]
            ln = lengths[k]
        tx = x / ln
        ty = y / ln
        tz = z / ln
        t[c, 0] = tx
        t[c, 1] = ty
        t[c, 2] = tz
        min_len = min(min_len, ln)
        if with_normals:
            nx = normals[k, 0]
            ny = normals[k, 1]
            nz = normals[k, 2]
            dot = nx * tx + ny * ty + nz * tz
            vx = nx - dot * tx
            vy = ny - dot * ty
            vz = nz - dot * tz
            vn = math.sqrt(vx * vx + vy * vy + vz * vz)
            if vn > 1e-12 * math.sqrt(nx * nx + ny * ny + nz * nz):
                u[c, 0] = vx / vn
                u[c, 1] = vy / vn
                u[c, 2] = vz / vn
            else:
                # d1 along the tangent carries no orientation: take any perpendicular
                # rather than return NaN.
                e = _any_perpendicular(t[c])
                for j in range(3):
                    u[c, j] = e[j]
        c += 1
    return nodes, t, u, min_len


@njit(cache=True, error_model="numpy")
def _any_perpendicular(t):
    ax = abs(t[0])
    ay = abs(t[1])
    az = abs(t[2])
    if ax <= ay and ax <= az:
        e = np.array([1.0, 0.0, 0.0])
    elif ay <= az:
        e = np.array([0.0, 1.0, 0.0])
    else:
        e = np.array([0.0, 0.0, 1.0])
    v = e - (e[0] * t[0] + e[1] * t[1] + e[2] * t[2]) * t
    return v / math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])


@njit(cache=True, error_model="numpy")
def _twist_core(t, u, closed):
    n = t.shape[0]
    nsteps = n if closed else n - 1
    total = 0.0
    for k in range(nsteps):
        k1 = (k + 1) % n
        c = t[k, 0] * t[k1, 0] + t[k, 1] * t[k1, 1] + t[k, 2] * t[k1, 2]
        vx = u[k, 0]
        vy = u[k, 1]
        vz = u[k, 2]
        # Parallel transport = the minimal rotation taking t_k to t_k1. For v normal to
        # t_k it is the double reflection v - (v.t_k1)/(1 + c) (t_k + t_k1). Antiparallel
        # tangents leave the axis free; a half turn about u_k itself keeps u_k.
        if 1.0 + c > 1e-12:
            f = (vx * t[k1, 0] + vy * t[k1, 1] + vz * t[k1, 2]) / (1.0 + c)
            vx -= f * (t[k, 0] + t[k1, 0])
            vy -= f * (t[k, 1] + t[k1, 1])
            vz -= f * (t[k, 2] + t[k1, 2])
        wx = u[k1, 0]
        wy = u[k1, 1]
        wz = u[k1, 2]
        cx = vy * wz - vz * wy
        cy = vz * wx - vx * wz
        cz = vx * wy - vy * wx
        sin_ = cx * t[k1, 0] + cy * t[k1, 1] + cz * t[k1, 2]
        cos_ = vx * wx + vy * wy + vz * wz
        total += math.atan2(sin_, cos_)
    return total / _TWO_PI


@njit(cache=True, error_model="numpy")
def _extend(nodes, t, closed, ext):
    """Centreline with the end extensions: (P, inf0, inf1, w0, w1)."""
    w0 = np.zeros(3)
    w1 = np.zeros(3)
    if closed:
        return nodes.copy(), False, False, w0, w1
    nv = t.shape[0]
    # Element by element, here and in _clean: an array assigned to a slice makes numba
    # compile the formatting of its shape-mismatch error, seconds of a first compile.
    for j in range(3):
        w0[j] = -t[0, j]
        w1[j] = t[nv - 1, j]
    nn = nodes.shape[0]
    P = np.empty((nn + 2, 3))
    for a in range(nn):
        for j in range(3):
            P[a + 1, j] = nodes[a, j]
    infinite = not math.isfinite(ext)
    for j in range(3):
        if infinite:
            # Placeholders: _fill never uses the coordinates of a node at infinity.
            P[0, j] = nodes[0, j]
            P[nn + 1, j] = nodes[nn - 1, j]
        else:
            P[0, j] = nodes[0, j] + ext * w0[j]
            P[nn + 1, j] = nodes[nn - 1, j] + ext * w1[j]
    return P, infinite, infinite, w0, w1


@njit(cache=True, error_model="numpy")
def _edge(P, u, closed, eps):
    """Ribbon edge: each node pushed by eps along the bisector of the adjacent d1."""
    m = P.shape[0]
    nv = u.shape[0]
    Q = np.empty_like(P)
    for a in range(m):
        if closed:
            s0 = (a - 1) % nv
            s1 = a
        else:
            # P has the extension node at each end; its d1 is that of the end segment.
            s0 = min(max(a - 2, 0), nv - 1)
            s1 = min(max(a - 1, 0), nv - 1)
        bx = u[s0, 0] + u[s1, 0]
        by = u[s0, 1] + u[s1, 1]
        bz = u[s0, 2] + u[s1, 2]
        bn = math.sqrt(bx * bx + by * by + bz * bz)
        if bn < 1e-8:
            # d1 turns by half a turn at this node: twist is ambiguous there anyway.
            bx = u[s1, 0]
            by = u[s1, 1]
            bz = u[s1, 2]
            bn = 1.0
        Q[a, 0] = P[a, 0] + eps * bx / bn
        Q[a, 1] = P[a, 1] + eps * by / bn
        Q[a, 2] = P[a, 2] + eps * bz / bn
    return Q


@njit(cache=True, error_model="numpy")
def _enough(t, closed):
    return t.shape[0] >= (3 if closed else 1)


@njit(cache=True, error_model="numpy")
def _frame_serial(points, normals, closed, ext, offset_fraction):
    nodes, t, u, min_len = _clean(points, normals, closed, True)
    if not _enough(t, closed):
        return 0.0, 0.0, 0.0
    tw = _twist_core(t, u, closed)
    P, inf0, inf1, w0, w1 = _extend(nodes, t, closed, ext)
    wr = _writhe_serial(P, closed, inf0, inf1, w0, w1)
    Q = _edge(P, u, closed, offset_fraction * min_len)
    lk = _link_serial(P, Q, closed, inf0, inf1, w0, w1)
    return lk, tw, wr


@njit(cache=True, error_model="numpy")
def _history_serial(points_history, normals_history, closed, ext, offset_fraction):
    S = points_history.shape[0]
    out = np.empty((3, S))
    for s in range(S):
        lk, tw, wr = _frame_serial(
            points_history[s], normals_history[s], closed, ext, offset_fraction
        )
        out[0, s] = lk
        out[1, s] = tw
        out[2, s] = wr
    return out


# The same loop as _history_serial with prange. It is a second function, not the first one
# compiled with parallel=True: numba's disk cache is keyed by the Python function (its name
# and line) and the signature, not by the compile flags, so one function compiled both ways
# would load the serial machine code for the parallel call or the other way round.
@njit(cache=True, error_model="numpy", parallel=True)
def _history_parallel(points_history, normals_history, closed, ext, offset_fraction):
    S = points_history.shape[0]
    out = np.empty((3, S))
    for s in prange(S):
        lk, tw, wr = _frame_serial(
            points_history[s], normals_history[s], closed, ext, offset_fraction
        )
        out[0, s] = lk
        out[1, s] = tw
        out[2, s] = wr
    return out


# --------------------------------------------------------------------------- first compile


def _history_signature():
    """The argument types topology_history passes to _history_serial (C-contiguous float64)."""
    from numba import types

    frames = types.Array(types.float64, 3, "C")
    return (frames, frames, types.boolean, types.float64, types.float64)


def history_compiled() -> bool:
    """Whether _history_serial, for the arrays topology_history passes, is compiled in this
    process or in numba's disk cache (then it loads in milliseconds). True where this cannot
    be told: the caller then compiles it in its own process, as it would anyway."""
    sig = _history_signature()
    if sig in _history_serial.overloads:
        return True
    try:
        return _history_serial._cache.load_overload(sig, _history_serial.targetctx) is not None
    except Exception:  # numba's cache internals changed: compile where it is used
        return True


def compile_history() -> None:
    """Compile _history_serial for topology_history's arrays (and write it to numba's disk
    cache): what a first run's topology compiles, without the kernel. rodphase.runner's
    compile_kernel runs this in a second process while it compiles the kernel."""
    # the LLVM options the kernel modules set (rod/_jit.py) are process-wide and were set
    # wherever topology compiled so far (after the kernel): the same machine code here
    from .rod import _jit  # noqa: F401

    _history_serial.compile(_history_signature())


# --------------------------------------------------------------------------- public API


def _threads(pairs):
    """Chunks for the parallel kernels, or 0 for the serial ones.

    One chunk of equal work per thread, as numba's prange splits statically. The thread
    count is numba's (NUMBA_NUM_THREADS / numba.set_num_threads): sweep workers that already
    fill every core should set it to 1.
    """
    n = numba.get_num_threads()
    return n if (n > 1 and pairs >= PARALLEL_MIN_PAIRS) else 0


def _as_points(points, name="points"):
    p = np.ascontiguousarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"{name} must have shape (N, 3), got {p.shape}")
    if not np.all(np.isfinite(p)):
        raise ValueError(f"{name} must be finite")
    return p


def _as_normals(normals, n_points, closed):
    d = np.ascontiguousarray(normals, dtype=np.float64)
    rows = n_points if closed else n_points - 1
    if d.shape != (rows, 3):
        kind = "closed" if closed else "open"
        raise ValueError(
            f"normals must have shape ({rows}, 3) for an {kind} curve of {n_points} points, "
            f"got {d.shape}"
        )
    if not np.all(np.isfinite(d)):
        raise ValueError("normals must be finite")
    return d


def _extension_value(extension):
    if extension is None:
        return math.inf
    ext = float(extension)
    if not ext > 0.0:
        raise ValueError(f"extension must be > 0 (metres) or None for infinite, got {extension}")
    return ext


def _offset_fraction(offset_fraction):
    f = float(offset_fraction)
    if not 0.0 < f < 0.5:
        raise ValueError(f"offset_fraction must be in (0, 0.5), got {offset_fraction}")
    return f


def writhe(points, closed=False, extension=None) -> float:
    """Writhe (turns) of the polyline `points` (N, 3).

    Open curves get straight extensions along their end tangents (Klenin & Langowski 2000).
    `extension` is their length X in metres; None (default) takes the limit X -> infinity
    exactly (rays), which removes the truncation error of finite extensions: O(L/X) when the
    two end tangents are not parallel (1e-4 turns at X = 100 L in the tests), O((L/X)^2)
    when they are. The limit is ill-defined only when the two rays point the same way (a
    hairpin whose ends both point along +d); their pair is then taken as zero, the value of
    the integrand. Segments of zero length are skipped. Ignored for closed curves.
    """
    p = _as_points(points)
    ext = _extension_value(extension)
    nodes, t, _, _ = _clean(p, np.zeros((0, 3)), bool(closed), False)
    if not _enough(t, bool(closed)):
        return 0.0
    P, inf0, inf1, w0, w1 = _extend(nodes, t, bool(closed), ext)
    npieces = _npieces(P, bool(closed))
    nchunks = _threads(npieces * npieces // 2)
    if nchunks:
        s = _pairs_parallel(P, P, True, bool(closed), inf0, inf1, w0, w1, nchunks)
        return -float(s) / _TWO_PI
    return float(_writhe_serial(P, bool(closed), inf0, inf1, w0, w1))


def twist(points, normals, closed=False) -> float:
    """Twist (turns) of d1 about the centreline.

    `normals` holds d1 for each segment: (N-1, 3) for an open curve, (N, 3) for a closed one
    (row N-1 is the segment from point N-1 back to point 0). d1 is projected on the plane
    normal to its segment first. Each step parallel-transports d1 to the next segment and
    adds the signed angle to the next d1 about that segment; the extensions of an open curve
    add nothing because d1 is constant along them.
    """
    p = _as_points(points)
    d = _as_normals(normals, p.shape[0], bool(closed))
    _, t, u, _ = _clean(p, d, bool(closed), True)
    if t.shape[0] < 2:
        return 0.0
    return float(_twist_core(t, u, bool(closed)))


def link(
    points, normals, closed=False, extension=None, offset_fraction=EDGE_OFFSET_FRACTION
) -> float:
    """Gauss linking number (turns) of the centreline with the ribbon edge.

    The edge is the centreline with every node pushed, by `offset_fraction` times the
    shortest segment, along the bisector of the projected d1 of its two segments. The link
    is the exact double sum over segment pairs of the two polylines, extensions included
    (see `writhe`). Lk = Tw + Wr to round-off (~1e-14) for closed curves, where Lk is an
    integer, and for open curves with the default infinite extensions, which close the
    ribbon through the point at infinity. With finite extensions of length X the identity
    holds only to about offset * L / X (1e-9 to 1e-7 for X = 100 L in the tests).
    """
    p = _as_points(points)
    d = _as_normals(normals, p.shape[0], bool(closed))
    ext = _extension_value(extension)
    f = _offset_fraction(offset_fraction)
    nodes, t, u, min_len = _clean(p, d, bool(closed), True)
    if not _enough(t, bool(closed)):
        return 0.0
    P, inf0, inf1, w0, w1 = _extend(nodes, t, bool(closed), ext)
    Q = _edge(P, u, bool(closed), f * min_len)
    npieces = _npieces(P, bool(closed))
    nchunks = _threads(npieces * npieces)
    if nchunks:
        s = _pairs_parallel(P, Q, False, bool(closed), inf0, inf1, w0, w1, nchunks)
        return -float(s) / _FOUR_PI
    return float(_link_serial(P, Q, bool(closed), inf0, inf1, w0, w1))


def topology_history(
    points_history,
    normals_history,
    closed=False,
    extension=None,
    offset_fraction=EDGE_OFFSET_FRACTION,
):
    """(lk, tw, wr): arrays of length S for snapshots (S, N, 3) and d1 (S, N-1, 3).

    Each snapshot is computed as by `link`, `twist` and `writhe`; long histories run one
    snapshot per thread (see PARALLEL_MIN_PAIRS).
    """
    P = np.ascontiguousarray(points_history, dtype=np.float64)
    D = np.ascontiguousarray(normals_history, dtype=np.float64)
    if P.ndim != 3 or P.shape[2] != 3:
        raise ValueError(f"points_history must have shape (S, N, 3), got {P.shape}")
    rows = P.shape[1] if closed else P.shape[1] - 1
    if D.shape != (P.shape[0], rows, 3):
        raise ValueError(
            f"normals_history must have shape ({P.shape[0]}, {rows}, 3), got {D.shape}"
        )
    if not (np.all(np.isfinite(P)) and np.all(np.isfinite(D))):
        raise ValueError("points_history and normals_history must be finite")
    ext = _extension_value(extension)
    f = _offset_fraction(offset_fraction)
    if P.shape[0] == 0:
        empty = np.zeros(0)
        return empty, empty.copy(), empty.copy()
    pieces = P.shape[1] + 1  # with the two extensions
    if _threads(P.shape[0] * 3 * pieces * pieces // 2):
        out = _history_parallel(P, D, bool(closed), ext, f)
    else:
        out = _history_serial(P, D, bool(closed), ext, f)
    return out[0].copy(), out[1].copy(), out[2].copy()
