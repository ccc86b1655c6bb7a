"""A naive twin of one step's loads: plain numpy, written to be read, not to be fast.

This is the specification the compiled kernel (rodphase/rod/kernel.py, contact.py) is tested
against (tests/test_naive_twin.py), in the manner of stumpy's tests/naive.py. Each function
is the formula of Gazzola, Dudte, McCormick & Mahadevan (R. Soc. Open Sci. 2018) written out
once, with the kernel's conventions but none of its tricks (no series, no fused passes, no
scratch rows, no structure-of-arrays).

Layout, one point per row (the public API's (N, 3)), SI units:

    x, v    (n+1, 3)   node positions and velocities, lab frame
    Q       (n, 3, 3)  Q[i] has rows d1, d2, d3 of element i (lab frame): Q[i] @ a takes a
                       lab vector a to element i's material components
    w       (n, 3)     element angular velocities, material frame
    torques            material frame, as the kernel's

Rotations: κ·D0 = log(Q_j Q_{j+1}ᵀ) is the rotation vector θ with Q_j Q_{j+1}ᵀ = exp([θ]×),
taken from scipy's Rotation (as_rotvec), so that Q_{j+1} = exp(−[θ]×) Q_j: a body turns by
θ (material components) from element j to element j+1.

`to_twin` and `from_twin` convert the kernel's (3, N) arrays.
"""

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

E3 = np.array([0.0, 0.0, 1.0])


# ---------------------------------------------------------------------------- layout

def to_twin(a):
    """Kernel layout → twin layout: (3, N) → (N, 3); (3, 3, n) directors → (n, 3, 3)."""
    a = np.asarray(a)
    if a.ndim == 3:
        return np.transpose(a, (2, 0, 1)).copy()
    return a.T.copy()


def from_twin(a):
    """Twin layout → kernel layout (C-contiguous, as the kernel is compiled for)."""
    a = np.asarray(a)
    if a.ndim == 3:
        return np.ascontiguousarray(np.transpose(a, (1, 2, 0)))
    return np.ascontiguousarray(a.T)


def rotation_vector(R):
    """θ with R = exp([θ]×): the axis-angle of a rotation matrix (|θ| ≤ π)."""
    return Rotation.from_matrix(R).as_rotvec()


def rotation_matrix(theta):
    """exp([θ]×), Rodrigues' formula."""
    return Rotation.from_rotvec(theta).as_matrix()


# ---------------------------------------------------------------------------- the rod

@dataclass
class NaiveRod:
    """Rest properties of the rod, one row per element (n) or Voronoi domain (n-1).

    rest_length (n,), rest_voronoi (n-1,) m; node_mass (n+1,) kg; inertia (n, 3) = ρ·l0·I
    [kg m]; shear_stiffness (n, 3) = (4GA/3, 4GA/3, EA) [N]; bend_stiffness (n-1, 3) =
    (EI1, EI2, GI3) [N m²]; rest_curvature (n-1, 3) [1/m], its third column the rest twist;
    rest_shear (n, 3); rest_radius (n,) m; contact_k, contact_c (n,) per element; local_mask
    (n-1,) 1 on the Voronoi domains of the active segment.
    """

    rest_length: np.ndarray
    rest_voronoi: np.ndarray
    node_mass: np.ndarray
    inertia: np.ndarray
    shear_stiffness: np.ndarray
    bend_stiffness: np.ndarray
    rest_curvature: np.ndarray
    rest_shear: np.ndarray
    rest_radius: np.ndarray
    contact_k: np.ndarray
    contact_c: np.ndarray
    local_mask: np.ndarray

    @classmethod
    def from_kernel(cls, props):
        """From the kernel's RodProperties (or the dict simulate._rod_arrays builds)."""
        get = props.get if isinstance(props, dict) else (lambda k: getattr(props, k))
        fields = {}
        for name in cls.__dataclass_fields__:
            value = np.asarray(get(name), dtype=float)
            fields[name] = value.T.copy() if value.ndim == 2 else value.copy()
        return cls(**fields)


@dataclass
class Loads:
    """force (n+1, 3) on nodes, lab frame [N]; torque (n, 3) on elements, material [N m];
    stretch (stretch and shear) and bend (bend and twist) energies [J]."""

    force: np.ndarray
    torque: np.ndarray
    stretch_energy: float = 0.0
    bend_energy: float = 0.0


def strains(x, Q, rod):
    """Per element: the edge Δx_i = x_{i+1} − x_i (lab), its length l_i, the dilatation
    e_i = l_i/l0_i, and the shear/stretch strain σ_i = Q_i Δx_i / l0_i − d3 (material)."""
    n = len(rod.rest_length)
    edge = x[1:] - x[:-1]
    length = np.linalg.norm(edge, axis=1)
    e = length / rod.rest_length
    sigma = np.array([Q[i] @ edge[i] / rod.rest_length[i] - E3 for i in range(n)])
    return edge, length, e, sigma


def curvatures(Q, rod):
    """κ_j = log(Q_j Q_{j+1}ᵀ)/D0_j at the n-1 Voronoi domains (material frame), and the
    cosine of each rotation angle."""
    n = Q.shape[0]
    kappa = np.zeros((n - 1, 3))
    cosine = np.zeros(n - 1)
    for j in range(n - 1):
        R = Q[j] @ Q[j + 1].T
        kappa[j] = rotation_vector(R) / rod.rest_voronoi[j]
        cosine[j] = 0.5 * (np.trace(R) - 1.0)
    return kappa, cosine


def internal_loads(x, v, Q, w, rod, *, incompressible=True, f_shear=1.0, f_bend=1.0,
                   f_inertia=1.0, f_twist=1.0, local_twist=0.0):
    """The internal loads of the paper's linear law (Gazzola 2018, eqs. 2.x in discrete form).

    Elements i = 0..n-1, Voronoi domains j = 0..n-2 (between elements j and j+1), nodes
    k = 0..n. With g_i = 1/e_i for an incompressible rod (area A0/e), else 1:

      stress        n_i = f_shear·S_i(σ_i − σ0_i)            material, per rest area
      element force N_i = g_i Q_iᵀ n_i                       lab: pulls node i+1 back, i on
      node force    F_k = N_k − N_{k−1}                      (N_{−1} = N_n = 0)
      shear couple  Q_i (Δx_i × N_i)                         moment of the pair ±N_i about
                                                             the element, in its frame
      Jω/e          J_i ω_i·f_inertia·g_i
      transport     (Jω/e) × ω
      dilatation    (Jω/e)·ė_i/e_i, ė_i = Δx_i·Δv_i/(l_i·l0_i)   (incompressible only)
      bend couple   c_j = f_bend·B_j(κ_j − κ0_j)/ε_j³,   ε_j = (l_j + l_{j+1})/(2 D0_j)
                    (no 1/ε³ unless incompressible), κ0_j = (κ0₁, κ0₂, f_twist·κ0₃ +
                    local_mask_j·local_twist)
      on element i  c_i − c_{i−1} + ½D0_i κ_i × c_i + ½D0_{i−1} κ_{i−1} × c_{i−1}
                    (Δʰ and the trapezoid Aʰ of κ × c·D0, absent terms beyond the ends)

    Energies: Σ ½ l0 (σ − σ0)·f_shear S(σ − σ0) and Σ ½ D0 (κ − κ0)·f_bend B(κ − κ0) (the
    quadratic forms, without the 1/e factors). Returns Loads, plus `dilatation` (n,),
    `lengths` (n,) and `cosines` (n-1,) as attributes.
    """
    n = len(rod.rest_length)
    edge, length, e, sigma = strains(x, Q, rod)
    g = 1.0 / e if incompressible else np.ones(n)

    strain = sigma - rod.rest_shear
    stress = f_shear * rod.shear_stiffness * strain
    stretch_energy = sum(0.5 * rod.rest_length[i] * strain[i] @ stress[i] for i in range(n))
    element_force = np.array([g[i] * Q[i].T @ stress[i] for i in range(n)])

    force = np.zeros((n + 1, 3))
    for i in range(n):
        force[i] += element_force[i]
        force[i + 1] -= element_force[i]

    torque = np.zeros((n, 3))
    for i in range(n):
        torque[i] += Q[i] @ np.cross(edge[i], element_force[i])
        j_omega = f_inertia * g[i] * rod.inertia[i] * w[i]
        torque[i] += np.cross(j_omega, w[i])
        if incompressible:
            e_rate = edge[i] @ (v[i + 1] - v[i]) / (length[i] * rod.rest_length[i])
            torque[i] += j_omega * e_rate / e[i]

    kappa, cosines = curvatures(Q, rod)
    rest = rod.rest_curvature.copy()
    rest[:, 2] = f_twist * rest[:, 2] + rod.local_mask * local_twist
    bend_energy = 0.0
    for j in range(n - 1):
        moment = f_bend * rod.bend_stiffness[j] * (kappa[j] - rest[j])
        bend_energy += 0.5 * rod.rest_voronoi[j] * (kappa[j] - rest[j]) @ moment
        voronoi_dilatation = 0.5 * (length[j] + length[j + 1]) / rod.rest_voronoi[j]
        couple = moment / voronoi_dilatation**3 if incompressible else moment
        transport = 0.5 * rod.rest_voronoi[j] * np.cross(kappa[j], couple)
        torque[j] += couple + transport
        torque[j + 1] += -couple + transport

    loads = Loads(force, torque, stretch_energy, bend_energy)
    loads.dilatation = e
    loads.lengths = length
    loads.cosines = cosines
    return loads


# ---------------------------------------------------------------------------- clamps

def clamp_frame(reference, axis, angle):
    """The clamp's frame (rows d1 d2 d3) turned by `angle` about the lab `axis`: each
    director d → R d, i.e. rows multiplied by Rᵀ."""
    return reference @ rotation_matrix(angle * np.asarray(axis, float)).T


# The κ × c term of a clamp spring: which part of half_length·κ × c the element takes.
# ENERGY_SHARE (½) is what the energy of the spring gives (see clamp_couple), and what
# rodphase/rod/kernel.py's _clamp_couple gives the element since 2026-12-06; WHOLE_SHARE (1) is
# what it gave before, first-order wrong (tests/test_naive_twin.py tells the two apart).
ENERGY_SHARE = 0.5
WHOLE_SHARE = 1.0


def clamp_couple(before, after, half_length, rest, stiffness, g3, share=ENERGY_SHARE):
    """The spring of a clamp over half an element, between frames `before` and `after`
    (rows d1 d2 d3; the start clamp is `before` element 0, the end clamp `after` element
    n-1).

    κ = log(before·afterᵀ)/half_length, c = g3·B(κ − κ0), energy ½·half_length·(κ −
    κ0)·B(κ − κ0). On the element, in its material frame: −c + share·half_length·κ × c if it
    is `after`, +c + share·half_length·κ × c if it is `before`. The energy's rotational
    derivative, turning one frame by δ (Q → exp(−[δ]×)Q), is ∓c + ½·half_length·κ × c to
    first order in θ = κ·half_length (the same first order at which the interior keeps its
    ½D0·κ × c per side): share ½. Returns (couple c, the κ × c part with share 1, energy,
    cosine of the angle between the frames).
    """
    R = before @ after.T
    kappa = rotation_vector(R) / half_length
    moment = stiffness * (kappa - rest)
    energy = 0.5 * half_length * (kappa - rest) @ moment
    couple = g3 * moment
    return couple, half_length * np.cross(kappa, couple), energy, 0.5 * (np.trace(R) - 1.0)


def clamp_loads(x, Q, rod, start_frame, end_frame, axis, start_rotation, end_rotation, *,
                incompressible=True, f_bend=1.0, f_radius_inv=1.0, share=ENERGY_SHARE):
    """Torques (n, 3) of the two clamp springs on elements 0 and n-1, their energy, the axial
    torque the end clamp exerts on element n-1 (lab couple · axis) and the two cosines.

    Each clamp's frame is its reference turned about `axis` by its rotation control. The
    start spring takes the stiffness and rest curvature of Voronoi domain 0, the end spring
    those of n-2, the rest twist scaled by 1/radius factor (f_radius_inv), the stiffness by
    f_bend; g3 = 1/e³ of the end element (incompressible) or 1.
    """
    n = Q.shape[0]
    _, _, e, _ = strains(x, Q, rod)
    torque = np.zeros((n, 3))
    energy = 0.0
    cosines = []
    ends = ((0, 0, clamp_frame(start_frame, axis, start_rotation), True),
            (n - 1, n - 2, clamp_frame(end_frame, axis, end_rotation), False))
    end_torque = 0.0
    for element, voronoi, frame, at_start in ends:
        rest = rod.rest_curvature[voronoi] * np.array([1.0, 1.0, f_radius_inv])
        stiffness = f_bend * rod.bend_stiffness[voronoi]
        g3 = 1.0 / e[element] ** 3 if incompressible else 1.0
        if at_start:
            couple, transport, part, cosine = clamp_couple(
                frame, Q[element], 0.5 * rod.rest_length[element], rest, stiffness, g3)
            torque[element] += -couple + share * transport
        else:
            couple, transport, part, cosine = clamp_couple(
                Q[element], frame, 0.5 * rod.rest_length[element], rest, stiffness, g3)
            torque[element] += couple + share * transport
            end_torque = (Q[element].T @ couple) @ axis
        energy += part
        cosines.append(cosine)
    return torque, energy, end_torque, cosines


# ---------------------------------------------------------------------------- external

def external_loads(x, rod, end_force, force_direction, gravity, radius_factor=1.0,
                   local_pull=0.0, segment=(0, 0)):
    """(n+1, 3) forces: the end force on node n, gravity m·g on every node (mass scaling as
    the radius factor squared), and the active segment's pull drawing its end nodes together
    along the chord between them."""
    force = np.zeros_like(x)
    force[-1] += end_force * np.asarray(force_direction, float)
    force += rod.node_mass[:, None] * radius_factor**2 * np.asarray(gravity, float)
    first, last = segment
    chord = x[last] - x[first]
    if local_pull != 0.0 and last > first and np.linalg.norm(chord) > 0.0:
        pull = local_pull * chord / np.linalg.norm(chord)
        force[first] += pull
        force[last] -= pull
    return force


# ---------------------------------------------------------------------------- contact

PARALLEL = 1e-12  # |u × w|² ≤ this·|u|²|w|²: the segments count as parallel


def closest_parameters(p0, p1, q0, q1):
    """(s, t) in [0, 1]² minimising |p0 + s·u − (q0 + t·w)|, u = p1 − p0, w = q1 − q0.

    Not parallel: the squared distance is strictly convex in (s, t), so its minimiser over
    the square is the unique one among the interior stationary point (if inside) and the
    minimisers along the four edges (each a clamped projection); all are tried and the
    nearest kept. Parallel (every point of an overlap is closest): the kernel's rule, s = 0
    and t the clamped projection of p0 on the other segment, then, if t was clamped, s the
    clamped projection of that end of it.
    """
    u = p1 - p0
    w = q1 - q0
    r = p0 - q0
    uu, ww, uw = u @ u, w @ w, u @ w

    def distance2(s, t):
        d = r + s * u - t * w
        return d @ d

    def clamp(a):
        return min(max(a, 0.0), 1.0)

    if np.cross(u, w) @ np.cross(u, w) <= PARALLEL * uu * ww:
        t = (w @ r) / ww
        if t < 0.0:
            return clamp(-(u @ r) / uu), 0.0
        if t > 1.0:
            return clamp((uw - u @ r) / uu), 1.0
        return 0.0, t
    candidates = []
    # interior: ∂/∂s = u·(r + su − tw) = 0, ∂/∂t = −w·(r + su − tw) = 0
    s, t = np.linalg.solve(np.array([[uu, -uw], [uw, -ww]]), np.array([-(u @ r), -(w @ r)]))
    if 0.0 <= s <= 1.0 and 0.0 <= t <= 1.0:
        candidates.append((s, t))
    for s in (0.0, 1.0):
        candidates.append((s, clamp((w @ (r + s * u)) / ww)))
    for t in (0.0, 1.0):
        candidates.append((clamp(-(u @ (r - t * w)) / uu), t))
    return min(candidates, key=lambda st: distance2(*st))


def contact_pair(x, v, radius, i, j, stiffness, damping, *, scale=1.0, friction=0.0,
                 slip_speed=1e-4, thinning=False):
    """The penalty force between element i and element j (capsules of radii radius[i],
    radius[j]) as a (n+1, 3) force array, and the pair's spring energy.

    Overlap δ = a_i + a_j − d at the closest points p = x_i + s·u, q = x_j + t·w, normal
    n̂ = (p − q)/d from j towards i. Normal force f = scale·k_i·δ − √scale·c_i·(v_p − v_q)·n̂,
    and nothing at all if f ≤ 0 (a dashpot may push apart, never pull together) or if the
    capsules do not overlap. Friction (regularised Coulomb) −μ·f·v_t/max(|v_t|, slip_speed)
    against the tangential relative velocity. The pair force acts at p (on i, split (1 − s,
    s) between its nodes) and, reversed, at q: the spring part is −∇(½kδ²) at fixed radii,
    since ∂d/∂x_i = (1 − s)·n̂ at the closest points. With `thinning` (incompressible: a =
    a0/√e, so δ depends on the element lengths) the rest of −∇(½kδ²) is added: ∂a_i/∂x_{i+1}
    = −½·a_i·u/|u|², so node i+1 gets spring·a_i·u/(2|u|²) and node i the opposite; likewise
    for j (spring = scale·k_i·δ, the dashpot does not enter). Energy ½·scale·k_i·δ².
    """
    force = np.zeros_like(x)
    u = x[i + 1] - x[i]
    w = x[j + 1] - x[j]
    s, t = closest_parameters(x[i], x[i + 1], x[j], x[j + 1])
    gap = (x[i] + s * u) - (x[j] + t * w)
    d = np.linalg.norm(gap)
    overlap = radius[i] + radius[j] - d
    if overlap <= 0.0 or d == 0.0:
        return force, 0.0
    normal = gap / d
    spring = scale * stiffness[i] * overlap
    energy = 0.5 * spring * overlap
    relative = ((1 - s) * v[i] + s * v[i + 1]) - ((1 - t) * v[j] + t * v[j + 1])
    normal_speed = relative @ normal
    f = spring - np.sqrt(scale) * damping[i] * normal_speed
    if f <= 0.0:
        return force, energy
    pair = f * normal
    if friction > 0.0:
        sliding = relative - normal_speed * normal
        pair -= friction * f * sliding / max(np.linalg.norm(sliding), slip_speed)
    force[i] += (1 - s) * pair
    force[i + 1] += s * pair
    force[j] -= (1 - t) * pair
    force[j + 1] -= t * pair
    if thinning:
        for element, edge in ((i, u), (j, w)):
            push = spring * radius[element] * edge / (2.0 * (edge @ edge))
            force[element + 1] += push
            force[element] -= push
    return force, energy


def contact_loads(x, v, radius, pairs, stiffness, damping, **law):
    """Sum of `contact_pair` over the listed (i, j) pairs: (force (n+1, 3), energy,
    touching pairs)."""
    force = np.zeros_like(x)
    energy = 0.0
    touching = 0
    for i, j in pairs:
        f, e = contact_pair(x, v, radius, i, j, stiffness, damping, **law)
        force += f
        energy += e
        touching += e > 0.0
    return force, energy, touching


def all_pairs(n, exclusion):
    """Every element pair (i, j) with j > i + exclusion: the pairs contact may act on."""
    return [(i, j) for i in range(n) for j in range(i + exclusion + 1, n)]


def current_radius(rod, e, radius_factor=1.0, incompressible=True):
    """(n,) element radii: rest × growth factor, thinned as a0/√e when incompressible."""
    return radius_factor * rod.rest_radius / (np.sqrt(e) if incompressible else 1.0)
