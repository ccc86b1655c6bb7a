"""The fused time loop of a discrete Cosserat rod (Gazzola et al., R. Soc. Open Sci. 2018).

Everything here is numba-compiled and knows nothing of files, YAML or scenes: arrays in,
arrays out. Layout is structure-of-arrays so that LLVM can vectorise the element loops:

    x, v      (3, n+1)    node positions [m] and velocities [m/s], lab frame
    Q         (3, 3, n)   element directors; Q[r, :, i] is d_{r+1} of element i (lab frame)
    w         (3, n)      element angular velocities [rad/s], material frame

Rod properties (rest values; see model.py for how they are built):
    rest_length (n,), rest_voronoi (n-1,), node_mass (n+1,), inertia (3, n) = ρ·l0·diag(I),
    shear_stiffness (3, n) = diag(4GA/3, 4GA/3, EA), bend_stiffness (3, n-1) = diag(EI1, EI2, GI3)
    at the Voronoi domains, rest_curvature (3, n-1), rest_shear (3, n), rest_radius (n,),
    contact_k / contact_c (n,) per-element contact stiffness [N/m] and dashpot [N s/m],
    local_mask (n-1,) 1.0 on the Voronoi domains of the "active agent" segment.

Controls are piecewise-linear tables in time (see the T_* indices), read by the loop; the
scalar settings are packed in `ints` and `floats` (I_* and F_* indices). The integrator is
position Verlet with the two half drifts merged, so positions live at half steps inside the
loop; damping multiplies velocities by exp(-ν·dt), which is stable for any ν ≥ 0, and is
applied before the boundary conditions so that prescribed motions are exact.

The functions advance calls on every step are inlined into it (inline="always", at numba's
IR level), so that their machine code exists once: a kernel loaded from numba's disk cache
then gives the same bits as a fresh compile (tests/test_kernel_cache.py). The functions that
run at most at check steps (_guards, _shear_guard, _record, _settle_windows, _stop_test with
_probe_distance and _start_probe) or once per call (_work_arrays, _report) are compiled on
their own instead (inline="never"), which shortens advance's first compile; their results
are the inlined ones to the bit (benchmarks/reference_positions.py). The per-step pieces
(_drift, rotated_frame, _kinetic_energy, the loads) stay inlined, and the arrays they work in
come from _step_arrays, inlined, so that LLVM sees them as advance's own allocations.

The step loop is written out in advance rather than as a page of helper calls: with
fastmath's 'reassoc' (_jit.FASTMATH) LLVM reorders sums by the shape of the code around them,
so moving a block into a helper moves the results' last bits, and every inlined helper that
binds arrays adds reference counting that costs time per step. Only the setup and the end
are pieces of their own (_drag_rates, _step_arrays, _work_arrays, _report), and contact's
counters travel as one record of scalars (ContactState). The measurements behind these
choices, with their dates: docs/history/kernel-speed.md.
"""

from collections import namedtuple

import numpy as np

from ..result import HISTORY_COLUMNS
from ._jit import FASTMATH as _FASTMATH
from ._jit import njit
from .contact import (
    DASHPOT_ROWS,
    add_body_forces,
    apply_dashpots,
    build_pairs,
    contact_forces_in,
    fold_forces,
    near_pairs,
)
from .neo_hookean import N_WORK as N_WORK_NEO_HOOKEAN
from .neo_hookean import clamp_couple_neo_hookean, internal_loads_neo_hookean
from .rotation import log_factor as _log_factor

# The kernel's inputs, by name. numba compiles a namedtuple of arrays and scalars into a
# plain struct (no Python per step) and caches functions taking them; simulate.py fills the
# fields by name. The field types must not vary between calls (each new combination of
# types is a new compile): simulate.py casts every scalar (bool, int, float).

# rest properties of the rod (see model.py and simulate._rod_arrays for how they are built)
RodProperties = namedtuple("RodProperties", [
    "rest_length",  # (n,) m
    "rest_voronoi",  # (n-1,) m
    "node_mass",  # (n+1,) kg
    "inertia",  # (3, n) ρ·l0·diag(I1, I2, I3), kg m
    "shear_stiffness",  # (3, n) diag(4GA/3, 4GA/3, EA), N
    "bend_stiffness",  # (3, n-1) diag(EI1, EI2, GI3) at the Voronoi domains, N m²
    "rest_curvature",  # (3, n-1) 1/m; [2] is the rest twist
    "rest_shear",  # (3, n)
    "rest_radius",  # (n,) m
    "contact_k",  # (n,) N/m per element
    "contact_c",  # (n,) N s/m per element
    "local_mask",  # (n-1,) 1.0 on the Voronoi domains of the "active agent" segment
])

# how the ends are held: what the boundary conditions read
Boundary = namedtuple("Boundary", [
    "start_held",  # (3,) int64: 1 where x, y, z of node 0 are held
    "start_frame_held",  # bool: element 0's frame is clamped
    "end_held",  # (3,) int64: 1 where x, y, z of node n are held
    "end_frame_held",  # bool: element n-1's frame is clamped
    "start_position",  # (3,) m, where node 0's held components are held
    "end_position",  # (3,) m, node n's, before the end displacement control
    "start_frame",  # (3, 3) the start clamp's frame (rows d1 d2 d3) before its rotation
    "end_frame",  # (3, 3) the end clamp's
    "axis",  # (3,) unit rod axis (lab): direction of end rotation and displacement
    "force_direction",  # (3,) unit direction of the end force
    "start_body",  # bool: a rigid rod beyond node 0, along -axis, takes part in contact
    "end_body",  # bool: a rigid rod beyond node n, along +axis (the loading rod)
    "body_radius",  # m, radius of the end bodies
    "segment_first",  # int: first node of the active-agent segment
    "segment_last",  # int: last node of it
    "gravity",  # (3,) m/s²
])

# the integrator, contact and the guards
Settings = namedtuple("Settings", [
    "dt",  # s
    "incompressible",  # bool: A·e constant, radius a0/√e; the 1/e and 1/e³ factors
    "damping",  # 1/s, translational
    "damping_rotation",  # 1/s, rotational, about d1 and d2 (half of it about d3)
    "quadratic_drag",  # 1/m: extra drag rate per unit speed (speed × this, in 1/s)
    "strain_rate_damping",  # s: axial Kelvin–Voigt time η (element dashpot EA·η/l), 0 = off
    "drag_radius",  # m: lever that turns spin into a surface speed for the quadratic drag
    "contact",  # bool: self-contact on
    "exclusion",  # int: elements closer than this along the rod never touch
    "fold",  # bool: nodes inside the exclusion kept from folding tighter than the rod (fold_forces)
    "thinning_force",  # bool: the contact spring's pull along thinning elements (contact_forces_in)
    "sleep",  # bool, with contact off: contact computed but not applied; S_WAKE at a touch
    "implicit_dashpot",  # bool: contact dashpots as backward-Euler impulses after the kick
    "friction",  # Coulomb coefficient
    "slip_speed",  # m/s, below it friction is viscous
    "skin",  # m: Verlet-list margin of the candidate pairs
    "near_skin",  # m: smallest gap margin of the short (near) contact list (it adapts upward)
    "penetration_limit",  # overlap / radius that counts as a failed contact
    "speed_limit",  # m/s; faster than this is a blow-up
    "history_every",  # int: steps between history rows
    "check_every",  # int: steps between guard and equilibrium checks
    "stop_at_equilibrium",  # bool
    "equilibrium_after",  # s: no equilibrium stop before this time (controls still moving)
    "hold_tolerance",  # residual force / force scale, and (squared) kinetic energy / (force scale × L0)
    "force_scale",  # N
    "length_scale",  # m
    "settle_window",  # s: window over which the mean shape is compared (0: residual test only)
    "settle_distance",  # m: the mean shape settled if no surface point moved more than this
    "probe",  # bool: an equilibrium ends the hold only if it survives a perturbation (stable)
    "probe_size",  # m: largest node displacement of the stability probe
    "probe_return",  # stable once the probe's component along its shape decayed below this fraction
    "probe_leave",  # unstable once that component, or any node's distance, grows past this many probes
])

# control tables: piecewise linear in time, row T_* of times (rows, width), values, counts (rows,)
ControlTables = namedtuple("ControlTables", ["times", "values", "counts"])

# what advance writes: history (H, N_HISTORY), snap_x (H, 3, n+1), snap_d1 (H, 3, n), info (N_INFO,)
Output = namedtuple("Output", ["history", "snap_x", "snap_d1", "info"])

# contact's running state from step to step (_contact_loads), besides its arrays (the lists
# `pairs` and `near`, regrown by it, and their positions at the last builds). Scalars only: a
# record of arrays passed to an inlined helper costs reference counts at every step (the
# module docstring).
ContactState = namedtuple("ContactState", [
    "n_pairs",  # int: candidate pairs in `pairs` (grid search, midpoint cutoff with a skin)
    "n_near",  # int: pairs in `near`, those of them within near_margin of touching
    "radius_cut",  # m: the candidate list holds pairs for radii up to this (1.1 x the widest)
    "rebuilds",  # int: builds of the candidate list so far
    "near_rebuilds",  # int: builds of the near list so far
    "max_pairs",  # int: the most candidate pairs
    "near_margin",  # m: the near list's gap margin, adapted between near_skin and skin/2
    "near_age",  # int: steps since the near list was built
])

# The control tables, one row each: the Controls field it comes from, its unit, its meaning.
# Row order is the kernel's table index (T_*), derived here as the history's slots are.
CONTROL_TABLES = (
    ("end_rotation", "rad", "about the axis, of the end frame (element n-1)"),
    ("end_force", "N", "along the force direction, on node n"),
    ("end_displacement", "m", "along the axis, of the held components of node n"),
    ("stiffness", "1", "factor on E and G (modulus ramp)"),
    ("radius", "1", "factor on the radius (growth); rest twist follows as 1/factor"),
    ("local_twist", "rad/m", "added to the rest twist on the active segment"),
    ("local_pull", "N", "pulling the two ends of the active segment together"),
    ("start_rotation", "rad", "about the axis, of the start frame (element 0)"),
)
CONTROL_TABLE_NAMES = tuple(name for name, _, _ in CONTROL_TABLES)
T_END_ROTATION = CONTROL_TABLE_NAMES.index("end_rotation")
T_END_FORCE = CONTROL_TABLE_NAMES.index("end_force")
T_END_DISPLACEMENT = CONTROL_TABLE_NAMES.index("end_displacement")
T_STIFFNESS = CONTROL_TABLE_NAMES.index("stiffness")
T_RADIUS = CONTROL_TABLE_NAMES.index("radius")
T_LOCAL_TWIST = CONTROL_TABLE_NAMES.index("local_twist")
T_LOCAL_PULL = CONTROL_TABLE_NAMES.index("local_pull")
T_START_ROTATION = CONTROL_TABLE_NAMES.index("start_rotation")
N_TABLES = len(CONTROL_TABLES)

# history slots, from the one table of columns (name, unit, meaning) in result.py
H_TIME = HISTORY_COLUMNS.index("time")
H_END_ROTATION = HISTORY_COLUMNS.index("end_rotation")
H_END_FORCE = HISTORY_COLUMNS.index("end_force")
H_END_TORQUE = HISTORY_COLUMNS.index("end_torque")
H_END_DISPLACEMENT = HISTORY_COLUMNS.index("end_displacement")
H_APPLIED_FORCE = HISTORY_COLUMNS.index("applied_force")
H_STRETCH_ENERGY = HISTORY_COLUMNS.index("stretch_energy")
H_BEND_ENERGY = HISTORY_COLUMNS.index("bend_energy")
H_KINETIC_ENERGY = HISTORY_COLUMNS.index("kinetic_energy")
H_CONTACTS = HISTORY_COLUMNS.index("contacts")
H_PENETRATION = HISTORY_COLUMNS.index("penetration")
H_RESIDUAL = HISTORY_COLUMNS.index("residual")
H_STIFFNESS = HISTORY_COLUMNS.index("stiffness_factor")
H_RADIUS_FACTOR = HISTORY_COLUMNS.index("radius_factor")
H_CONTACT_ENERGY = HISTORY_COLUMNS.index("contact_energy")
H_START_ROTATION = HISTORY_COLUMNS.index("start_rotation")
N_HISTORY = len(HISTORY_COLUMNS)

# cos 135°: neighbouring frames (and an end frame and its clamp) turned further apart than
# this bring the matrix log near its branch cut at 180°, where twist would silently wrap
COS_MAX_TURN = -0.7071
# cos 45°: an element whose frame's d3 is this far off its tangent is sheared beyond what a
# rod model describes (Fig 3's tightest solenoids shear by 20-30° at n = 80 before a snap runs
# away past 60°); d1 then lies near the centreline, the twist measured about it wraps, and
# link is lost to a numerical runaway. More elements usually mend it (runner.REFINABLE_GUARDS)
COS_MAX_SHEAR = 0.7071

# status codes advance returns
S_COMPLETED = 0
S_EQUILIBRIUM = 1
S_NAN = 2
S_SPEED = 3
S_PENETRATION = 4
S_RESOLUTION = 5  # neighbouring frames turned by more than 135°: the rod is under-resolved
S_CLAMP_LAG = 6  # an end frame lags its turning clamp by more than 135°: twisted too fast
S_SHEAR = 7  # an element sheared by more than 45°: a runaway, not a rod
# not a guard: sleeping contact (settings.sleep) found the rod touching itself or an end body;
# the state is at the returned time, and the caller goes on with contact on (and its step)
S_WAKE = 8

# The guards, one row each (as diffrax's RESULTS): the short name for diagnostics["guard"]
# (what a caller may act on), what tripped, where info[D_WHERE] points, and what to change.
Guard = namedtuple("Guard", ["name", "message", "where", "advice"])
_STEP_ADVICE = ("Try a smaller solver.dt or solver.safety, more solver.damping, or a stiffer "
                "contact.stiffness.")
GUARDS = {
    S_NAN: Guard("non_finite", "non-finite state (NaN or inf)", "node", _STEP_ADVICE),
    S_SPEED: Guard("speed", "runaway velocity", "node", _STEP_ADVICE),
    S_PENETRATION: Guard("penetration", "contact penetration", "element", _STEP_ADVICE),
    S_RESOLUTION: Guard("resolution",
                        "under-resolved rod (neighbouring frames turned by more than 135°)",
                        "Voronoi domain",
                        "Use more rod.elements (twist per element = Φa·L0/(a·n) rad)."),
    S_CLAMP_LAG: Guard("clamp_lag", "end frame lagging its turning clamp by more than 135°",
                       "element", "The twist is put in faster than it spreads along the rod: "
                       "lower loading.twist_rate (turns/s)."),
    S_SHEAR: Guard("shear", "element sheared by more than 45° (its frame's d3 that far off "
                   "its tangent)", "element",
                   # Fig 3's runaways at Φa >= 2.41 trip at any resolution, step or twist
                   # rate, an element of a strand stretched to 1.8-2.1 while the law's
                   # 1/e³ bend couple feeds the motion (docs/history/fig3-corner.md, "Where the
                   # corner's failures get their energy"): the step advice alone sent users
                   # the wrong way
                   "If it trips here at any step and resolution (a runaway of the Cosserat "
                   "model, often with elements stretched past 1.4, where the incompressible "
                   "law's stiffnesses have fallen as 1/e and 1/e³), only another model removes "
                   "it: a stiffer shear (material.shear_stiffness, N, 4GA/3, or "
                   "material.shear_modulus). If not, use more rod.elements. " + _STEP_ADVICE),
}

# What advance reports besides the history, one row each (name, meaning); info[D_*] slots
# are derived from it.
DIAGNOSTICS = (
    ("where", "node or element index where a guard tripped"),
    ("value", "the value that tripped it"),
    ("max_penetration", "largest contact overlap / radius"),
    ("rebuilds", "rebuilds of the candidate (grid) contact list"),
    ("max_pairs", "most candidate contact pairs"),
    ("residual", "last residual force / force scale"),
    ("kinetic", "last kinetic energy / (force scale x L0)"),
    ("settled", "1 if the last equilibrium stop was by the settled mean shape, not the residual"),
    ("settle_motion", "m: last settle measure: motion of the window-mean shape or spread"),
    ("near_rebuilds", "rebuilds of the near contact list"),
    ("probes", "stability probes applied (perturbations of a candidate equilibrium)"),
    ("probes_left", "probes after which the rod left the candidate (it was unstable)"),
)
DIAGNOSTIC_NAMES = tuple(name for name, _ in DIAGNOSTICS)
D_WHERE = DIAGNOSTIC_NAMES.index("where")
D_VALUE = DIAGNOSTIC_NAMES.index("value")
D_MAX_PENETRATION = DIAGNOSTIC_NAMES.index("max_penetration")
D_REBUILDS = DIAGNOSTIC_NAMES.index("rebuilds")
D_MAX_PAIRS = DIAGNOSTIC_NAMES.index("max_pairs")
D_RESIDUAL = DIAGNOSTIC_NAMES.index("residual")
D_KINETIC = DIAGNOSTIC_NAMES.index("kinetic")
D_SETTLED = DIAGNOSTIC_NAMES.index("settled")
D_SETTLE_MOTION = DIAGNOSTIC_NAMES.index("settle_motion")
D_NEAR_REBUILDS = DIAGNOSTIC_NAMES.index("near_rebuilds")
D_PROBES = DIAGNOSTIC_NAMES.index("probes")
D_PROBES_LEFT = DIAGNOSTIC_NAMES.index("probes_left")
N_INFO = len(DIAGNOSTICS)


@njit(cache=True, inline="always")
def table_value(times, values, count, t):
    """Piecewise-linear interpolation, constant beyond both ends."""
    if count == 1 or t <= times[0]:
        return values[0]
    if t >= times[count - 1]:
        return values[count - 1]
    lo = 0
    hi = count - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if times[mid] <= t:
            lo = mid
        else:
            hi = mid
    f = (t - times[lo]) / (times[hi] - times[lo])
    return values[lo] + f * (values[hi] - values[lo])


@njit(cache=True, inline="always")
def table_slope(times, values, count, t):
    if count == 1 or t < times[0] or t >= times[count - 1]:
        return 0.0
    lo = 0
    while times[lo + 1] <= t:
        lo += 1
    return (values[lo + 1] - values[lo]) / (times[lo + 1] - times[lo])


@njit(cache=True, fastmath=_FASTMATH, inline="always")
def rotate_frames(Q, w, scale):
    """Q_i ← exp(−scale·[w_i]×)·Q_i: a body rotation by angle scale·|w_i| about w_i (material)."""
    n = Q.shape[2]
    for i in range(n):
        u0 = scale * w[0, i]
        u1 = scale * w[1, i]
        u2 = scale * w[2, i]
        th2 = u0 * u0 + u1 * u1 + u2 * u2
        # sinθ/θ and (1−cosθ)/θ² to θ⁶, branch-free: a step turns an element by ω·dt ≪ 0.1
        # rad (truncation < 3e-14 there); a faster spin is a blow-up the speed guard stops
        a = 1.0 - th2 / 6.0 * (1.0 - th2 / 20.0 * (1.0 - th2 / 42.0))
        b = 0.5 - th2 / 24.0 * (1.0 - th2 / 30.0 * (1.0 - th2 / 56.0))
        # R = I − a[u]× + b[u]×²   (the minus: Q maps lab to material coordinates)
        r00 = 1.0 - b * (u1 * u1 + u2 * u2)
        r11 = 1.0 - b * (u0 * u0 + u2 * u2)
        r22 = 1.0 - b * (u0 * u0 + u1 * u1)
        r01 = a * u2 + b * u0 * u1
        r10 = -a * u2 + b * u0 * u1
        r02 = -a * u1 + b * u0 * u2
        r20 = a * u1 + b * u0 * u2
        r12 = a * u0 + b * u1 * u2
        r21 = -a * u0 + b * u1 * u2
        for c in range(3):
            q0 = Q[0, c, i]
            q1 = Q[1, c, i]
            q2 = Q[2, c, i]
            Q[0, c, i] = r00 * q0 + r01 * q1 + r02 * q2
            Q[1, c, i] = r10 * q0 + r11 * q1 + r12 * q2
            Q[2, c, i] = r20 * q0 + r21 * q1 + r22 * q2


@njit(cache=True, inline="always")
def rotated_frame(reference, axis, angle, out):
    """out = reference · R(axis, angle)ᵀ: the reference body turned by `angle` about lab `axis`."""
    c = np.cos(angle)
    s = np.sin(angle)
    k0 = axis[0]
    k1 = axis[1]
    k2 = axis[2]
    # R = cI + s[k]× + (1 − c) k kᵀ, as scalars: this runs every step, so no allocation
    q = 1.0 - c
    r00 = c + q * k0 * k0
    r01 = -s * k2 + q * k0 * k1
    r02 = s * k1 + q * k0 * k2
    r10 = s * k2 + q * k1 * k0
    r11 = c + q * k1 * k1
    r12 = -s * k0 + q * k1 * k2
    r20 = -s * k1 + q * k2 * k0
    r21 = s * k0 + q * k2 * k1
    r22 = c + q * k2 * k2
    for r in range(3):
        a0 = reference[r, 0]
        a1 = reference[r, 1]
        a2 = reference[r, 2]
        out[r, 0] = a0 * r00 + a1 * r01 + a2 * r02
        out[r, 1] = a0 * r10 + a1 * r11 + a2 * r12
        out[r, 2] = a0 * r20 + a1 * r21 + a2 * r22


@njit(cache=True, inline="always")
def _row_dot(A, i, B, j):
    return A[i, 0] * B[j, 0] + A[i, 1] * B[j, 1] + A[i, 2] * B[j, 2]


@njit(cache=True, inline="always")
def _clamp_couple(A, B, half_length, rest0, rest1, rest2, b0, b1, b2, g3, result):
    """Couple of a clamp spring between frames A and B (rows d1 d2 d3) over half an element.

    κ = log(A Bᵀ)/half_length in the material frame; result[0:3] = g3·B(κ − κ0) (the couple),
    result[3:6] = ½·half_length·κ × couple (the element's share of the κ × τ term), result[6]
    the energy, result[7] the cosine of the angle between the two frames.

    The share is half, as each side of an interior Voronoi domain takes ½·D0·κ × τ: it is what
    the spring's energy gives, −∂E/∂δ for a turn δ of the element being ∓c + ½·half_length·κ × c
    to first order in the clamp's angle (tests/test_naive_twin.py checks the misfit falls as
    its square). Until 2026-12-06 the element took the whole (half_length·κ × c), first-order
    wrong; the straight rod's onset moved by at most 1e-5 of itself with the fix (n = 40-160).
    """
    # R_ab = row a of A · row b of B, only the entries the log needs
    a0 = 0.5 * (_row_dot(A, 2, B, 1) - _row_dot(A, 1, B, 2))
    a1 = 0.5 * (_row_dot(A, 0, B, 2) - _row_dot(A, 2, B, 0))
    a2 = 0.5 * (_row_dot(A, 1, B, 0) - _row_dot(A, 0, B, 1))
    trace = _row_dot(A, 0, B, 0) + _row_dot(A, 1, B, 1) + _row_dot(A, 2, B, 2)
    result[7] = 0.5 * (trace - 1.0)
    factor = _log_factor(a0 * a0 + a1 * a1 + a2 * a2, result[7])
    k0 = a0 * factor / half_length
    k1 = a1 * factor / half_length
    k2 = a2 * factor / half_length
    m0 = b0 * (k0 - rest0)
    m1 = b1 * (k1 - rest1)
    m2 = b2 * (k2 - rest2)
    result[6] = 0.5 * (m0 * (k0 - rest0) + m1 * (k1 - rest1) + m2 * (k2 - rest2)) * half_length
    result[0] = g3 * m0
    result[1] = g3 * m1
    result[2] = g3 * m2
    lever = 0.5 * half_length
    result[3] = lever * (k1 * result[2] - k2 * result[1])
    result[4] = lever * (k2 * result[0] - k0 * result[2])
    result[5] = lever * (k0 * result[1] - k1 * result[0])


N_WORK = 13  # rows of the scratch array internal_loads needs, each of length n


@njit(cache=True, fastmath=_FASTMATH, inline="always")
def internal_loads(x, v, Q, w, rest_length, rest_voronoi, inertia, shear_stiffness,
                   bend_stiffness, rest_curvature, rest_shear, local_mask, incompressible,
                   f_shear, f_bend, f_inertia, f_twist, local_twist,
                   force, torque, dilatation, lengths, energies, work):
    """Internal forces on nodes and torques on elements (material frame), Gazzola 2018.

    force (3, n+1) and torque (3, n) are overwritten; energies[0:2] receive the stretch/shear
    and bend/twist energies (quadratic forms of the linear law), energies[2:4] the smallest
    cosine of the rotation between neighbouring frames and where; work is (N_WORK, n) scratch.
    The passes are split so that each loop is branch-free and writes only its own index,
    which lets LLVM vectorise them over the (3, n) layout.
    """
    n = rest_length.shape[0]
    inc = 1.0 if incompressible else 0.0  # branch-free switch of the 1/e, 1/e³ factors
    nl0, nl1, nl2 = work[0], work[1], work[2]  # element internal force, lab frame
    ka0, ka1, ka2 = work[3], work[4], work[5]  # half the skew part of R, then κ
    sin2 = work[6]
    cos_ = work[7]
    factor = work[8]
    c0, c1, c2 = work[9], work[10], work[11]  # couple / ε³ per Voronoi domain
    density = work[12]

    # elements: the internal force n = S(σ − σ0) of stretch and shear, the shear couple,
    # and the rigid-body rotation terms (Lagrangian transport, unsteady dilatation)
    for i in range(n):
        t0 = x[0, i + 1] - x[0, i]
        t1 = x[1, i + 1] - x[1, i]
        t2 = x[2, i + 1] - x[2, i]
        length = np.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
        inv_l0 = 1.0 / rest_length[i]
        e = length * inv_l0
        lengths[i] = length
        dilatation[i] = e
        qt0 = Q[0, 0, i] * t0 + Q[0, 1, i] * t1 + Q[0, 2, i] * t2
        qt1 = Q[1, 0, i] * t0 + Q[1, 1, i] * t1 + Q[1, 2, i] * t2
        qt2 = Q[2, 0, i] * t0 + Q[2, 1, i] * t1 + Q[2, 2, i] * t2
        s0 = qt0 * inv_l0 - rest_shear[0, i]
        s1 = qt1 * inv_l0 - rest_shear[1, i]
        s2 = qt2 * inv_l0 - 1.0 - rest_shear[2, i]
        n0 = f_shear * shear_stiffness[0, i] * s0
        n1 = f_shear * shear_stiffness[1, i] * s1
        n2 = f_shear * shear_stiffness[2, i] * s2
        density[i] = 0.5 * (n0 * s0 + n1 * s1 + n2 * s2) * rest_length[i]
        # incompressible: the force per current area carries 1/e (A = A0/e)
        g = 1.0 + inc * (1.0 / e - 1.0)
        nl0[i] = g * (Q[0, 0, i] * n0 + Q[1, 0, i] * n1 + Q[2, 0, i] * n2)
        nl1[i] = g * (Q[0, 1, i] * n0 + Q[1, 1, i] * n1 + Q[2, 1, i] * n2)
        nl2[i] = g * (Q[0, 2, i] * n0 + Q[1, 2, i] * n1 + Q[2, 2, i] * n2)
        # shear couple (Q t × n)·g: the moment of the internal force pair about the element;
        # Lagrangian transport (Jω/e) × ω and unsteady dilatation (Jω/e)·ė/e
        j0 = g * f_inertia * inertia[0, i] * w[0, i]
        j1 = g * f_inertia * inertia[1, i] * w[1, i]
        j2 = g * f_inertia * inertia[2, i] * w[2, i]
        edot = (t0 * (v[0, i + 1] - v[0, i]) + t1 * (v[1, i + 1] - v[1, i])
                + t2 * (v[2, i + 1] - v[2, i])) / (length * rest_length[i])
        h = inc * edot / e
        torque[0, i] = g * (qt1 * n2 - qt2 * n1) + j1 * w[2, i] - j2 * w[1, i] + j0 * h
        torque[1, i] = g * (qt2 * n0 - qt0 * n2) + j2 * w[0, i] - j0 * w[2, i] + j1 * h
        torque[2, i] = g * (qt0 * n1 - qt1 * n0) + j0 * w[1, i] - j1 * w[0, i] + j2 * h
    stretch_energy = 0.0
    for i in range(n):
        stretch_energy += density[i]

    # nodes: the difference of the element forces
    force[0, 0] = nl0[0]
    force[1, 0] = nl1[0]
    force[2, 0] = nl2[0]
    for i in range(1, n):
        force[0, i] = nl0[i] - nl0[i - 1]
        force[1, i] = nl1[i] - nl1[i - 1]
        force[2, i] = nl2[i] - nl2[i - 1]
    force[0, n] = -nl0[n - 1]
    force[1, n] = -nl1[n - 1]
    force[2, n] = -nl2[n - 1]

    # Voronoi domains: R = Q_j Q_{j+1}ᵀ, R_ab = d_a(j)·d_b(j+1); κ D0 = log R
    for j in range(n - 1):
        r01 = Q[0, 0, j] * Q[1, 0, j + 1] + Q[0, 1, j] * Q[1, 1, j + 1] + Q[0, 2, j] * Q[1, 2, j + 1]
        r10 = Q[1, 0, j] * Q[0, 0, j + 1] + Q[1, 1, j] * Q[0, 1, j + 1] + Q[1, 2, j] * Q[0, 2, j + 1]
        r02 = Q[0, 0, j] * Q[2, 0, j + 1] + Q[0, 1, j] * Q[2, 1, j + 1] + Q[0, 2, j] * Q[2, 2, j + 1]
        r20 = Q[2, 0, j] * Q[0, 0, j + 1] + Q[2, 1, j] * Q[0, 1, j + 1] + Q[2, 2, j] * Q[0, 2, j + 1]
        r12 = Q[1, 0, j] * Q[2, 0, j + 1] + Q[1, 1, j] * Q[2, 1, j + 1] + Q[1, 2, j] * Q[2, 2, j + 1]
        r21 = Q[2, 0, j] * Q[1, 0, j + 1] + Q[2, 1, j] * Q[1, 1, j + 1] + Q[2, 2, j] * Q[1, 2, j + 1]
        r00 = Q[0, 0, j] * Q[0, 0, j + 1] + Q[0, 1, j] * Q[0, 1, j + 1] + Q[0, 2, j] * Q[0, 2, j + 1]
        r11 = Q[1, 0, j] * Q[1, 0, j + 1] + Q[1, 1, j] * Q[1, 1, j + 1] + Q[1, 2, j] * Q[1, 2, j + 1]
        r22 = Q[2, 0, j] * Q[2, 0, j + 1] + Q[2, 1, j] * Q[2, 1, j + 1] + Q[2, 2, j] * Q[2, 2, j + 1]
        a0 = 0.5 * (r21 - r12)
        a1 = 0.5 * (r02 - r20)
        a2 = 0.5 * (r10 - r01)
        ka0[j] = a0
        ka1[j] = a1
        ka2[j] = a2
        sin2[j] = a0 * a0 + a1 * a1 + a2 * a2
        cos_[j] = 0.5 * (r00 + r11 + r22 - 1.0)
    worst_cos = 1.0
    worst_at = -1
    for j in range(n - 1):
        factor[j] = _log_factor(sin2[j], cos_[j])  # the one branchy loop, kept short
        if cos_[j] < worst_cos:
            worst_cos = cos_[j]
            worst_at = j
    energies[2] = worst_cos
    energies[3] = worst_at
    bend_energy = 0.0
    for j in range(n - 1):
        f = factor[j] / rest_voronoi[j]
        k0 = ka0[j] * f
        k1 = ka1[j] * f
        k2 = ka2[j] * f
        d0 = k0 - rest_curvature[0, j]
        d1 = k1 - rest_curvature[1, j]
        d2 = k2 - (f_twist * rest_curvature[2, j] + local_mask[j] * local_twist)
        m0 = f_bend * bend_stiffness[0, j] * d0
        m1 = f_bend * bend_stiffness[1, j] * d1
        m2 = f_bend * bend_stiffness[2, j] * d2
        bend_energy += 0.5 * (m0 * d0 + m1 * d1 + m2 * d2) * rest_voronoi[j]
        eps = 0.5 * (lengths[j] + lengths[j + 1]) / rest_voronoi[j]
        g3 = 1.0 + inc * (1.0 / (eps * eps * eps) - 1.0)
        c0[j] = g3 * m0
        c1[j] = g3 * m1
        c2[j] = g3 * m2
        ka0[j] = k0
        ka1[j] = k1
        ka2[j] = k2
    # elements: the bend-twist couple, the difference of the Voronoi couples B(κ − κ0)/ε³,
    # plus κ × τ·D0/ε³ split between both sides
    # (with the full curvature κ, not κ − κ0)
    for i in range(n):
        acc0 = 0.0
        acc1 = 0.0
        acc2 = 0.0
        if i < n - 1:
            h = 0.5 * rest_voronoi[i]
            acc0 += c0[i] + h * (ka1[i] * c2[i] - ka2[i] * c1[i])
            acc1 += c1[i] + h * (ka2[i] * c0[i] - ka0[i] * c2[i])
            acc2 += c2[i] + h * (ka0[i] * c1[i] - ka1[i] * c0[i])
        if i > 0:
            j = i - 1
            h = 0.5 * rest_voronoi[j]
            acc0 += h * (ka1[j] * c2[j] - ka2[j] * c1[j]) - c0[j]
            acc1 += h * (ka2[j] * c0[j] - ka0[j] * c2[j]) - c1[j]
            acc2 += h * (ka0[j] * c1[j] - ka1[j] * c0[j]) - c2[j]
        torque[0, i] += acc0
        torque[1, i] += acc1
        torque[2, i] += acc2
    energies[0] = stretch_energy
    energies[1] = bend_energy


@njit(cache=True, fastmath=_FASTMATH, inline="always")
def _radii(rest_radius, dilatation, f_radius, incompressible, radius):
    for i in range(rest_radius.shape[0]):
        if incompressible:
            radius[i] = f_radius * rest_radius[i] / np.sqrt(dilatation[i])
        else:
            radius[i] = f_radius * rest_radius[i]


@njit(cache=True, inline="always")
def _apply_held(x, v, ends, displacement, displacement_rate):
    """Overwrite held node positions and velocities: prescribed motions are exact."""
    n = x.shape[1] - 1
    for c in range(3):
        if ends.start_held[c]:
            x[c, 0] = ends.start_position[c]
            v[c, 0] = 0.0
        if ends.end_held[c]:
            x[c, n] = ends.end_position[c] + displacement * ends.axis[c]
            v[c, n] = displacement_rate * ends.axis[c]


@njit(cache=True, inline="always")
def _drag_factors(nu_dt):
    """(e^{−x}, (1 − e^{−x})/x) for x = ν·dt, with the series near 0."""
    if nu_dt < 1e-6:
        return 1.0 - nu_dt, 1.0 - 0.5 * nu_dt
    decay = np.exp(-nu_dt)
    return decay, (1.0 - decay) / nu_dt


@njit(cache=True, inline="always")
def _hold_velocities(v, ends, displacement_rate):
    n = v.shape[1] - 1
    for c in range(3):
        if ends.start_held[c]:
            v[c, 0] = 0.0
        if ends.end_held[c]:
            v[c, n] = displacement_rate * ends.axis[c]


# The pieces of one step, in the order advance composes them: controls -> loads (internal,
# clamps, contact, external) -> kick -> guards -> record -> drift -> settle/equilibrium.
# Each is inlined into advance but for the six check-step pieces the module docstring names; a
# piece that can trip a guard returns the status code and advance stops on anything but
# S_COMPLETED.

ControlValues = namedtuple("ControlValues", [
    "end_rotation", "start_rotation", "displacement", "displacement_rate", "end_force",
    "stiffness", "radius", "local_twist", "local_pull"])


@njit(cache=True, fastmath=_FASTMATH, inline="always")
def _controls(tables, t, now):
    """The controls at time t (positions live at half steps: advance passes t + dt/2); now
    (N_TABLES,) is a work buffer."""
    table_t = tables.times
    table_v = tables.values
    table_n = tables.counts
    # one interpolation site in a loop, not one per table: every inlined call is IR that
    # numba types and lowers again (the seven sites saved 4-5 s of the first compile)
    for row in range(N_TABLES):
        now[row] = table_value(table_t[row], table_v[row], table_n[row], t)
    return ControlValues(
        now[T_END_ROTATION], now[T_START_ROTATION], now[T_END_DISPLACEMENT],
        table_slope(table_t[T_END_DISPLACEMENT], table_v[T_END_DISPLACEMENT], table_n[T_END_DISPLACEMENT], t),
        now[T_END_FORCE], now[T_STIFFNESS], now[T_RADIUS], now[T_LOCAL_TWIST], now[T_LOCAL_PULL])


@njit(cache=True, fastmath=_FASTMATH, inline="always")
def _start_clamp_couple(Q, rod, frame, axis, rotation, dilatation, f_radius_inv, fb,
                        incompressible, torque, energies, clamp, couple):
    """Bend-twist couple of the start clamp's spring on element 0; couple[7] is the cosine of
    the angle between the clamp and the element's frame (the clamp-lag guard)."""
    rest_length = rod.rest_length
    rest_curvature = rod.rest_curvature
    bend_stiffness = rod.bend_stiffness
    rotated_frame(frame, axis, rotation, clamp)
    e0 = dilatation[0]
    _clamp_couple(clamp, Q[:, :, 0], 0.5 * rest_length[0], rest_curvature[0, 0],
                  rest_curvature[1, 0], f_radius_inv * rest_curvature[2, 0],
                  fb * bend_stiffness[0, 0], fb * bend_stiffness[1, 0], fb * bend_stiffness[2, 0],
                  1.0 / (e0 * e0 * e0) if incompressible else 1.0, couple)
    for c in range(3):
        torque[c, 0] += couple[3 + c] - couple[c]
    energies[1] += couple[6]


@njit(cache=True, fastmath=_FASTMATH, inline="always")
def _end_clamp_couple(Q, rod, frame, axis, rotation, dilatation, f_radius_inv, fb,
                      incompressible, torque, energies, clamp, couple):
    """Bend-twist couple of the end clamp's spring on element n-1; returns the axial torque
    the clamp exerts on it. couple[7] as for the start clamp."""
    n = rod.rest_length.shape[0]
    rest_length = rod.rest_length
    rest_curvature = rod.rest_curvature
    bend_stiffness = rod.bend_stiffness
    clamp_torque = 0.0
    rotated_frame(frame, axis, rotation, clamp)
    e1 = dilatation[n - 1]
    _clamp_couple(Q[:, :, n - 1], clamp, 0.5 * rest_length[n - 1], rest_curvature[0, n - 2],
                  rest_curvature[1, n - 2], f_radius_inv * rest_curvature[2, n - 2],
                  fb * bend_stiffness[0, n - 2], fb * bend_stiffness[1, n - 2],
                  fb * bend_stiffness[2, n - 2], 1.0 / (e1 * e1 * e1) if incompressible else 1.0,
                  couple)
    for c in range(3):
        torque[c, n - 1] += couple[c] + couple[3 + c]
        clamp_torque += (Q[0, c, n - 1] * couple[0] + Q[1, c, n - 1] * couple[1]
                         + Q[2, c, n - 1] * couple[2]) * axis[c]
    energies[1] += couple[6]
    return clamp_torque


@njit(cache=True, fastmath=_FASTMATH, inline="always")
def _contact_loads(x, v, rod, ends, settings, axis, dilatation, lengths, f_radius, f_stiff,
                   radius, x_build, x_near, radius_near, pairs, near, state, force, dashpots,
                   contact_work, fold_reach, fold_next):
    """Self-contact and contact with the end bodies: penalty forces added to `force`.

    Two-level Verlet list: `pairs` (grid search, midpoint cutoff with a skin) is rebuilt when
    a node has moved skin/4 since x_build; `near` (the pairs of it within near_margin of
    touching) when gaps could have closed by near_margin since x_near / radius_near.
    The margin adapts to how fast the rod moves (see below), between near_skin and skin/2.
    With settings.implicit_dashpot the dashpots are noted in `dashpots` (regrown with the
    lists) for apply_dashpots after the kick instead of entering `force`. With settings.fold
    the nodes inside the exclusion are kept from folding through each other (fold_forces,
    work buffers fold_reach and fold_next).
    state is the lists' ContactState. Returns (pairs, near, the dashpot buffer, the new
    ContactState, touching pairs, largest overlap / radius, its element, contact energy,
    dashpots noted in the buffer).
    """
    (n_pairs, n_near, radius_cut, rebuilds, near_rebuilds, max_pairs, near_margin,
     near_age) = state
    n = lengths.shape[0]
    incompressible = settings.incompressible
    exclusion = settings.exclusion
    skin = settings.skin
    near_skin = settings.near_skin
    contact_k = rod.contact_k
    contact_c = rod.contact_c
    _radii(rod.rest_radius, dilatation, f_radius, incompressible, radius)
    moved = 0.0
    moved_near = 0.0
    for i in range(n + 1):
        d0 = x[0, i] - x_build[0, i]
        d1 = x[1, i] - x_build[1, i]
        d2 = x[2, i] - x_build[2, i]
        moved = max(moved, d0 * d0 + d1 * d1 + d2 * d2)
        d0 = x[0, i] - x_near[0, i]
        d1 = x[1, i] - x_near[1, i]
        d2 = x[2, i] - x_near[2, i]
        moved_near = max(moved_near, d0 * d0 + d1 * d1 + d2 * d2)
    grown = 0.0
    widest = 0.0
    for i in range(n):
        grown = max(grown, radius[i] - radius_near[i])
        widest = max(widest, radius[i])
    # A pair outside the long list needs its gap to shrink by > skin: midpoints and
    # half-lengths each move by at most the largest node displacement, so 4·moved.
    if rebuilds == 0 or 16.0 * moved > skin * skin or widest > radius_cut:
        longest = 0.0
        for i in range(n):
            longest = max(longest, lengths[i])
        radius_cut = 1.1 * widest
        pairs, n_pairs = build_pairs(x, exclusion, 2.0 * radius_cut + longest + skin, pairs)
        if near.shape[1] < pairs.shape[1]:
            near = np.empty((2, pairs.shape[1]), dtype=np.int64)
        if settings.implicit_dashpot and dashpots.shape[1] < near.shape[1] + 2 * (n + 1):
            dashpots = np.empty((DASHPOT_ROWS, near.shape[1] + 2 * (n + 1)))
        # copies element by element here and below: an array-to-slice assignment makes numba
        # compile the formatting of its shape-mismatch error, ~3 s of the first compile
        for c in range(3):
            for i in range(n + 1):
                x_build[c, i] = x[c, i]
        rebuilds += 1
        max_pairs = max(max_pairs, n_pairs)
        moved_near = np.inf
    # A gap changes by at most the two segments' largest node displacements plus the
    # growth of the two radii (closest_parameters' fallback for segments parallel to
    # 1e-6 rad adds up to 1e-6 of an element length: negligible against the margin).
    # With the margin at skin/2 this never fires between grid builds: the old, one-list
    # behaviour.
    near_age += 1
    if 2.0 * (np.sqrt(moved_near) + grown) >= near_margin:
        # The margin trades the rebuild (a pass over every candidate pair) against the force
        # loop (a pass over the near pairs): a rod that closes the margin within a few steps
        # rebuilds almost every step, so the margin doubles; one that keeps its list for
        # long halves it back towards near_skin. Forces are unchanged by the margin: only
        # touching pairs add force and they enter the near list in candidate-list order
        # whatever its margin, so the sums run in the same order (positions bit-identical).
        if moved_near != np.inf:  # a rebuild for motion, not for a new candidate list
            if near_age < 8:
                near_margin = min(2.0 * near_margin, 0.5 * skin)
            elif near_age > 64:
                near_margin = max(0.5 * near_margin, near_skin)
        n_near = near_pairs(x, radius, pairs, n_pairs, near_margin, near)
        for c in range(3):
            for i in range(n + 1):
                x_near[c, i] = x[c, i]
        for i in range(n):
            radius_near[i] = radius[i]
        near_rebuilds += 1
        near_age = 0
    implicit = settings.implicit_dashpot
    touching, worst, worst_at, contact_energy, noted = 0, 0.0, -1, 0.0, 0
    if n_near > 0:  # a rod far from itself (e.g. straight) skips the per-element pass too
        touching, worst, worst_at, contact_energy, noted = contact_forces_in(
            x, v, radius, near, n_near, contact_k, contact_c, f_stiff, settings.friction,
            settings.slip_speed, 1.0 if incompressible and settings.thinning_force else 0.0,
            force, dashpots, implicit,
            contact_work[:3], contact_work[3], contact_work[4])
    if settings.fold:
        fold_touching, fold_worst, fold_at, fold_energy = fold_forces(
            x, radius, lengths, rod.rest_length, exclusion, contact_k, f_stiff, fold_reach,
            fold_next, force)
        touching += fold_touching
        contact_energy += fold_energy
        if fold_worst > worst:
            worst, worst_at = fold_worst, fold_at
    # The bodies the held ends are fixed to (a loading rod, the clamp's holder): no
    # strand can pass around such an end, so link leaves only where the scene lets it.
    for which in range(2):  # 0: the start's body, beyond node 0; 1: the end's
        if (ends.end_body if which == 1 else ends.start_body):
            body_touching, body_worst, body_energy, noted = add_body_forces(
                x, v, radius, contact_k, contact_c, f_stiff, which * n,
                2.0 * which - 1.0, axis, ends.body_radius, exclusion, force, dashpots, noted,
                implicit)
            touching += body_touching
            contact_energy += body_energy
            if body_worst > worst:
                worst, worst_at = body_worst, which * (n - 1)
    state = ContactState(n_pairs, n_near, radius_cut, rebuilds, near_rebuilds, max_pairs,
                         near_margin, near_age)
    return (pairs, near, dashpots, state, touching, worst, worst_at, contact_energy, noted)


@njit(cache=True, fastmath=_FASTMATH, inline="always")
def _external_loads(x, node_mass, r2, end_force, force_dir, gravity, local_pull, seg_first,
                    seg_last, force):
    """End force, gravity and the active agent's pull, added to `force`."""
    n = x.shape[1] - 1
    for c in range(3):
        force[c, n] += end_force * force_dir[c]
    if gravity[0] != 0.0 or gravity[1] != 0.0 or gravity[2] != 0.0:
        for c in range(3):
            for i in range(n + 1):
                force[c, i] += node_mass[i] * r2 * gravity[c]
    if local_pull != 0.0 and seg_last > seg_first:
        d0 = x[0, seg_last] - x[0, seg_first]
        d1 = x[1, seg_last] - x[1, seg_first]
        d2 = x[2, seg_last] - x[2, seg_first]
        dn = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        if dn > 0.0:
            p = local_pull / dn
            force[0, seg_first] += p * d0
            force[1, seg_first] += p * d1
            force[2, seg_first] += p * d2
            force[0, seg_last] -= p * d0
            force[1, seg_last] -= p * d1
            force[2, seg_last] -= p * d2


@njit(cache=True, fastmath=_FASTMATH, inline="always")
def _kinetic_energy(v, w, node_mass, inertia, r2):
    n = w.shape[1]
    kinetic = 0.0
    for i in range(n + 1):
        kinetic += 0.5 * node_mass[i] * r2 * (v[0, i] ** 2 + v[1, i] ** 2 + v[2, i] ** 2)
    for i in range(n):
        for c in range(3):
            kinetic += 0.5 * inertia[c, i] * r2 * r2 * w[c, i] * w[c, i]
    return kinetic


@njit(cache=True, fastmath=_FASTMATH, inline="always")
def _kick(v, w, force, torque, dilatation, inv_mass, inv_inertia, r2, dt, decay, gain,
          decay_rotation, gain_rotation, incompressible, quadratic_drag, drag_radius):
    """Velocities from the loads over a step, with the linear drag integrated exactly; the
    angular momentum balance carries the dilatation factor e of an incompressible rod."""
    n = w.shape[1]
    for c in range(3):
        for i in range(n + 1):
            v[c, i] = v[c, i] * decay + gain * dt * force[c, i] * inv_mass[i] / r2
    for c in range(3):
        for i in range(n):
            gi = dilatation[i] if incompressible else 1.0
            w[c, i] = (w[c, i] * decay_rotation[c]
                       + gain_rotation[c] * dt * gi * torque[c, i] * inv_inertia[c, i] / (r2 * r2))
    if quadratic_drag > 0.0:
        # Drag growing with speed (implicit, so stable at any speed): quasi-static motion
        # barely feels it, but a snap-through cannot turn stored twist into speeds that
        # no contact spring can stop. Equilibria do not depend on it.
        for i in range(n + 1):
            speed = np.sqrt(v[0, i] ** 2 + v[1, i] ** 2 + v[2, i] ** 2)
            f = 1.0 / (1.0 + quadratic_drag * speed * dt)
            v[0, i] *= f
            v[1, i] *= f
            v[2, i] *= f
        for i in range(n):
            spin = drag_radius * np.sqrt(w[0, i] ** 2 + w[1, i] ** 2 + w[2, i] ** 2)
            f = 1.0 / (1.0 + quadratic_drag * spin * dt)
            w[0, i] *= f
            w[1, i] *= f
            w[2, i] *= f


N_AXIAL_WORK = 8  # rows of the scratch array _axial_damping needs, each of length n


@njit(cache=True, fastmath=_FASTMATH, inline="always")
def _axial_damping(x, v, inv_mass, rest_length, axial_stiffness, f_axial, eta, dt,
                   incompressible, work):
    """Axial Kelvin–Voigt damping over a step, backward Euler: v is the kicked velocity.

    Element i carries a dashpot c_i = EA·η/l_i (η·EA·ė with ė = u_i/l0, per current area for
    an incompressible rod) on its axial relative velocity u_i = (v_{i+1} − v_i)·t_i, t_i its
    unit tangent. Its impulse p_i (pulling node i along +t_i, node i+1 along −t_i) taken
    with the velocities at the end of the step, p_i = c_i·dt·(u_i + Δu_i), is a scalar
    tridiagonal system along the rod (the tangents held at the half step):
        (1/(c_i·dt) + 1/m_i + 1/m_{i+1})·p_i − (t_{i−1}·t_i)/m_i·p_{i−1} − (t_i·t_{i+1})/m_{i+1}·p_{i+1} = u_i,
    symmetric and diagonally dominant, solved by one Thomas sweep forward and back (no
    pivoting needed). It damps a mode of frequency ω at the ratio ω·η/2 for any η·dt
    without a step limit. inv_mass (n+1,): 1/m as the kick uses it, 0 at held nodes.
    work: (N_AXIAL_WORK, n) scratch.
    """
    n = rest_length.shape[0]
    t0, t1, t2 = work[0], work[1], work[2]
    diag = work[3]
    rhs = work[4]
    coupling = work[5]  # between elements i and i+1
    impulse = work[6]
    for i in range(n):
        d0 = x[0, i + 1] - x[0, i]
        d1 = x[1, i + 1] - x[1, i]
        d2 = x[2, i + 1] - x[2, i]
        length = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        inv = 1.0 / length
        t0[i] = d0 * inv
        t1[i] = d1 * inv
        t2[i] = d2 * inv
        lever = length if incompressible else rest_length[i]
        # 1/(c_i·dt) with c_i = EA·η/lever
        diag[i] = lever / (f_axial * axial_stiffness[i] * eta * dt) + inv_mass[i] + inv_mass[i + 1]
        rhs[i] = ((v[0, i + 1] - v[0, i]) * t0[i] + (v[1, i + 1] - v[1, i]) * t1[i]
                  + (v[2, i + 1] - v[2, i]) * t2[i])
    for i in range(n - 1):
        coupling[i] = -(t0[i] * t0[i + 1] + t1[i] * t1[i + 1] + t2[i] * t2[i + 1]) * inv_mass[i + 1]
    # Thomas: eliminate below the diagonal, then substitute back
    for i in range(1, n):
        f = coupling[i - 1] / diag[i - 1]
        diag[i] -= f * coupling[i - 1]
        rhs[i] -= f * rhs[i - 1]
    impulse[n - 1] = rhs[n - 1] / diag[n - 1]
    for i in range(n - 2, -1, -1):
        impulse[i] = (rhs[i] - coupling[i] * impulse[i + 1]) / diag[i]
    # node i: its own element's impulse along +t_i, the previous one's along −t_{i−1}
    for i in range(n + 1):
        a = impulse[i] * inv_mass[i] if i < n else 0.0
        b = impulse[i - 1] * inv_mass[i] if i > 0 else 0.0
        v[0, i] += a * t0[min(i, n - 1)] - b * t0[max(i - 1, 0)]
        v[1, i] += a * t1[min(i, n - 1)] - b * t1[max(i - 1, 0)]
        v[2, i] += a * t2[min(i, n - 1)] - b * t2[max(i - 1, 0)]


@njit(cache=True, fastmath=_FASTMATH, inline="never")
def _guards(v, w, force, torque, ends, node_mass, inertia, rest_length, r2, speed_limit, info):
    """Residual (largest nodal force and element torque per length on free degrees of
    freedom), kinetic energy, and the non-finite and speed guards.
    Returns (status, residual [N], kinetic energy [J])."""
    n = w.shape[1]
    res = 0.0
    kin = 0.0
    for i in range(n + 1):
        fm = 0.0
        vv = 0.0
        for c in range(3):
            held = (i == 0 and ends.start_held[c] != 0) or (i == n and ends.end_held[c] != 0)
            if not held:
                fm += force[c, i] * force[c, i]
            vv += v[c, i] * v[c, i]
        res = max(res, np.sqrt(fm))
        kin += 0.5 * node_mass[i] * r2 * vv
        if not np.isfinite(vv) or not np.isfinite(fm):
            info[D_WHERE] = i
            info[D_VALUE] = vv
            return S_NAN, res, kin
        if vv > speed_limit * speed_limit:
            info[D_WHERE] = i
            info[D_VALUE] = np.sqrt(vv)
            return S_SPEED, res, kin
    for i in range(n):
        tm = 0.0
        for c in range(3):
            tm += torque[c, i] * torque[c, i]
            kin += 0.5 * inertia[c, i] * r2 * r2 * w[c, i] * w[c, i]
        res = max(res, np.sqrt(tm) / rest_length[i])
    if not np.isfinite(kin) or not np.isfinite(res):
        info[D_WHERE] = -1
        info[D_VALUE] = kin
        return S_NAN, res, kin
    return S_COMPLETED, res, kin


@njit(cache=True, fastmath=_FASTMATH, inline="never")
def _shear_guard(x, Q, info):
    """S_SHEAR if an element's d3 is more than 45° off its tangent (info: where, the angle
    in rad), else S_COMPLETED. Checked with the other guards, every check_every steps."""
    n = Q.shape[2]
    for i in range(n):
        t0 = x[0, i + 1] - x[0, i]
        t1 = x[1, i + 1] - x[1, i]
        t2 = x[2, i + 1] - x[2, i]
        along = Q[2, 0, i] * t0 + Q[2, 1, i] * t1 + Q[2, 2, i] * t2
        # d3·t/|t| < cos 45°, without the root (a reversed element fails it too)
        if along < 0.0 or along * along < COS_MAX_SHEAR * COS_MAX_SHEAR * (
                t0 * t0 + t1 * t1 + t2 * t2):
            info[D_WHERE] = i
            info[D_VALUE] = np.arccos(min(max(along / np.sqrt(t0 * t0 + t1 * t1 + t2 * t2),
                                              -1.0), 1.0))
            return S_SHEAR
    return S_COMPLETED


@njit(cache=True, fastmath=_FASTMATH, inline="never")
def _record(row, x, v, Q, w, force, dt, t_next, end_force, force_dir, axis, end_position,
            tables, clamp_torque, energies, kinetic, touching, worst, residual, f_stiff,
            f_radius, contact_energy, out):
    """One history row and snapshot, at t + dt (positions are at t + dt/2 inside the loop)."""
    n = x.shape[1] - 1
    history = out.history
    snap_x = out.snap_x
    snap_d1 = out.snap_d1
    table_t = tables.times
    table_v = tables.values
    table_n = tables.counts
    # positions are at t + dt/2; bring the recorded ones to t + dt
    for c in range(3):
        for i in range(n + 1):
            snap_x[row, c, i] = x[c, i] + 0.5 * dt * v[c, i]
    Qs = Q.copy()
    rotate_frames(Qs, w, 0.5 * dt)
    for c in range(3):
        for i in range(n):
            snap_d1[row, c, i] = Qs[0, c, i]
    # axial force the outside exerts on node n: minus the rod's force on it
    rod_on_end = 0.0
    for c in range(3):
        rod_on_end += (force[c, n] - end_force * force_dir[c]) * axis[c]
    end_disp = 0.0
    for c in range(3):
        end_disp += (snap_x[row, c, n] - end_position[c]) * axis[c]
    history[row, H_TIME] = t_next
    history[row, H_END_ROTATION] = table_value(table_t[T_END_ROTATION], table_v[T_END_ROTATION],
                                               table_n[T_END_ROTATION], t_next)
    history[row, H_END_FORCE] = -rod_on_end
    history[row, H_END_TORQUE] = clamp_torque
    history[row, H_END_DISPLACEMENT] = end_disp
    history[row, H_APPLIED_FORCE] = end_force
    history[row, H_STRETCH_ENERGY] = energies[0]
    history[row, H_BEND_ENERGY] = energies[1]
    history[row, H_KINETIC_ENERGY] = kinetic
    history[row, H_CONTACTS] = touching
    history[row, H_PENETRATION] = worst
    history[row, H_RESIDUAL] = residual
    history[row, H_STIFFNESS] = f_stiff
    history[row, H_RADIUS_FACTOR] = f_radius
    history[row, H_CONTACT_ENERGY] = contact_energy
    history[row, H_START_ROTATION] = table_value(
        table_t[T_START_ROTATION], table_v[T_START_ROTATION], table_n[T_START_ROTATION], t_next)


@njit(cache=True, fastmath=_FASTMATH, inline="always")
def _drift(x, v, Q, w, h):
    """Positions and frames moved by the velocities over h."""
    n = w.shape[1]
    for c in range(3):
        for i in range(n + 1):
            x[c, i] += h * v[c, i]
    rotate_frames(Q, w, h)


@njit(cache=True, fastmath=_FASTMATH, inline="never")
def _settle_windows(x, Q, t, drag_radius, settle_window, settle_distance, equilibrium_after,
                    window_sum, window_squares, window_mean, window_count, window_start,
                    have_mean, settle_motion, settled):
    """Window means of node positions and of d1 (times the radius: a surface point), summed
    at every check; the shape has settled when two consecutive window means agree and within
    the window no point strayed from its mean (rms) by more than the same distance.
    Averaging is what lets a hold end under contact: there a standing vibration (~390 Hz,
    amplitude ~0.2 % of the radius, see docs/history/holds-and-laws.md) keeps the residual above any
    useful tolerance although the shape no longer changes. The spread test keeps a slow,
    large oscillation whose period matches the window from passing as settled.
    Returns (window_count, window_start, have_mean, settle_motion, settled)."""
    n = Q.shape[2]
    if t < equilibrium_after:
        window_start = t  # controls still moving: windows start when they stop
        return window_count, window_start, have_mean, settle_motion, settled
    for c in range(3):
        for i in range(n + 1):
            window_sum[c, i] += x[c, i]
            window_squares[c, i] += x[c, i] * x[c, i]
        for i in range(n):
            surface = drag_radius * Q[0, c, i]
            window_sum[3 + c, i] += surface
            window_squares[3 + c, i] += surface * surface
    window_count += 1
    if t - window_start >= settle_window:
        motion = 0.0
        spread = 0.0
        for i in range(n + 1):
            dx = 0.0
            dd = 0.0
            vx = 0.0
            vd = 0.0
            for c in range(3):
                mean = window_sum[c, i] / window_count
                dx += (mean - window_mean[c, i]) ** 2
                vx += window_squares[c, i] / window_count - mean * mean
                window_mean[c, i] = mean
                mean = window_sum[3 + c, i] / window_count
                dd += (mean - window_mean[3 + c, i]) ** 2
                vd += window_squares[3 + c, i] / window_count - mean * mean
                window_mean[3 + c, i] = mean
            motion = max(motion, np.sqrt(dx) + np.sqrt(dd))
            spread = max(spread, np.sqrt(max(vx, 0.0)) + np.sqrt(max(vd, 0.0)))
        if have_mean:
            settle_motion = max(motion, spread)
            settled = settle_motion < settle_distance
        have_mean = True
        window_sum[:, :] = 0.0
        window_squares[:, :] = 0.0
        window_count = 0
        window_start = t
    return window_count, window_start, have_mean, settle_motion, settled


@njit(cache=True, fastmath=_FASTMATH, inline="never")
def _probe_distance(x, probe_reference, probe_shape, probe_size, probe_norm2):
    """(largest node distance from the probed candidate, the probe's remaining component
    along its shape as a fraction of the probe)."""
    n = x.shape[1] - 1
    away = 0.0
    along = 0.0
    for i in range(n + 1):
        d0 = x[0, i] - probe_reference[0, i]
        d1 = x[1, i] - probe_reference[1, i]
        d2 = x[2, i] - probe_reference[2, i]
        away = max(away, d0 * d0 + d1 * d1 + d2 * d2)
        along += d0 * probe_shape[0, i] + d1 * probe_shape[1, i] + d2 * probe_shape[2, i]
    away = np.sqrt(away)
    along = abs(along) / (probe_size * probe_norm2)
    return away, along


@njit(cache=True, fastmath=_FASTMATH, inline="never")
def _start_probe(x, probe_reference, probe_shape, probe_size):
    """Displace the candidate equilibrium by probe_size along probe_shape."""
    n = x.shape[1] - 1
    for c in range(3):
        for i in range(n + 1):
            probe_reference[c, i] = x[c, i]
    for c in range(3):
        for i in range(n + 1):
            x[c, i] += probe_size * probe_shape[c, i]


@njit(cache=True, fastmath=_FASTMATH, inline="never")
def _stop_test(x, t, at_rest, touching, settings, probe_shape, probe_norm2, probe_reference,
               probe_running, probes, probes_left, window_sum, window_squares, window_count,
               window_start, have_mean, settled):
    """Does the hold end here, at a stable equilibrium? Called at check steps of a hold past
    settings.equilibrium_after; at_rest says the rod passes the equilibrium test (settled
    shape, or residual and kinetic energy below the tolerance).

    Stability probe: a residual test cannot tell a stable equilibrium from an unstable one
    (a straight twisted rod above its onset is in equilibrium too). A candidate is displaced
    by settings.probe_size along probe_shape (its squared norm probe_norm2); it is stable if
    the displacement along that shape decays below probe_return of the probe and the rod
    passes the equilibrium test there, unstable if it grows beyond probe_leave probes (or any
    node moves that many probe sizes away): the test then resumes and the next candidate is
    probed in turn. Undecided, the hold runs to its time limit: `not_converged`.
    Candidates in self-contact are accepted unprobed: damped dynamics from a generic state
    ends on an unstable equilibrium only where symmetry keeps the unstable mode unexcited
    (the straight rod, a flat loop) and no contact confines it; a coil or braid in contact
    creeps by more than a probe's return distance while its shape is settled.

    Starting a probe displaces x and restarts the settle windows (window_sum, window_squares
    in place). Returns (accept, probe_running, probes, probes_left, window_count,
    window_start, have_mean, settled)."""
    accept = at_rest
    if settings.probe:
        accept = False
        probe_size = settings.probe_size
        if probe_running:
            # how much of the probe is left (its projection on the probe shape; an error of
            # the candidate along other directions, e.g. the axial stretch still settling to
            # the tolerance, does not count) and how far the rod went
            away, along = _probe_distance(x, probe_reference, probe_shape, probe_size,
                                          probe_norm2)
            leave = settings.probe_leave
            if away > leave * probe_size or along > leave:
                probe_running = False
                probes_left += 1
            elif at_rest and along < settings.probe_return:
                accept = True
        elif at_rest and touching > 0:
            accept = True  # held by contact: see above
        elif at_rest:
            _start_probe(x, probe_reference, probe_shape, probe_size)
            probe_running = True
            probes += 1
            # the shape test starts afresh: the windows before the probe say nothing
            window_sum[:, :] = 0.0
            window_squares[:, :] = 0.0
            window_count = np.int64(0)
            window_start = t
            have_mean = np.bool_(False)
            settled = np.bool_(False)
    return (accept, probe_running, probes, probes_left, window_count, window_start, have_mean,
            settled)


@njit(cache=True, fastmath=_FASTMATH, inline="never")
def _work_arrays(x, rod, ends, settings, probe_shape):
    """Arrays `advance` works in, made once per call (compiled on its own: it runs once):
    contact's two-level Verlet list (_contact_loads) x_build, pairs, x_near, radius_near,
    near; the contact loop's per-element buffers (segment vectors, 1/|u|², thinning lever)
    contact_work, fold_reach, fold_next; dashpots, the contact dashpots taken implicitly after
    the kick (contact.apply_dashpots; none without settings.implicit_dashpot and contact); the
    settled-shape test's window sums (_settle_windows: node positions and d1 times the radius,
    (6, n+1) each); the probe's reference state and the squared norm of its shape. The
    arrays of the per-step loads and the kick come from _step_arrays, inlined into advance
    (the module docstring says why).
    """
    n = rod.rest_length.shape[0]
    x_build = x.copy()
    pairs = np.empty((2, 16 * n + 64), dtype=np.int64)
    x_near = x.copy()
    radius_near = rod.rest_radius.copy()
    near = np.empty((2, pairs.shape[1]), dtype=np.int64)
    contact_work = np.empty((5, n))
    fold_reach = np.empty(settings.exclusion + 1)
    fold_next = np.empty(n + 1, dtype=np.int64)
    implicit_dashpot = settings.contact and settings.implicit_dashpot
    dashpots = np.empty((DASHPOT_ROWS, near.shape[1] + 2 * (n + 1) if implicit_dashpot else 0))
    window_sum = np.zeros((6, n + 1))
    window_squares = np.zeros((6, n + 1))
    window_mean = np.zeros((6, n + 1))
    probe_reference = x.copy()
    probe_norm2 = 0.0
    for c in range(3):
        for i in range(n + 1):
            probe_norm2 += probe_shape[c, i] * probe_shape[c, i]
    return (x_build, pairs, x_near, radius_near, near, contact_work, fold_reach, fold_next,
            dashpots, window_sum, window_squares, window_mean, probe_reference, probe_norm2)


@njit(cache=True, fastmath=_FASTMATH, inline="always")
def _step_arrays(rod, ends):
    """The arrays the per-step loads and the kick work in, 1/m and 1/J. Inlined, so that they
    are advance's own fresh allocations to LLVM (the module docstring says why). free_inv_mass
    is 1/m of the free nodes as the kick scales it, for the stiff dissipative terms taken
    implicitly after the kick (_axial_damping, contact.apply_dashpots): 0 at a node held in
    all three components, whose impulse then goes to its partner (a held node's infinite
    mass); kick_inv_mass is its scaled copy, filled at each step. Last, the clamp frame and
    couple (the clamp couples) and the controls' buffer (_controls)."""
    n = rod.rest_length.shape[0]
    force = np.zeros((3, n + 1))
    torque = np.zeros((3, n))
    dilatation = np.ones(n)
    lengths = rod.rest_length.copy()
    radius = rod.rest_radius.copy()
    energies = np.zeros(4)
    work = np.zeros((max(N_WORK, N_WORK_NEO_HOOKEAN), n))
    inv_mass = 1.0 / rod.node_mass
    inv_inertia = 1.0 / rod.inertia
    free_inv_mass = inv_mass.copy()
    for i in (0, n):
        held = ends.start_held if i == 0 else ends.end_held
        if held[0] != 0 and held[1] != 0 and held[2] != 0:
            free_inv_mass[i] = 0.0
    kick_inv_mass = free_inv_mass.copy()
    axial_work = np.zeros((N_AXIAL_WORK, n))
    return (force, torque, dilatation, lengths, radius, energies, work, inv_mass, inv_inertia,
            free_inv_mass, kick_inv_mass, axial_work, np.empty((3, 3)), np.empty(8),
            np.empty(N_TABLES))


@njit(cache=True, fastmath=_FASTMATH, inline="always")
def _drag_rates(settings):
    """Linear drag integrated exactly over a step (integrating factor): v' = a − νv gives
    v ← v·e^{−νdt} + a·dt·(1 − e^{−νdt})/(νdt). Stable for any ν, and right in the
    overdamped limit νdt ≫ 1 (velocity a/ν), where multiplying by e^{−νdt} alone stalls.
    Returns (decay, gain) of the velocities and (3,) arrays of them per material axis of the
    spin (half the rotational damping about d3)."""
    dt = settings.dt
    decay, gain = _drag_factors(settings.damping * dt)
    decay_rotation = np.empty(3)
    gain_rotation = np.empty(3)
    decay_rotation[0], gain_rotation[0] = _drag_factors(settings.damping_rotation * dt)
    decay_rotation[1], gain_rotation[1] = decay_rotation[0], gain_rotation[0]
    decay_rotation[2], gain_rotation[2] = _drag_factors(0.5 * settings.damping_rotation * dt)
    return decay, gain, decay_rotation, gain_rotation


@njit(cache=True, inline="never")
def _report(info, max_penetration, rebuilds, max_pairs, residual, kinetic, settle_motion,
            near_rebuilds, probes, probes_left):
    """The run's counters into out.info (D_* slots), at the end of advance."""
    info[D_MAX_PENETRATION] = max_penetration
    info[D_REBUILDS] = rebuilds
    info[D_MAX_PAIRS] = max_pairs
    info[D_RESIDUAL] = residual
    info[D_KINETIC] = kinetic
    info[D_SETTLE_MOTION] = settle_motion
    info[D_NEAR_REBUILDS] = near_rebuilds
    info[D_PROBES] = probes
    info[D_PROBES_LEFT] = probes_left


@njit(cache=True, fastmath=_FASTMATH)
def advance(x, v, Q, w, t_start, n_steps, rod, ends, settings, tables, probe_shape, out,
            neo_hookean=None):
    """Advance the rod by up to n_steps steps of settings.dt from time t_start, in place.

    rod: RodProperties, ends: Boundary, settings: Settings, tables: ControlTables, out: Output.
    out.history (H, N_HISTORY), out.snap_x (H, 3, n+1) and out.snap_d1 (H, 3, n) receive a
    row every settings.history_every steps and at the end; H must be ≥ n_steps // every + 2.
    probe_shape (3, n+1), largest row norm 1 and zero on held components, is the direction of
    the stability probe (settings.probe): a candidate equilibrium of a hold is displaced by
    settings.probe_size along it, and the hold ends only once that displacement has decayed.
    Returns (status, steps_taken, t_end, rows_written); out.info (N_INFO,) gets diagnostics.
    With contact asleep (settings.sleep, settings.contact off) the status S_WAKE says the rod
    touched itself (or an end body) at t_end: the caller goes on from there with contact on.

    A step composes the pieces above: controls at the half step -> loads (internal_loads,
    the clamp couples, contact, external loads) -> kick -> guards -> record -> drift -> the
    settled-shape windows and the equilibrium test (with the stability probe).

    neo_hookean: None (left out) for the paper's law (internal_loads, the clamp couples, the
    1/e and 1/e³ factors); anything else for the conservative law of neo_hookean.py. The
    choice is by type, so numba prunes the other law's branches before typing: each law is
    its own specialization, and the paper law's is the code from before the option (its
    results bit-identical: benchmarks/reference_positions.py --compare).
    """
    rest_length = rod.rest_length
    rest_voronoi = rod.rest_voronoi
    node_mass = rod.node_mass
    inertia = rod.inertia
    shear_stiffness = rod.shear_stiffness
    bend_stiffness = rod.bend_stiffness
    rest_curvature = rod.rest_curvature
    rest_shear = rod.rest_shear
    local_mask = rod.local_mask
    end_position = ends.end_position
    info = out.info
    n = rest_length.shape[0]
    dt = settings.dt
    incompressible = settings.incompressible
    contact_on = settings.contact
    # Sleeping contact (settings.sleep): contact is computed as awake, but at the first
    # touch (a pair, a fold or an end body) the loop returns S_WAKE before the forces act,
    # with the state at that step's start, and the caller goes on with contact on and its
    # time step. Before that the step is the larger one of a rod without contact.
    asleep = (not contact_on) and settings.sleep
    history_every = max(settings.history_every, 1)
    check_every = max(settings.check_every, 1)
    stop_at_equilibrium = settings.stop_at_equilibrium
    axis = ends.axis.copy()
    force_dir = ends.force_direction.copy()
    gravity = ends.gravity.copy()
    decay, gain, decay_rotation, gain_rotation = _drag_rates(settings)
    tolerance = settings.hold_tolerance
    force_scale = settings.force_scale
    equilibrium_after = settings.equilibrium_after
    quadratic_drag = settings.quadratic_drag
    drag_radius = settings.drag_radius
    settle_window = settings.settle_window
    (force, torque, dilatation, lengths, radius, energies, work, inv_mass, inv_inertia,
     free_inv_mass, kick_inv_mass, axial_work, clamp, couple, control_now) = _step_arrays(rod,
                                                                                          ends)
    (x_build, pairs, x_near, radius_near, near, contact_work, fold_reach, fold_next, dashpots,
     window_sum, window_squares, window_mean, probe_reference, probe_norm2) = _work_arrays(
        x, rod, ends, settings, probe_shape)
    # the running state of contact (_contact_loads), of the settled-shape windows and of the
    # probe (_settle_windows, _stop_test): typed int64 and bool from the start, as a literal
    # would have numba compile the callees that take them (not inlined) once more for its type
    settle_on = stop_at_equilibrium and settle_window > 0.0
    window_count, window_start, have_mean = np.int64(0), t_start, np.bool_(False)
    settle_motion, settled = np.inf, np.bool_(False)
    implicit_dashpot = contact_on and settings.implicit_dashpot
    noted = 0
    eta = settings.strain_rate_damping
    contact = ContactState(np.int64(0), np.int64(0), 0.0, np.int64(0), np.int64(0),
                           np.int64(0), settings.near_skin, np.int64(0))
    touching = 0
    max_penetration, worst, contact_energy = 0.0, 0.0, 0.0
    residual, kinetic, kinetic_before = np.inf, np.inf, 0.0
    probe_running, probes, probes_left = np.bool_(False), np.int64(0), np.int64(0)

    info[D_SETTLED] = 0.0
    t, steps, status = t_start, 0, S_COMPLETED
    rows = np.int64(0)  # int64 from the start, as window_count above (_record)

    # first half drift: positions to t + dt/2
    _drift(x, v, Q, w, 0.5 * dt)

    for step in range(n_steps):
        # controls at the half step, where the positions are
        u = _controls(tables, t + 0.5 * dt, control_now)
        _apply_held(x, v, ends, u.displacement, u.displacement_rate)

        # loads. Growth keeps the density: area ∝ r², second moments ∝ r⁴, rest twist ∝ 1/r
        # (a·κ3⁰ fixed).
        f_stiff = u.stiffness
        f_radius = u.radius
        r2 = f_radius * f_radius
        fb = f_stiff * r2 * r2
        f_radius_inv = 1.0 / f_radius
        if neo_hookean is None:
            internal_loads(x, v, Q, w, rest_length, rest_voronoi, inertia, shear_stiffness,
                           bend_stiffness, rest_curvature, rest_shear, local_mask, incompressible,
                           f_stiff * r2, fb, r2 * r2, f_radius_inv, u.local_twist,
                           force, torque, dilatation, lengths, energies, work)
        else:
            internal_loads_neo_hookean(x, v, Q, w, rest_length, rest_voronoi, inertia,
                                       shear_stiffness, bend_stiffness, rest_curvature,
                                       rest_shear, local_mask, f_stiff * r2, fb, r2 * r2,
                                       f_radius_inv, u.local_twist, force, torque, dilatation,
                                       lengths, energies, work, couple)
        if energies[2] < COS_MAX_TURN:
            # beyond 135° between neighbours the matrix log nears its branch cut at 180°,
            # where twist would silently wrap and link be lost: stop and say so
            status = S_RESOLUTION
            info[D_WHERE] = energies[3]
            info[D_VALUE] = np.arccos(max(energies[2], -1.0))
            break
        # Held frames are clamps at the rod's ends, half an element from the end elements'
        # centres: a bending/twisting spring over that half element (second order at the
        # boundary, and the twist put in spans the whole rest length L0).
        clamp_torque = 0.0
        if ends.start_frame_held:
            if neo_hookean is None:
                _start_clamp_couple(Q, rod, ends.start_frame, axis, u.start_rotation,
                                    dilatation, f_radius_inv, fb, incompressible, torque,
                                    energies, clamp, couple)
            else:
                rotated_frame(ends.start_frame, axis, u.start_rotation, clamp)
                couple[7] = clamp_couple_neo_hookean(
                    clamp, Q[:, :, 0], 0, x, rest_length, rest_curvature[0, 0],
                    rest_curvature[1, 0], f_radius_inv * rest_curvature[2, 0],
                    fb * bend_stiffness[0, 0], fb * bend_stiffness[1, 0],
                    fb * bend_stiffness[2, 0], False, torque, force, energies, couple)
            if couple[7] < COS_MAX_TURN:
                # the clamp spring's log would wrap past 180° and twist the rod the wrong way
                status = S_CLAMP_LAG
                info[D_WHERE] = 0
                info[D_VALUE] = np.arccos(max(couple[7], -1.0))
                break
        if ends.end_frame_held:
            if neo_hookean is None:
                clamp_torque = _end_clamp_couple(Q, rod, ends.end_frame, axis, u.end_rotation,
                                                 dilatation, f_radius_inv, fb, incompressible,
                                                 torque, energies, clamp, couple)
            else:
                rotated_frame(ends.end_frame, axis, u.end_rotation, clamp)
                cos_end = clamp_couple_neo_hookean(
                    Q[:, :, n - 1], clamp, n - 1, x, rest_length, rest_curvature[0, n - 2],
                    rest_curvature[1, n - 2], f_radius_inv * rest_curvature[2, n - 2],
                    fb * bend_stiffness[0, n - 2], fb * bend_stiffness[1, n - 2],
                    fb * bend_stiffness[2, n - 2], True, torque, force, energies, couple)
                for c in range(3):
                    clamp_torque += (Q[0, c, n - 1] * couple[0] + Q[1, c, n - 1] * couple[1]
                                     + Q[2, c, n - 1] * couple[2]) * axis[c]
                couple[7] = cos_end
            if couple[7] < COS_MAX_TURN:
                status = S_CLAMP_LAG
                info[D_WHERE] = n - 1
                info[D_VALUE] = np.arccos(max(couple[7], -1.0))
                break

        if contact_on or asleep:
            (pairs, near, dashpots, contact, touching, worst, worst_at, contact_energy,
             noted) = _contact_loads(
                x, v, rod, ends, settings, axis, dilatation, lengths, f_radius, f_stiff, radius,
                x_build, x_near, radius_near, pairs, near, contact, force, dashpots,
                contact_work, fold_reach, fold_next)
            if asleep and touching > 0:
                # hand back the state at t (positions are half a step ahead here); the
                # overlap is at most one asleep step's closing, as at any first touch
                status = S_WAKE
                _drift(x, v, Q, w, -0.5 * dt)
                break
            if worst > max_penetration:
                max_penetration = worst
            if worst > settings.penetration_limit:
                status = S_PENETRATION
                info[D_WHERE] = worst_at
                info[D_VALUE] = worst
                break
        _external_loads(x, node_mass, r2, u.end_force, force_dir, gravity, u.local_pull,
                        ends.segment_first, ends.segment_last, force)

        t_next = t + dt
        last = step == n_steps - 1
        check = (step + 1) % check_every == 0 or last
        record = (step + 1) % history_every == 0 or last
        if record:
            # kinetic energy at t (before the kick); averaged with the one after it, it sits at
            # t + dt/2 with the potential energy, so the recorded total is second-order accurate
            kinetic_before = _kinetic_energy(v, w, node_mass, inertia, r2)

        if neo_hookean is None:
            _kick(v, w, force, torque, dilatation, inv_mass, inv_inertia, r2, dt, decay, gain,
                  decay_rotation, gain_rotation, incompressible, quadratic_drag, drag_radius)
        else:
            # the rotary inertia keeps its rest value (neo_hookean.py): no factor e
            _kick(v, w, force, torque, dilatation, inv_mass, inv_inertia, r2, dt, decay, gain,
                  decay_rotation, gain_rotation, False, quadratic_drag, drag_radius)
        if eta > 0.0 or (implicit_dashpot and noted > 0):
            # held velocities first: a held node's kicked velocity is not its velocity, and
            # the implicit terms would pass it on to its neighbours
            _hold_velocities(v, ends, u.displacement_rate)
            for i in range(n + 1):
                kick_inv_mass[i] = free_inv_mass[i] / r2
            if eta > 0.0:
                _axial_damping(x, v, kick_inv_mass, rest_length, shear_stiffness[2],
                               f_stiff * r2, eta, dt, incompressible, axial_work)
            if implicit_dashpot and noted > 0:
                apply_dashpots(v, kick_inv_mass, dashpots, noted, dt)
        _hold_velocities(v, ends, u.displacement_rate)

        if check or record:
            status, res, kin = _guards(v, w, force, torque, ends, node_mass, inertia, rest_length,
                                       r2, settings.speed_limit, info)
            if status == S_COMPLETED:
                status = _shear_guard(x, Q, info)
            if status != S_COMPLETED:
                break
            residual = res / force_scale
            kinetic = kin / (force_scale * settings.length_scale)
            if record:
                # the row's kinetic energy from the inlined sum, not from _guards' kin: the
                # copy of _guards a process that loads advance from the cache calls sums it in
                # another order than the one a compiling process calls (up to 1.4e-14 J apart
                # on a 2-core AMD EPYC, tests/test_kernel_cache.py); advance's own code is the
                # same in both
                _record(rows, x, v, Q, w, force, dt, t_next, u.end_force, force_dir, axis,
                        end_position, tables, clamp_torque, energies,
                        0.5 * (_kinetic_energy(v, w, node_mass, inertia, r2) + kinetic_before),
                        touching, worst, residual, f_stiff, f_radius, contact_energy, out)
                rows += 1

        # drift: a full step, or half a step to land on t + dt at the end
        _drift(x, v, Q, w, 0.5 * dt if last else dt)
        t = t_next
        steps = step + 1

        if settle_on and check:
            window_count, window_start, have_mean, settle_motion, settled = _settle_windows(
                x, Q, t, drag_radius, settle_window, settings.settle_distance, equilibrium_after,
                window_sum, window_squares, window_mean, window_count, window_start, have_mean,
                settle_motion, settled)

        accept = False
        if check and stop_at_equilibrium and t >= equilibrium_after:
            at_rest = settled or (residual < tolerance and kinetic < tolerance * tolerance)
            (accept, probe_running, probes, probes_left, window_count, window_start, have_mean,
             settled) = _stop_test(x, t, at_rest, touching, settings, probe_shape, probe_norm2,
                                   probe_reference, probe_running, probes, probes_left,
                                   window_sum, window_squares, window_count, window_start,
                                   have_mean, settled)
        if accept:
            status = S_EQUILIBRIUM
            info[D_SETTLED] = 0.0 if residual < tolerance and kinetic < tolerance * tolerance else 1.0
            if not last:
                # undo the extra half step so the state is at time t
                _drift(x, v, Q, w, -0.5 * dt)
            if not record:
                # the hold's end is a row too (the state is at t itself: no half step to add),
                # or a hold shorter than a history interval would leave no row at all
                _record(rows, x, v, Q, w, force, 0.0, t, u.end_force, force_dir, axis,
                        end_position, tables, clamp_torque, energies,
                        _kinetic_energy(v, w, node_mass, inertia, r2), touching, worst,
                        residual, f_stiff, f_radius, contact_energy, out)
                rows += 1
            break

    if status == S_COMPLETED or status == S_EQUILIBRIUM or status == S_WAKE:
        disp = table_value(tables.times[T_END_DISPLACEMENT], tables.values[T_END_DISPLACEMENT],
                           tables.counts[T_END_DISPLACEMENT], t)
        _apply_held(x, v, ends, disp, 0.0)
    _report(info, max_penetration, contact.rebuilds, contact.max_pairs, residual, kinetic,
            settle_motion, contact.near_rebuilds, probes, probes_left)
    return status, steps, t, rows
