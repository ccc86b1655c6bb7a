"""The compiled kernel's loads against their naive numpy twin (tests/naive.py), on random states.

The twin is the specification: one step's loads (internal forces and torques of the paper's
law and their energies, the clamp springs, the end force and gravity, the self-contact pair
forces) written plainly from the formulas. The kernel's compiled functions are called
directly, as advance calls them, on seeded random states: near-straight rods with random
bends, twists, shears and stretches, nonzero v and ω, random rest curvature and rest shear.

Tolerance: TOL = 1e-11 relative to the largest entry of the array compared. The kernel runs
with fastmath (reassociation, contraction into FMA) and a power series for θ/sinθ, the twin
with numpy and scipy's Rotation: both are double round-off (~1e-16) over a few dozen
operations per entry, amplified by the cancellations of the discretisation (a node force is
the difference of two element forces up to ~100× larger at small strain; κ from the skew part
of Q_j Q_{j+1}ᵀ loses digits as 1/θ). Measured: ~1e-15 on forces and torques, at most 2e-13
(the end clamp's axial torque, a sum that cancels). TOL leaves a margin of 50 over that and
still catches any wrong term: the smallest physical effect switched here (1/e with e − 1 of a
few %, κ × τ at θ ~ 0.1) moves the loads by ≥ 1e-3 relative.

The twin's own correctness is checked apart from the kernel: its forces are −∇E of its energy
(exactly, for a compressible rod at rest), its torques −∇_θE to first order in the rotation
between neighbouring frames, its contact forces −∇(½kδ²).
"""

import naive as N  # tests/naive.py: pytest puts tests/ on sys.path
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import rodphase
from rodphase.rod import Problem, Rod, straight_state
from rodphase.rod import kernel as K
from rodphase.rod.contact import DASHPOT_ROWS, contact_forces_in
from rodphase.rod.simulate import _rod_arrays, clamp_reference
from rodphase.scenes import build

TOL = 1e-11
SEEDS = range(6)


def close(kernel_value, twin_value, tol=TOL):
    """max |kernel − twin| ≤ tol · max |twin| (per array: relative to its largest entry)."""
    kernel_value = np.asarray(kernel_value, float)
    twin_value = np.asarray(twin_value, float)
    scale = np.abs(twin_value).max()
    return np.abs(kernel_value - twin_value).max() <= tol * scale


# ---------------------------------------------------------------------------- random states

def random_rod(seed):
    """(rod properties for the kernel, the twin's NaiveRod, state in kernel layout, rng):
    n in 7..20, a rod near straight but with every strain of the law present."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(7, 21))
    rod = Rod(length=float(rng.uniform(0.3, 1.0)), radius=float(rng.uniform(0.01, 0.03)),
              elements=n)
    state = straight_state(rod, axis=rng.standard_normal(3),
                           twist_turns=float(rng.uniform(-0.5, 0.5)))
    s = np.linspace(0.0, 1.0, n + 1)
    axis = state.x[:, -1] - state.x[:, 0]
    state.x += np.outer(rng.uniform(0.0, 0.2, 3), np.sin(np.pi * s)) * rod.length  # a bend
    state.x += np.outer(axis, s) * rng.uniform(-0.05, 0.2)  # a stretch (or compression)
    state.x += 0.002 * rod.length * rng.standard_normal(state.x.shape)  # shears and kinks
    for i in range(n):
        turn = Rotation.from_rotvec(0.08 * rng.standard_normal(3)).as_matrix()
        state.Q[:, :, i] = turn @ state.Q[:, :, i]
    state.v[:] = 0.3 * rng.standard_normal(state.v.shape)
    state.w[:] = 5.0 * rng.standard_normal(state.w.shape)
    arrays = _rod_arrays(Problem(rod=rod, state=state))
    arrays["rest_curvature"][:] = rng.standard_normal(arrays["rest_curvature"].shape)
    arrays["rest_shear"][:] = 0.01 * rng.standard_normal(arrays["rest_shear"].shape)
    mask = np.zeros(n - 1)
    mask[n // 3: n // 2] = 1.0
    props = K.RodProperties(local_mask=mask, **arrays)
    return props, N.NaiveRod.from_kernel(props), state, rng


def kernel_internal(state, props, incompressible, factors):
    """kernel.internal_loads as advance calls it; factors = (f_shear, f_bend, f_inertia,
    f_twist, local_twist)."""
    n = props.rest_length.shape[0]
    force, torque = np.zeros((3, n + 1)), np.zeros((3, n))
    dilatation, lengths, energies = np.zeros(n), np.zeros(n), np.zeros(4)
    K.internal_loads(state.x, state.v, state.Q, state.w, props.rest_length, props.rest_voronoi,
                     props.inertia, props.shear_stiffness, props.bend_stiffness,
                     props.rest_curvature, props.rest_shear, props.local_mask, incompressible,
                     *factors, force, torque, dilatation, lengths, energies,
                     np.zeros((K.N_WORK, n)))
    return force, torque, dilatation, lengths, energies


def twin_internal(state, rod, incompressible, factors):
    f_shear, f_bend, f_inertia, f_twist, local_twist = factors
    return N.internal_loads(N.to_twin(state.x), N.to_twin(state.v), N.to_twin(state.Q),
                            N.to_twin(state.w), rod, incompressible=incompressible,
                            f_shear=f_shear, f_bend=f_bend, f_inertia=f_inertia,
                            f_twist=f_twist, local_twist=local_twist)


def random_factors(rng):
    return tuple(rng.uniform(0.7, 1.3, 4)) + (float(rng.uniform(-2.0, 2.0)),)


# ---------------------------------------------------------------------------- internal loads

@pytest.mark.parametrize("incompressible", [True, False])
@pytest.mark.parametrize("seed", SEEDS)
def test_internal_loads_match_the_twin(seed, incompressible):
    props, rod, state, rng = random_rod(seed)
    factors = random_factors(rng)
    force, torque, dilatation, lengths, energies = kernel_internal(state, props, incompressible,
                                                                   factors)
    twin = twin_internal(state, rod, incompressible, factors)
    assert close(N.to_twin(force), twin.force)
    assert close(N.to_twin(torque), twin.torque)
    assert close(energies[0], twin.stretch_energy)
    assert close(energies[1], twin.bend_energy)
    assert close(dilatation, twin.dilatation) and close(lengths, twin.lengths)
    # the resolution guard's input: the smallest neighbour cosine and where
    assert close(energies[2], twin.cosines.min())
    assert energies[3] == np.argmin(twin.cosines)


def test_internal_loads_of_a_shipped_scene_match_the_twin():
    # the rod exactly as the builder makes it for a real config (twist_under_load, n = 12),
    # in a random deformed state
    problem = build(rodphase.load("twist_under_load", {"rod.elements": 12}))
    rng = np.random.default_rng(0)
    state = straight_state(problem.rod, twist_turns=1.0)
    state.x += 0.003 * rng.standard_normal(state.x.shape)
    state.v[:] = 0.1 * rng.standard_normal(state.v.shape)
    state.w[:] = rng.standard_normal(state.w.shape)
    props = K.RodProperties(local_mask=np.zeros(11), **_rod_arrays(problem))
    rod = N.NaiveRod.from_kernel(props)
    factors = (1.0, 1.0, 1.0, 1.0, 0.0)
    force, torque, _, _, energies = kernel_internal(state, props, problem.rod.incompressible,
                                                    factors)
    twin = twin_internal(state, rod, problem.rod.incompressible, factors)
    assert close(N.to_twin(force), twin.force) and close(N.to_twin(torque), twin.torque)
    assert close(energies[:2], [twin.stretch_energy, twin.bend_energy])


def test_rigid_motion_rotates_forces_and_leaves_material_torques():
    # Objectivity, kernel and twin: a rotation R and a translation of the whole state (x, v
    # and every director rotated, ω in the material frame unchanged) rotates the node forces
    # and leaves the material-frame torques and the energies as they were.
    props, rod, state, rng = random_rod(11)
    R = Rotation.from_rotvec(rng.standard_normal(3)).as_matrix()
    moved = state.copy()
    moved.x = R @ state.x + rng.standard_normal((3, 1))
    moved.v = R @ state.v
    moved.Q = np.einsum("rci,dc->rdi", state.Q, R)  # each row d → R d
    for incompressible in (True, False):
        f0, t0, _, _, e0 = kernel_internal(state, props, incompressible, (1, 1, 1, 1, 0))
        f1, t1, _, _, e1 = kernel_internal(moved, props, incompressible, (1, 1, 1, 1, 0))
        assert close(f1, R @ f0) and close(t1, t0) and close(e1[:2], e0[:2])
        twin0 = twin_internal(state, rod, incompressible, (1, 1, 1, 1, 0))
        twin1 = twin_internal(moved, rod, incompressible, (1, 1, 1, 1, 0))
        assert close(twin1.force, twin0.force @ R.T) and close(twin1.torque, twin0.torque)


@pytest.mark.parametrize("seed", SEEDS)
def test_internal_forces_sum_to_zero(seed):
    # Newton's third law: without external loads the node forces cancel (each element pushes
    # its two nodes apart by ±N); relative to the largest node force.
    props, rod, state, rng = random_rod(seed)
    force = kernel_internal(state, props, True, random_factors(rng))[0]
    assert np.abs(force.sum(axis=1)).max() <= TOL * np.abs(force).max()
    twin = twin_internal(state, rod, True, (1, 1, 1, 1, 0))
    assert np.abs(twin.force.sum(axis=0)).max() <= TOL * np.abs(twin.force).max()


def _twin_energy(x, Q, rod, f_shear=1.0):
    loads = N.internal_loads(x, np.zeros_like(x), Q, np.zeros((Q.shape[0], 3)), rod,
                             incompressible=False, f_shear=f_shear)
    return loads.stretch_energy + loads.bend_energy


def test_the_twin_is_the_gradient_of_its_energy():
    # The twin checked against first principles, not against the kernel: for a compressible
    # rod at rest (no 1/e factors, no ω terms) the law is conservative. Forces are −∂E/∂x
    # exactly (central differences, h = 1e-7 m: error ~h²·E''' ~ 1e-8 relative). Torques:
    # the shear couple is exact too, but the bend-twist couple is −∂E/∂δ (body turn Q_i →
    # exp(−[δ]×)Q_i) only to first order in θ = κ·D0: the discrete κ × τ term is the
    # first-order part of the log's Jacobian, whose next term β·θ × (θ × c), β = 1/12 +
    # O(θ²), is left out: the misfit is below θ²/12 relative (θ up to 0.38 here: 8e-4 of the
    # bend-twist torques alone, f_shear = 0, where dropping κ × τ would misfit by 1.8e-2).
    props, rod, state, rng = random_rod(3)
    rod.rest_curvature[:] *= 0.3
    x, Q = N.to_twin(state.x), N.to_twin(state.Q)
    at_rest = (np.zeros_like(x), Q, np.zeros((Q.shape[0], 3)), rod)
    loads = N.internal_loads(x, *at_rest, incompressible=False)
    h = 1e-7
    numeric = np.zeros_like(x)
    for k in range(x.shape[0]):
        for c in range(3):
            xp, xm = x.copy(), x.copy()
            xp[k, c] += h
            xm[k, c] -= h
            numeric[k, c] = -(_twin_energy(xp, Q, rod) - _twin_energy(xm, Q, rod)) / (2 * h)
    assert close(loads.force, numeric, 1e-6)
    theta = np.arccos(np.clip(loads.cosines, -1, 1)).max()
    for f_shear in (1.0, 0.0):
        torque = N.internal_loads(x, *at_rest, incompressible=False, f_shear=f_shear).torque
        h = 1e-6
        numeric = np.zeros_like(torque)
        for i in range(Q.shape[0]):
            for c in range(3):
                turn = np.zeros(3)
                turn[c] = h
                Qp, Qm = Q.copy(), Q.copy()
                Qp[i] = N.rotation_matrix(-turn) @ Q[i]
                Qm[i] = N.rotation_matrix(turn) @ Q[i]
                numeric[i, c] = -(_twin_energy(x, Qp, rod, f_shear)
                                  - _twin_energy(x, Qm, rod, f_shear)) / (2 * h)
        assert close(torque, numeric, theta**2 / 12)
    assert not close(torque, numeric, 1e-5)  # a remainder exists: FD is not a tautology


# ---------------------------------------------------------------------------- clamps

def _clamp_setup(seed):
    props, rod, state, rng = random_rod(seed)
    n = props.rest_length.shape[0]
    start = np.ascontiguousarray(
        Rotation.from_rotvec(0.15 * rng.standard_normal(3)).as_matrix() @ state.Q[:, :, 0])
    end = np.ascontiguousarray(
        Rotation.from_rotvec(0.15 * rng.standard_normal(3)).as_matrix() @ state.Q[:, :, n - 1])
    axis = (state.x[:, -1] - state.x[:, 0]) + 0.1 * rng.standard_normal(3)
    axis /= np.linalg.norm(axis)
    controls = dict(start_rotation=float(rng.uniform(-0.3, 0.3)),
                    end_rotation=float(rng.uniform(-0.3, 0.3)),
                    f_bend=float(rng.uniform(0.7, 1.3)), f_radius_inv=float(rng.uniform(0.7, 1.3)))
    return props, rod, state, start, end, axis, controls


def kernel_clamps(state, props, start, end, axis, incompressible, controls):
    """_start_clamp_couple and _end_clamp_couple as advance calls them: (torque, bend energy,
    axial end torque, cosines)."""
    n = props.rest_length.shape[0]
    dilatation = np.linalg.norm(np.diff(state.x, axis=1), axis=0) / props.rest_length
    torque, energies = np.zeros((3, n)), np.zeros(4)
    clamp, couple = np.zeros((3, 3)), np.zeros(8)
    K._start_clamp_couple(state.Q, props, start, axis, controls["start_rotation"], dilatation,
                          controls["f_radius_inv"], controls["f_bend"], incompressible, torque,
                          energies, clamp, couple)
    start_cos = couple[7]
    end_torque = K._end_clamp_couple(state.Q, props, end, axis, controls["end_rotation"],
                                     dilatation, controls["f_radius_inv"], controls["f_bend"],
                                     incompressible, torque, energies, clamp, couple)
    return N.to_twin(torque), energies[1], end_torque, [start_cos, couple[7]]


def twin_clamps(state, rod, start, end, axis, incompressible, controls, share):
    return N.clamp_loads(N.to_twin(state.x), N.to_twin(state.Q), rod, start, end, axis,
                         controls["start_rotation"], controls["end_rotation"],
                         incompressible=incompressible, f_bend=controls["f_bend"],
                         f_radius_inv=controls["f_radius_inv"], share=share)


@pytest.mark.parametrize("incompressible", [True, False])
@pytest.mark.parametrize("seed", SEEDS)
def test_clamp_couples_match_the_twin(seed, incompressible):
    # Against the twin with the energy's share of the κ × c term (half: see
    # test_kernel_clamp_couple_is_the_gradient_of_its_energy).
    props, rod, state, start, end, axis, controls = _clamp_setup(seed)
    torque, energy, end_torque, cosines = kernel_clamps(state, props, start, end, axis,
                                                        incompressible, controls)
    twin = twin_clamps(state, rod, start, end, axis, incompressible, controls, N.ENERGY_SHARE)
    assert close(torque, twin[0]) and close(energy, twin[1]) and close(end_torque, twin[2])
    assert close(cosines, twin[3])


def test_clamp_frames_of_a_shipped_scene_match_the_twin():
    # The real clamp reference of twist_under_load turned by a real end rotation (3 turns),
    # on a rod twisted by a bit less: the clamps pull the end elements round.
    problem = build(rodphase.load("twist_under_load", {"rod.elements": 12}))
    start, end = clamp_reference(problem)
    props = K.RodProperties(local_mask=np.zeros(11), **_rod_arrays(problem))
    state = straight_state(problem.rod, twist_turns=2.9)
    axis = np.asarray(problem.ends.axis, float)
    controls = dict(start_rotation=0.0, end_rotation=3 * 2 * np.pi, f_bend=1.0, f_radius_inv=1.0)
    torque, energy, end_torque, _ = kernel_clamps(state, props, start, end, axis, True, controls)
    twin = twin_clamps(state, N.NaiveRod.from_kernel(props), start, end, axis, True, controls,
                       N.ENERGY_SHARE)
    assert close(torque, twin[0]) and close(energy, twin[1]) and close(end_torque, twin[2])
    assert end_torque > 0  # the clamp turned ahead of the rod drags it forward


def _clamp_energy_gradient(rod, state, start, end, axis, controls):
    """−∂E/∂δ of the two clamp springs' energy for a body turn of elements 0 and n-1
    (compressible: no 1/e³, so the energy is the potential), central differences."""
    x, Q = N.to_twin(state.x), N.to_twin(state.Q)
    args = (controls["start_rotation"], controls["end_rotation"])

    def energy(Q):
        return N.clamp_loads(x, Q, rod, start, end, axis, *args, incompressible=False)[1]

    h = 1e-6
    numeric = np.zeros((Q.shape[0], 3))
    for i in (0, Q.shape[0] - 1):
        for c in range(3):
            turn = np.zeros(3)
            turn[c] = h
            Qp, Qm = Q.copy(), Q.copy()
            Qp[i] = N.rotation_matrix(-turn) @ Q[i]
            Qm[i] = N.rotation_matrix(turn) @ Q[i]
            numeric[i, c] = -(energy(Qp) - energy(Qm)) / (2 * h)
    return numeric


def _clamp_misfits(seed, share, kernel):
    """Relative misfit of the clamp torques to −∂E/∂δ, for clamps turned off their elements
    by ~0.15 and ~0.04 rad: a law right to first order in θ misfits as θ² (ratio ~14), one
    wrong at first order as θ (ratio ~4)."""
    misfits = []
    for size in (1.0, 0.25):
        props, rod, state, start, end, axis, controls = _clamp_setup(seed)
        controls = dict(controls, f_bend=1.0, f_radius_inv=1.0,
                        start_rotation=size * controls["start_rotation"],
                        end_rotation=size * controls["end_rotation"])
        for frame, element in ((start, 0), (end, -1)):
            off = Rotation.from_matrix(frame @ state.Q[:, :, element].T).as_rotvec()
            frame[:] = Rotation.from_rotvec(size * off).as_matrix() @ state.Q[:, :, element]
        # rest curvature a fraction of the misfit, so that κ − κ0 and κ are of one order
        rod.rest_curvature[:] *= 0.1 * size
        props = props._replace(rest_curvature=N.from_twin(rod.rest_curvature))
        numeric = _clamp_energy_gradient(rod, state, start, end, axis, controls)
        if kernel:
            torque = kernel_clamps(state, props, start, end, axis, False, controls)[0]
        else:
            torque = twin_clamps(state, rod, start, end, axis, False, controls, share)[0]
        misfits.append(np.abs(torque - numeric).max() / np.abs(numeric).max())
    return misfits


def test_twin_clamp_couple_is_the_gradient_of_its_energy():
    # The twin's clamp (share ½) is the spring's rotational derivative to first order in θ,
    # as the interior couples are: its misfit falls as θ²; the whole share's only as θ.
    for seed in SEEDS:
        big, small = _clamp_misfits(seed, N.ENERGY_SHARE, kernel=False)
        assert big / small > 10
        big, small = _clamp_misfits(seed, N.WHOLE_SHARE, kernel=False)
        assert big / small < 6


def test_kernel_clamp_couple_is_the_gradient_of_its_energy():
    # The kernel's clamp, as the twin's with share ½: its misfit to −∂E/∂δ falls as θ² (ratio
    # > 10 for θ quartered; the whole share, the kernel before 2026-12-06, gave < 6)
    for seed in SEEDS:
        big, small = _clamp_misfits(seed, None, kernel=True)
        assert big / small > 10


# ---------------------------------------------------------------------------- external loads

@pytest.mark.parametrize("seed", SEEDS)
def test_external_loads_match_the_twin(seed):
    props, rod, state, rng = random_rod(seed)
    n = props.rest_length.shape[0]
    end_force = float(rng.uniform(-5.0, 5.0))
    direction = rng.standard_normal(3)
    direction /= np.linalg.norm(direction)
    gravity = rng.standard_normal(3) * 9.81
    r2 = float(rng.uniform(0.8, 1.2)) ** 2
    pull = float(rng.uniform(-1.0, 1.0))
    first, last = sorted(rng.choice(n + 1, 2, replace=False))
    force = np.zeros((3, n + 1))
    K._external_loads(state.x, props.node_mass, r2, end_force, direction, gravity, pull,
                      int(first), int(last), force)
    twin = N.external_loads(N.to_twin(state.x), rod, end_force, direction, gravity,
                            radius_factor=np.sqrt(r2), local_pull=pull, segment=(first, last))
    assert close(N.to_twin(force), twin)
    # the pull is internal: it adds nothing to the total
    total = end_force * direction + rod.node_mass.sum() * r2 * gravity
    assert np.allclose(force.sum(axis=1), total, rtol=TOL, atol=TOL * np.abs(total).max())


# ---------------------------------------------------------------------------- contact

def kernel_contact(x, v, radius, pairs, stiffness, damping, scale=1.0, friction=0.0,
                   slip_speed=1e-4, thinning=False):
    """contact_forces_in with the dashpot explicit: (force (n+1, 3), (touching, worst overlap
    / radius, its element, energy, noted))."""
    n = x.shape[0] - 1
    pairs = np.array(pairs, dtype=np.int64).T.copy()
    force = np.zeros((3, n + 1))
    out = contact_forces_in(N.from_twin(x), N.from_twin(v), np.asarray(radius, float), pairs,
                            pairs.shape[1], np.asarray(stiffness, float),
                            np.asarray(damping, float), scale, friction, slip_speed,
                            1.0 if thinning else 0.0, force,
                            np.zeros((DASHPOT_ROWS, pairs.shape[1])), False, np.zeros((3, n)),
                            np.zeros(n), np.zeros(n))
    return N.to_twin(force), out


def two_segments(p0, p1, q0, q1):
    """A three-element 'rod' whose elements 0 and 2 are the two segments (element 1 only
    joins them and takes no part): the pair (0, 2)."""
    return np.array([p0, p1, q0, q1], dtype=float)


A = 0.01  # radius of the hand-placed capsules [m]
L = 0.03  # their length [m]
K_SPRING = 1e4  # N/m
HAND_PLACED = {
    # name: (nodes, closest parameters (s, t), unit normal from j towards i)
    "crossed": (two_segments((-L / 2, 0, 0), (L / 2, 0, 0), (0, -L / 2, 1.5 * A),
                             (0, L / 2, 1.5 * A)), (0.5, 0.5), (0, 0, -1)),
    "parallel": (two_segments((0, 0, 0), (L, 0, 0), (L / 2, 1.5 * A, 0),
                              (3 * L / 2, 1.5 * A, 0)), (0.5, 0.0), (0, -1, 0)),
    "end_on": (two_segments((0, 0, 0), (L, 0, 0), (L / 4, 0, 1.5 * A), (L / 4, 0, 1.5 * A + L)),
               (0.25, 0.0), (0, 0, -1)),
    "ends_touch": (two_segments((0, 0, 0), (L, 0, 0), (L + 1.5 * A, 0, 0),
                                (L + 1.5 * A + L, L, 0)), (1.0, 0.0), (-1, 0, 0)),
    "skew_off_end": (two_segments((0, 0, 0), (L, 0, 0), (L + 0.5 * A, -L / 2, A),
                                  (L + 0.5 * A, L / 2, A)),
                     (1.0, 0.5), (-1 / np.sqrt(5), 0, -2 / np.sqrt(5))),
}


@pytest.mark.parametrize("name", sorted(HAND_PLACED))
def test_hand_placed_contacts_match_by_hand_and_the_twin(name):
    x, (s, t), normal = HAND_PLACED[name]
    radius = np.full(3, A)
    stiffness = np.full(3, K_SPRING)
    v = np.zeros_like(x)
    force, (touching, worst, worst_at, energy, _) = kernel_contact(x, v, radius, [(0, 2)],
                                                                   stiffness, np.zeros(3))
    # by hand: overlap 2a − d, force k·δ along the normal split by (s, t)
    p = x[0] + s * (x[1] - x[0])
    q = x[2] + t * (x[3] - x[2])
    overlap = 2 * A - np.linalg.norm(p - q)
    assert overlap > 0
    pair = K_SPRING * overlap * np.asarray(normal)
    expected = np.array([(1 - s) * pair, s * pair, -(1 - t) * pair, -t * pair])
    assert close(force, expected)
    assert touching == 1 and close(energy, 0.5 * K_SPRING * overlap**2)
    assert close(worst, overlap / A) and worst_at == 0
    assert N.closest_parameters(*x) == pytest.approx((s, t), abs=1e-12)
    twin, twin_energy = N.contact_pair(x, v, radius, 0, 2, stiffness, np.zeros(3))
    assert close(force, twin) and close(energy, twin_energy)


def test_separated_and_pulled_apart_pairs_add_nothing():
    x = HAND_PLACED["crossed"][0].copy()
    radius, stiffness, damping = np.full(3, A), np.full(3, K_SPRING), np.full(3, 100.0)
    far = x.copy()
    far[2:, 2] += A  # gap 0.5a: no contact
    force, out = kernel_contact(far, np.zeros_like(x), radius, [(0, 2)], stiffness, damping)
    assert not force.any() and out[0] == 0
    # touching, but separating so fast that the dashpot would pull: no force, energy counted
    v = np.zeros_like(x)
    v[2:, 2] = 1.0  # j leaves i at 1 m/s: the dashpot's c·v = 100 N beats k·δ = 50 N
    force, out = kernel_contact(x, v, radius, [(0, 2)], stiffness, damping)
    twin, energy = N.contact_pair(x, v, radius, 0, 2, stiffness, damping)
    assert not force.any() and not twin.any()
    assert out[0] == 1 and close(out[3], energy) and energy > 0


def random_crossing(rng):
    """Two segments whose closest points lie anywhere on them or beyond their ends (clamped),
    at a distance up to 1.5 × the sum of radii: some overlap, some not."""
    p0 = 0.01 * rng.standard_normal(3)
    u = rng.standard_normal(3)
    u *= L / np.linalg.norm(u)
    w = rng.standard_normal(3)
    w *= L * rng.uniform(0.5, 1.5) / np.linalg.norm(w)
    s, t = rng.uniform(-0.3, 1.3, 2)
    out = np.cross(u, w)
    out /= np.linalg.norm(out)
    q0 = p0 + s * u - t * w + out * rng.uniform(-1.5, 1.5) * 2 * A
    return two_segments(p0, p0 + u, q0, q0 + w)


def test_random_crossing_pairs_match_the_twin():
    # Overlapping and separate pairs, all law options: dashpot, stiffness scale (√scale on
    # the dashpot), friction (sliding and sticking), thinning of an incompressible rod.
    rng = np.random.default_rng(7)
    touched = 0
    for _ in range(300):
        x = random_crossing(rng)
        v = 0.1 * rng.standard_normal(x.shape)
        radius = A * rng.uniform(0.8, 1.2, 3)
        stiffness = rng.uniform(1e3, 1e4, 3)
        damping = rng.uniform(0.0, 5.0, 3)
        law = dict(scale=float(rng.uniform(0.5, 2.0)), friction=float(rng.choice([0.0, 0.3])),
                   slip_speed=float(rng.choice([1e-4, 1.0])), thinning=bool(rng.integers(2)))
        force, out = kernel_contact(x, v, radius, [(0, 2)], stiffness, damping, **law)
        twin, energy = N.contact_pair(x, v, radius, 0, 2, stiffness, damping, **law)
        assert close(out[3], energy)
        if energy > 0:
            touched += 1
            assert close(force, twin)
            assert np.abs(force.sum(axis=0)).max() <= TOL * np.abs(force).max()
        else:
            assert not force.any() and not twin.any()
    assert touched > 100


def test_twin_contact_spring_is_the_gradient_of_its_energy():
    # At rest, without friction, the twin's pair force is −∇(½kδ²), with the radii thinning
    # as a0/√e when `thinning` (central differences, h = 1e-9 m against overlaps ~1e-3 m).
    rng = np.random.default_rng(3)
    rest_radius = np.full(3, A)
    rest_length = np.array([L, 1.0, L])
    checked = 0
    while checked < 10:
        x = random_crossing(rng)
        stiffness = np.full(3, K_SPRING)

        def energy(x, thinning):
            e = np.linalg.norm(np.diff(x, axis=0), axis=1) / rest_length
            radius = rest_radius / np.sqrt(e) if thinning else rest_radius
            return N.contact_pair(x, np.zeros_like(x), radius, 0, 2, stiffness, np.zeros(3))[1]

        for thinning in (False, True):
            e = np.linalg.norm(np.diff(x, axis=0), axis=1) / rest_length
            radius = rest_radius / np.sqrt(e) if thinning else rest_radius
            force, spring = N.contact_pair(x, np.zeros_like(x), radius, 0, 2, stiffness,
                                           np.zeros(3), thinning=thinning)
            if spring < 1e-3 * K_SPRING * A**2:
                break  # too shallow: the difference quotient would straddle the edge
            h = 1e-9
            numeric = np.zeros_like(x)
            for k in (0, 1, 2, 3):
                for c in range(3):
                    xp, xm = x.copy(), x.copy()
                    xp[k, c] += h
                    xm[k, c] -= h
                    numeric[k, c] = -(energy(xp, thinning) - energy(xm, thinning)) / (2 * h)
            assert close(force, numeric, 1e-5)
        else:
            checked += 1


def hairpin(rng, n):
    """A rod of 2·(n//2) + 1 elements folded back on itself: two straight legs 1.7 radii
    apart centre to centre, crossing at a small angle, joined by one element at the top,
    with noise. Many touching pairs, some elements in several."""
    s = np.linspace(0.0, 1.0, n // 2 + 1)
    leg = np.outer(s, [0.0, 0.0, 0.2])
    back = leg[::-1] + [1.7 * A, 0.0, 0.0] + np.outer(s[::-1], [0.0, 0.3 * A, 0.0])
    x = np.vstack([leg, back])
    return x + 0.1 * A * rng.standard_normal(x.shape)


def test_rod_self_contact_matches_the_twin():
    # A whole rod's self-contact: every pair beyond the exclusion, as the kernel sums them.
    rng = np.random.default_rng(5)
    for n in (12, 18):
        x = hairpin(rng, n)
        n = x.shape[0] - 1
        v = 0.05 * rng.standard_normal(x.shape)
        e = np.linalg.norm(np.diff(x, axis=0), axis=1) / (0.2 / (n // 2))
        radius = A / np.sqrt(e)
        stiffness = rng.uniform(1e3, 1e4, n)
        damping = rng.uniform(0.0, 2.0, n)
        pairs = N.all_pairs(n, 2)
        law = dict(scale=1.3, friction=0.2, slip_speed=1e-3, thinning=True)
        force, out = kernel_contact(x, v, radius, pairs, stiffness, damping, **law)
        twin, energy, touching = N.contact_loads(x, v, radius, pairs, stiffness, damping, **law)
        assert touching >= 5 and out[0] == touching
        assert close(force, twin) and close(out[3], energy)
        # momentum: contact forces between parts of one rod cancel
        assert np.abs(force.sum(axis=0)).max() <= TOL * np.abs(force).max()
        # objectivity of the contact law: rotate everything
        R = Rotation.from_rotvec(rng.standard_normal(3)).as_matrix()
        turned, _ = kernel_contact(x @ R.T + 1.0, v @ R.T, radius, pairs, stiffness, damping,
                                   **law)
        assert close(turned, force @ R.T)
