"""The rod problem as plain data: material and geometry, ends, controls, contact, solver.

These objects are what the kernel needs, in SI units, and nothing else: no YAML, no files.
Public arrays are (N, 3), one point per row; they are converted to the kernel's (3, N)
layout in `simulate`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..units import buckling_force, paper_shear_modulus

Table = tuple[tuple[float, ...], tuple[float, ...]]  # (times [s], values): piecewise linear

# The incompressible laws: "paper" is Gazzola 2018's (force /e, couple /ε³: not the gradient
# of an energy, the default for the paper's figures); "neo_hookean" the conservative law of
# rod/neo_hookean.py (forces and couples from one strain energy).
LAWS = ("paper", "neo_hookean")


def setting(default, unit: str = "", *, minimum: float | None = None,
            maximum: float | None = None, strict_min: bool = False,
            choices: tuple[str, ...] | None = None):
    """A field a config may set: its default, unit and allowed range in one place.

    rodphase.config builds the schema's check for the field from this metadata (a bool
    default is true/false, a None default also accepts "auto", `choices` makes it one of
    those names), so the engine and the config cannot disagree on a default, a unit or a
    bound.
    """
    return field(default=default, metadata={"unit": unit, "minimum": minimum,
                                            "maximum": maximum, "strict_min": strict_min,
                                            "choices": choices})


def constant(value: float) -> Table:
    return ((0.0,), (float(value),))


def ramp(t0: float, t1: float, v0: float, v1: float) -> Table:
    """v0 until t0, linear to v1 at t1, v1 after."""
    if t1 <= t0:
        return ((t0,), (float(v1),))
    return ((float(t0), float(t1)), (float(v0), float(v1)))


@dataclass(frozen=True)
class Rod:
    """A uniform rod at rest: straight reference, circular section, linear elastic law.

    rest_curvature is the intrinsic (κ1, κ2, κ3) in the material frame [1/m]; κ3 is the
    intrinsic twist. With `incompressible`, the section shrinks as the rod stretches
    (A·e constant, a = a0/√e, I = I0/e²) through the 1/e and 1/e³ factors of Gazzola 2018;
    without it the law is the plain quadratic energy (used to test conservation).
    `law` picks the incompressible law (LAWS); "neo_hookean" needs `incompressible`.
    """

    length: float  # m, rest length L0
    radius: float  # m, rest radius a0
    elements: int
    density: float = setting(1000.0, "kg/m^3", minimum=0.0, strict_min=True)
    youngs_modulus: float = setting(1.0e6, "Pa", minimum=0.0, strict_min=True)
    # None = the paper's G = 2E/3 of this E
    shear_modulus: float | None = setting(None, "Pa", minimum=0.0, strict_min=True)
    rest_curvature: tuple[float, float, float] = (0.0, 0.0, 0.0)
    incompressible: bool = setting(True)
    law: str = setting("paper", choices=LAWS)
    # Stiffnesses given directly (None: from E, G and the radius), for rods that are not
    # solid isotropic cylinders (e.g. the helical buckling benchmark's B, C, S): bending
    # B = EI [N m²], twist C = GJ [N m²], shear 4GA/3 [N], axial EA [N]. The radius then only
    # sets mass, inertia and contact.
    bend_stiffness_given: float | None = None
    twist_stiffness_given: float | None = None
    shear_stiffness_given: float | None = None
    axial_stiffness_given: float | None = None

    def __post_init__(self):
        if self.law not in LAWS:
            raise ValueError(f"law must be one of {', '.join(LAWS)}; got {self.law!r}")
        if self.law == "neo_hookean" and not self.incompressible:
            raise ValueError("the neo-Hookean law is incompressible: it needs incompressible=True")
        if self.shear_modulus is None:
            object.__setattr__(self, "shear_modulus", paper_shear_modulus(self.youngs_modulus))

    @property
    def area(self) -> float:
        return math.pi * self.radius**2

    @property
    def second_moment(self) -> float:
        return math.pi * self.radius**4 / 4.0

    @property
    def bending_stiffness(self) -> float:
        if self.bend_stiffness_given is not None:
            return self.bend_stiffness_given
        return self.youngs_modulus * self.second_moment

    @property
    def twist_stiffness(self) -> float:
        if self.twist_stiffness_given is not None:
            return self.twist_stiffness_given
        return self.shear_modulus * 2.0 * self.second_moment

    @property
    def shear_stiffness(self) -> float:
        if self.shear_stiffness_given is not None:
            return self.shear_stiffness_given
        return 4.0 * self.shear_modulus * self.area / 3.0

    @property
    def axial_stiffness(self) -> float:
        if self.axial_stiffness_given is not None:
            return self.axial_stiffness_given
        return self.youngs_modulus * self.area

    @property
    def wave_moduli(self) -> tuple[float, float]:
        """(E, G) that the axial and shear waves see: EA/A and (3/4)·S/A with given stiffnesses."""
        e = self.youngs_modulus if self.axial_stiffness_given is None else self.axial_stiffness / self.area
        g = (self.shear_modulus if self.shear_stiffness_given is None
             else 0.75 * self.shear_stiffness / self.area)
        return e, g

    @property
    def buckling_force(self) -> float:
        """F_C = π² B / L0², the paper's unit of load (units.buckling_force)."""
        return buckling_force(self.bending_stiffness, self.length)

    @property
    def element_length(self) -> float:
        return self.length / self.elements


@dataclass(frozen=True)
class Ends:
    """How the two ends are held. Node 0 / element 0 is the start, node n / element n-1 the end.

    `*_held` lists which lab components (x, y, z) of the end node are held at their initial
    place (plus the end displacement control along the axis, for the end node); `*_frame_held`
    holds the end element's frame at its initial orientation turned by the rotation control
    about `axis`. A clamp holds all three components and the frame.
    """

    start_held: tuple[bool, bool, bool] = (True, True, True)
    start_frame_held: bool = True
    end_held: tuple[bool, bool, bool] = (False, False, False)
    end_frame_held: bool = False
    axis: tuple[float, float, float] = (0.0, 0.0, 1.0)
    # Rigid bodies the ends are fixed to, taking part in self-contact (see
    # contact.add_body_forces): a cylinder on the axis line beyond the end, running away from
    # the rod, of body_radius rest radii. With them no strand can pass around a held end, so
    # link stays what was put in, as in the experiment (a weight's hanger, a clamp's holder).
    start_body: bool = False
    end_body: bool = False
    body_radius: float = 1.0


@dataclass(frozen=True)
class Controls:
    """Time tables the loop reads: what moves during a run."""

    end_rotation: Table = constant(0.0)  # rad about the axis
    start_rotation: Table = constant(0.0)  # rad about the axis
    end_force: Table = constant(0.0)  # N along force_direction, on the end node
    force_direction: tuple[float, float, float] = (0.0, 0.0, 1.0)
    end_displacement: Table = constant(0.0)  # m along the axis, held components of the end node
    stiffness: Table = constant(1.0)  # factor on E and G
    radius: Table = constant(1.0)  # factor on the radius; rest twist scales as its inverse
    local_twist: Table = constant(0.0)  # rad/m added to the rest twist over `segment`
    local_pull: Table = constant(0.0)  # N pulling the segment's two end nodes together
    segment: tuple[int, int] = (0, 0)  # first and last node of the active-agent segment
    gravity: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def tables(self) -> list[Table]:
        from . import kernel as k

        # in the kernel's row order, by name (CONTROL_TABLES)
        return [getattr(self, name) for name in k.CONTROL_TABLE_NAMES]


@dataclass(frozen=True)
class Contact:
    """Frictionless (by default) penalty self-contact between non-neighbouring elements.

    stiffness: the pair spring per unit element length in units of E (k = stiffness·E·l0),
    so that a line load q = 10 E·δ... is resisted with an overlap δ = q / (stiffness·E).
    exclusion: elements closer than this arc length (in rest radii) never interact; a rod
    cannot bend back on itself tighter than about π·a.
    """

    enabled: bool = False
    stiffness: float = setting(10.0, "E per unit overlap per unit length", minimum=0.0,
                               strict_min=True)
    damping_ratio: float = setting(0.5, minimum=0.0, maximum=10.0)
    # explicit: the dashpot is part of the force, lagged by half a step, and takes its share
    # of the time step (ratio ζ: the pair springs' ω grows by 1 + ζ); above ζ ≈ 1 it feeds
    # the contact vibration instead of damping it. implicit: backward Euler per pair after
    # the kick (contact.apply_dashpots), never reversing a pair's normal velocity, no dt
    # limit whatever ζ.
    dashpot: str = setting("explicit", choices=("explicit", "implicit"))
    friction: float = setting(0.0, minimum=0.0, maximum=5.0)
    slip_speed: float = 1e-4  # m/s, below it friction is viscous (regularised Coulomb)
    exclusion: float = setting(math.pi, "rest radii of arc length", minimum=0.0, strict_min=True)
    # nodes inside the exclusion held apart by the chord of a circle of the rod's radius over
    # the rest arc between them (contact.fold_forces): a loop pulled tighter than the rod
    # cannot close through itself, so link is not lost by a self-passage no filament makes
    fold: bool = setting(True)
    # The pair spring's pull along each element in contact, k·δ·a/(2l): the overlap δ depends
    # on the radii, a0/√e for an incompressible rod, so this is the rest of the gradient of the
    # contact energy ½kδ² (with it, contact does no work on a stretching rod). PyElastica's
    # contact, the paper's, has none; off, rodphase's tight braids stretch as PyElastica's
    # (docs/history/fig3-corner.md, "The four against the authors' code"). Only an incompressible rod
    # thins: for any other it changes nothing.
    thinning_force: bool = setting(True)
    # Contact sleeps until the rod first touches itself (a pair, a fold) or an end body: until
    # then the run takes the larger time step of a rod without contact, and from the step of
    # that touch on it is awake, with its own step, for the rest of the run (simulate.py)
    sleep: bool = setting(True)
    # the Verlet-list margin
    skin: float = setting(0.5, "rest radii", minimum=0.0, strict_min=True)
    # the smallest margin of the short list the force loop runs over; the kernel doubles it
    # (up to skin/2) for a rod that closes it within a few steps, halves it back when still
    near_skin: float = setting(0.01, "rest radii", minimum=0.0, strict_min=True)
    # beyond this overlap the run is unstable
    penetration_limit: float = setting(0.5, "overlap / radius", minimum=0.0, maximum=2.0,
                                       strict_min=True)

    def __post_init__(self):
        allowed = Contact.__dataclass_fields__["dashpot"].metadata["choices"]
        if self.dashpot not in allowed:
            raise ValueError(f"contact.dashpot: {self.dashpot!r} (allowed: {', '.join(allowed)})")


@dataclass(frozen=True)
class Solver:
    """Time stepping. dt=None derives it from the stiffest mode with the safety factor."""

    dt: float | None = setting(None, "s", minimum=0.0, strict_min=True)
    safety: float = setting(0.5, minimum=0.0, maximum=1.0, strict_min=True)
    # velocities decay as exp(-damping·t) without forces
    damping: float = setting(20.0, "1/s", minimum=0.0)
    # 1/s about d1 and d2, half of it about d3. None = 40·c_G/L0 with c_G = √(G/ρ): the
    # lowest twist modes are overdamped (about 3x critical) so stored twist cannot snap into
    # a loop faster than contact can catch it, while twist still spreads over the rod in
    # L0²/(π²·2G/(ρν)) ≈ 0.1 s for the paper's rod. (PyElastica's matched 4·damping/a² is
    # far heavier: twist then piles up at a turning end.)
    rotational_damping: float | None = setting(None, "1/s", minimum=0.0)
    # 1/m: drag rate growing with speed, speed × quadratic_drag [1/s] (spin × radius for
    # rotation), integrated implicitly. 0 turns it off.
    quadratic_drag: float = setting(0.0, "1/m: extra drag rate per unit speed", minimum=0.0)
    # s: axial Kelvin–Voigt damping, an element stress η·E·(strain rate), integrated by
    # backward Euler along the rod (kernel._axial_damping): a mode of frequency ω is damped
    # at the ratio ω·η/2, so the stiff axial and contact-coupled vibrations (hundreds of Hz)
    # far more than the slow shape changes. 0 turns it off.
    strain_rate_damping: float = setting(0.0, "s (Kelvin-Voigt time)", minimum=0.0, maximum=1.0)
    # between history rows
    history_interval: float = setting(0.05, "s", minimum=0.0, strict_min=True)
    check_interval: int = 50  # steps between guard and equilibrium checks
    # equilibrium: residual force / force scale
    hold_tolerance: float = setting(1e-4, minimum=0.0, maximum=1.0, strict_min=True)
    # s; > 0 also ends a hold once the shape, averaged over consecutive windows this long,
    # has moved by less than hold_tolerance × settle_scale [m] at every surface point between them
    settle_window: float = setting(0.0, "s; 0 = residual test only", minimum=0.0)
    settle_scale: float | None = None  # m; None = the rod's rest length (as the kinetic test)
    speed_limit: float | None = None  # m/s; None = the axial wave speed
    # Stability probe of a hold's equilibrium (see kernel.advance): displace the candidate by
    # probe_size rest radii (seeded smooth lateral shape, probe_seed) and accept it only once
    # the displacement along that shape has decayed below probe_return of the probe; grown
    # past probe_leave probes means the rod left an unstable equilibrium.
    stability_probe: bool = setting(False)
    probe_size: float = setting(0.1, "rest radii", minimum=0.0, maximum=1.0, strict_min=True)
    probe_return: float = 0.1
    probe_leave: float = 3.0
    probe_seed: int = 0
    # With stability_probe, a candidate that does not touch itself must also be stable by the
    # model's own stiffness (rod/static.py): the probe's few sine modes miss the slow helical
    # pair that goes unstable first on a twisted straight rod (issue #32). If it is not, the
    # rod is pushed by probe_size along its most unstable mode and the hold goes on.
    static_stability: bool = setting(True)


@dataclass(frozen=True)
class Stage:
    """One phase of a protocol: run `duration` seconds, or less if `until_equilibrium`.

    `controls` (times relative to the stage start) replaces the problem's controls for this
    stage; an equilibrium stop is allowed only once its tables have stopped moving.
    """

    duration: float
    until_equilibrium: bool = False
    label: str = ""
    controls: Controls | None = None
    ends: Ends | None = None  # replaces the problem's ends; held places are taken at the stage start
    # the sweep sample whose state this stage's end is (a continuation's holds), else None
    sample: int | None = None


@dataclass
class RodState:
    """Kernel state in (3, N) layout. Use `positions` and `directors` for (N, 3) views."""

    time: float
    x: np.ndarray  # (3, n+1)
    v: np.ndarray  # (3, n+1)
    Q: np.ndarray  # (3, 3, n), Q[r, :, i] = d_{r+1} of element i
    w: np.ndarray  # (3, n), material frame

    @property
    def positions(self) -> np.ndarray:
        """(n+1, 3) node positions [m]."""
        return np.ascontiguousarray(self.x.T)

    @property
    def directors(self) -> np.ndarray:
        """(n, 3, 3): directors[i, r] is d_{r+1} of element i in the lab frame."""
        return np.ascontiguousarray(np.transpose(self.Q, (2, 0, 1)))

    def copy(self) -> RodState:
        return RodState(self.time, self.x.copy(), self.v.copy(), self.Q.copy(), self.w.copy())


def state_from(positions: np.ndarray, directors: np.ndarray, time: float = 0.0) -> RodState:
    """A state at rest from (n+1, 3) positions and (n, 3, 3) directors (rows d1, d2, d3)."""
    positions = np.asarray(positions, dtype=float)
    directors = np.asarray(directors, dtype=float)
    n = directors.shape[0]
    if positions.shape != (n + 1, 3) or directors.shape != (n, 3, 3):
        raise ValueError(f"positions must be (n+1, 3) and directors (n, 3, 3); got {positions.shape}"
                         f" and {directors.shape}")
    x = np.ascontiguousarray(positions.T)
    Q = np.ascontiguousarray(np.transpose(directors, (1, 2, 0)))
    return RodState(time, x, np.zeros_like(x), Q, np.zeros((3, n)))


def spread_twist(angle: float, elements: int) -> np.ndarray:
    """(n,) the rotation [rad] of each element's frame about its d3 when a twist `angle`
    [rad] is spread evenly along the rod, from the clamp at the start: element i (its centre
    at (i + ½)/n of the length) turns by angle·(i + ½)/n. The straight branch's twist, and the
    static predictor's guess of where a turned end's twist goes."""
    return angle * (np.arange(elements) + 0.5) / elements


def straight_state(rod: Rod, axis=(0.0, 0.0, 1.0), twist_turns: float = 0.0,
                   origin=(0.0, 0.0, 0.0)) -> RodState:
    """A straight rod from `origin` along `axis` at rest, d3 = axis, d1 turned uniformly by
    `twist_turns` turns from the first to the last element (about the axis)."""
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    n = rod.elements
    s = np.linspace(0.0, rod.length, n + 1)
    positions = np.asarray(origin, float) + s[:, None] * axis
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    d1 = helper - axis * (helper @ axis)
    d1 /= np.linalg.norm(d1)
    d2 = np.cross(axis, d1)
    angles = spread_twist(2 * np.pi * twist_turns, n) if twist_turns else np.zeros(n)
    directors = np.empty((n, 3, 3))
    c, sn = np.cos(angles)[:, None], np.sin(angles)[:, None]
    directors[:, 0] = c * d1 + sn * d2
    directors[:, 1] = -sn * d1 + c * d2
    directors[:, 2] = axis
    return state_from(positions, directors)


def hairpin_state(rod: Rod, bend_radius: float) -> RodState:
    """A rod folded at its middle, at rest: up along +z from the origin, a half circle of
    `bend_radius` in the x–z plane, back down along −z at x = 2·bend_radius; d1 = +y
    throughout, d3 the chord of each element (tests and scripts squeeze or release it)."""
    n = rod.elements
    straight = (rod.length - math.pi * bend_radius) / 2
    positions = np.zeros((n + 1, 3))
    for i, si in enumerate(np.linspace(0, rod.length, n + 1)):
        if si <= straight:
            positions[i] = [0, 0, si]
        elif si <= straight + math.pi * bend_radius:
            phi = (si - straight) / bend_radius
            positions[i] = [bend_radius - bend_radius * math.cos(phi), 0,
                            straight + bend_radius * math.sin(phi)]
        else:
            positions[i] = [2 * bend_radius, 0, straight - (si - straight - math.pi * bend_radius)]
    t = np.diff(positions, axis=0)
    t /= np.linalg.norm(t, axis=1)[:, None]
    d1 = np.tile([0.0, 1.0, 0.0], (n, 1))
    return state_from(positions, np.stack([d1, np.cross(t, d1), t], axis=1))


def wave_speeds(rod: Rod, stiffness_factor: float = 1.0) -> tuple[float, float]:
    """(axial, shear) wave speeds [m/s]."""
    e, g = rod.wave_moduli
    e, g = e * stiffness_factor, g * stiffness_factor
    return math.sqrt(e / rod.density), math.sqrt(max(4.0 * g / 3.0, g) / rod.density)


def stable_time_step(rod: Rod, contact: Contact, stiffness_factor: float = 1.0,
                     radius_factor: float = 1.0) -> float:
    """Largest dt that position Verlet takes stably, 2/ω_max, from the stiffest modes.

    ω_max² sums the chain mode of the stiffest wave speed c over an element, (2c/l)², the
    rotation of a section against its shear, 16G/(3ρa²) (the shear couple S1·l over the
    rotational inertia ρI1·l), and, with contact, the pair springs k = κ·E·l over an element
    mass ρ·A·l. In dense contact (a plectoneme, a solenoid) an element presses on the elements
    of the neighbouring strand within about two radii, 2 + 4a/l of them, so that term grows
    as elements get shorter than the radius: measured, a plectoneme at 100 elements was
    stable only to 0.43x the bound without it. Stretching only lengthens elements, so rest
    values bound the rest.
    """
    c_axial, c_shear = wave_speeds(rod, stiffness_factor)
    c = max(c_axial, c_shear)
    l0 = rod.element_length
    a = rod.radius * min(radius_factor, 1.0)
    g = rod.wave_moduli[1] * stiffness_factor
    omega2 = (2.0 * c / l0) ** 2 + 16.0 * g / (3.0 * rod.density * a * a)
    if contact.enabled:
        partners = 2.0 + 4.0 * rod.radius * max(radius_factor, 1.0) / l0
        spring = partners * contact.stiffness * rod.youngs_modulus * stiffness_factor / (
            rod.density * rod.area * radius_factor**2)
        # the explicit dashpot (ratio ζ of the pair springs) takes its share of the step too;
        # the implicit one (contact.apply_dashpots) takes none
        ratio = contact.damping_ratio if contact.dashpot == "explicit" else 0.0
        omega2 += spring * (1.0 + ratio) ** 2
    return 2.0 / math.sqrt(omega2)


@dataclass
class Problem:
    """Everything one run needs, assembled by a scene."""

    rod: Rod
    state: RodState
    ends: Ends = field(default_factory=Ends)
    controls: Controls = field(default_factory=Controls)
    contact: Contact = field(default_factory=Contact)
    solver: Solver = field(default_factory=Solver)
    stages: tuple[Stage, ...] = (Stage(1.0),)
    force_scale: float | None = None  # N; default max(|end force|, F_C)
    name: str = ""
    rest_curvature: np.ndarray | None = None  # (n-1, 3), added to rod.rest_curvature
    # (start, end) (3, 3) clamp frames (rows d1 d2 d3) at zero rotation control; None: the
    # frames half an element beyond the initial state's end elements (see clamp_frames). A run
    # continued from a stored state sets them so that its clamps hold the rod where it was; a
    # run started twisted sets the untwisted frames, so that its rotation control carries
    # the turns already in.
    clamp_reference: tuple[np.ndarray, np.ndarray] | None = None
    # m, added to the recorded end displacement: where the end already was when a continued
    # run (or a run started stretched) started, so that its history counts from the rest length
    end_displacement_offset: float = 0.0
    # continued from a stored state (restart.continue_from): its link is accounted for from
    # its first history row, not from zero, since the stored run's clamps put it in
    continued: bool = False
