#!/usr/bin/env python
"""Kernel benchmark: µs per time step of rodphase against PyElastica 1.0, same scene, same dt.

    python benchmarks/bench_kernel.py [--write docs/history/benchmarks.md] [--quick]

The scene (DESIGN.md §7) is the paper's rod, L0 = 1 m, a = 0.025 m, E = 1 MPa, G = 2E/3
(= E/(1+ν) with ν = ½, as PyElastica's examples write it), ρ = 1000 kg/m³, clamped at node 0;
node n is held laterally, slides along the axis under a constant load 25 F_C
(F_C = π²EI/L0²) and is twisted on (0.1 turns/s for the first second, then held). Both codes
start from the same plectoneme, so the self-contact columns time steps with real contacts:

1. rodphase's scene twist_under_load (120 elements, Φa = 0.7, i.e. 4.46 turns at 25 F_C) is run
   to equilibrium once;
2. its final shape is resampled to each n: node positions by a cubic spline in the material
   coordinate (so the stretch is kept), directors rebuilt as d3 = tangent and d1 = a parallel-
   transported vector turned by the source's twist angle (measured against its own parallel
   transport, interpolated in the material coordinate), so the stored twist is carried over;
3. rodphase relaxes that shape at the new n for 0.5 s with contact and heavy damping (the
   resampled polyline cuts corners, leaving small overlaps), and this relaxed state, at rest,
   starts every timed run of both codes at that n.

Both codes use position Verlet at the same dt = 0.25 × rodphase's stable bound with contact
(rodphase.rod.stable_time_step) for that n, unless PyElastica blows up at it; then dt is halved
for both and the table says so. Damping is matched: velocities decay as exp(-ν t), angular
velocities as exp(-ν_r t) about d1, d2 and exp(-ν_r t/2) about d3 (PyElastica:
AnalyticalLinearDamper with per-node and per-element physical constants). ν = 200/s and ν_r =
5 × rodphase's automatic value by default (--damping, --rotational-factor), ten and five times
the scene's: the timed state is a plectoneme being held, not one in violent motion (see
DAMPING below). The
contact springs are matched too: PyElastica's RodSelfContact gets rodphase's k = 10·E·l0 per
element pair and a dashpot ν = √(k m_element) (rodphase's damping ratio ½). PyElastica's
shear stiffness is set to rodphase's 4GA/3 (its default is 27/28 GA).

Remaining differences (physics, not cost): rodphase holds the end frames as clamps half an
element beyond the end elements, PyElastica sets the end elements' frames; PyElastica's contact
skips fewer neighbours (1 + ⌈0.8πa/l⌉ against ⌈πa/l⌉) and tests every pair (O(n²)), rodphase
keeps a Verlet list from a hashed grid (O(n)) and runs its force loop over the pairs of it
within an adaptive margin (0.01 rest radii up to a quarter radius) of touching.

Timing is CPU time of the process (time.process_time), excludes compilation (every
configuration is run once briefly first), and interleaves the two codes: for each n and
contact setting the timed runs alternate rodphase / PyElastica (order swapped every round),
so load from elsewhere on the machine slows both alike. Each timed run is at least --seconds
of CPU time (PyElastica with contact at least 200 steps); the median of --repeats runs is
reported. Threads are pinned to one (NUMBA/OMP/MKL/OPENBLAS) before imports.
"""

from __future__ import annotations

import os

for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS",
             "NUMEXPR_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse
import datetime
import math
import platform
import statistics
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numba
import numpy as np
from numba import njit
from scipy.interpolate import CubicSpline

from rodphase import config as C
from rodphase.rod import (
    Contact,
    Controls,
    Ends,
    Problem,
    Rod,
    Solver,
    Stage,
    constant,
    ramp,
    simulate,
    stable_time_step,
    state_from,
)
from rodphase.rod.contact import closest_parameters
from rodphase.rod.simulate import rotational_damping_auto
from rodphase.scenes import SCENES, build

SECTION = "## Kernel: µs per step, rodphase vs PyElastica"

LENGTH = 1.0
RADIUS = 0.025
YOUNG = 1.0e6
SHEAR = 2.0 * YOUNG / 3.0
DENSITY = 1000.0
LOAD_MULTIPLE = 25.0
# Damping of the timed runs, both codes: 1/s on velocities; factor on rodphase's automatic
# rotational damping (40·√(G/ρ)/L0 about d1, d2, half of it about d3). Heavier than the scene's
# default (20/s, factor 1): with that, the resampled plectoneme does not settle in rodphase at
# n ≥ 200 (its kinetic energy grows under contact; not with contact off or incompressible=False)
# and runs at n ≥ 300 stop as unstable.
DAMPING = 200.0
ROTATIONAL_FACTOR = 5.0
RELAX_DAMPING = (200.0, 5.0)  # the same, for the relaxation of the resampled shape
TWIST_RATE = 0.1 * 2 * math.pi  # rad/s during the timed runs ...
TWIST_TIME = 1.0  # ... for this long, then held
DT_FACTOR = 0.25
SOURCE_ELEMENTS = 120
SOURCE_TWIST_DENSITY = 0.7  # Φa → 4.46 turns
RELAX_TIME = 0.5  # s


def rod_for(n: int) -> Rod:
    return Rod(length=LENGTH, radius=RADIUS, elements=n, density=DENSITY, youngs_modulus=YOUNG,
               shear_modulus=SHEAR)


def end_load(rod: Rod) -> float:
    return LOAD_MULTIPLE * rod.buckling_force


# ---------------------------------------------------------------- machine

def _load() -> str:
    try:
        return Path("/proc/loadavg").read_text().split()[0]
    except OSError:
        return "?"


def machine_note() -> dict:
    cpu = platform.processor() or "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    try:
        import elastica.version

        pyelastica = elastica.version.VERSION
    except ImportError:
        pyelastica = "not installed"
    try:
        commit = subprocess.run(["git", "describe", "--always", "--dirty"], capture_output=True,
                                check=False, text=True, cwd=Path(__file__).resolve().parent,
                                timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        commit = ""
    import rodphase

    return {
        "date": datetime.datetime.now().strftime("%Y-%m-%d %H:%M"),
        "cpu": cpu,
        "nproc": os.cpu_count(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "numba": numba.__version__,
        "pyelastica": pyelastica,
        "rodphase": rodphase.__version__ + (f" ({commit})" if commit else ""),
        "threads": os.environ["NUMBA_NUM_THREADS"],
        "load": _load(),
    }


# ---------------------------------------------------------------- the common start shape

def make_plectoneme():
    """rodphase's twist_under_load at Φa = 0.7, 25 F_C, to equilibrium: (positions, directors, info)."""
    cfg = C.load_scene("twist_under_load", [("loading.twist_density", SOURCE_TWIST_DENSITY),
                                            ("loading.force_multiple", LOAD_MULTIPLE),
                                            ("rod.elements", SOURCE_ELEMENTS)], SCENES)
    problem = build(cfg)
    result = simulate(problem)
    asked = 2 * math.pi * C.twist_turns(cfg)
    h = result.history
    info = {
        "status": result.status, "message": result.message,
        "turns": C.twist_turns(cfg), "end_rotation": float(h["end_rotation"][-1]),
        "asked_rotation": asked, "contacts": int(h["contacts"][-1]),
        "end_height": float(result.positions[-1, 2]), "wall": result.diagnostics["wall_time"],
        "sim_time": result.diagnostics["final_time"],
    }
    return result.positions, result.directors, info


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _transport(p, a, b):
    """Rotate p by the smallest rotation taking unit a to unit b."""
    c = float(a @ b)
    k = np.cross(a, b)
    return p * c + np.cross(k, p) + k * (k @ p) / (1.0 + c)


def _transported_frame(tangents, first):
    """Parallel-transported unit normals along the element tangents, starting from `first`."""
    p = np.empty_like(tangents)
    q = first - tangents[0] * (first @ tangents[0])
    p[0] = q / np.linalg.norm(q)
    for i in range(1, len(tangents)):
        q = _transport(p[i - 1], tangents[i - 1], tangents[i])
        q -= tangents[i] * (q @ tangents[i])
        p[i] = q / np.linalg.norm(q)
    return p


def resample(positions, directors, n):
    """The shape on n elements: positions by arc length in the material coordinate, directors
    from tangents with a parallel-transported d1 turned by the source's twist angle."""
    m = directors.shape[0]
    s_src = np.linspace(0.0, LENGTH, m + 1)
    s_new = np.linspace(0.0, LENGTH, n + 1)
    x = CubicSpline(s_src, positions, axis=0)(s_new)
    x[0] = positions[0]
    x[-1, :2] = positions[-1, :2]  # the held end stays exactly where it was held

    t_src = _unit(np.diff(positions, axis=0))
    p_src = _transported_frame(t_src, directors[0, 0])
    d1 = directors[:, 0]
    psi = np.unwrap(np.arctan2(np.einsum("ij,ij->i", np.cross(t_src, p_src), d1),
                               np.einsum("ij,ij->i", p_src, d1)))
    mid_src = 0.5 * (s_src[1:] + s_src[:-1])
    mid_new = 0.5 * (s_new[1:] + s_new[:-1])
    psi_new = CubicSpline(mid_src, psi)(mid_new)

    t = _unit(np.diff(x, axis=0))
    p = _transported_frame(t, directors[0, 0])
    q = np.cross(t, p)
    new_d1 = np.cos(psi_new)[:, None] * p + np.sin(psi_new)[:, None] * q
    out = np.empty((n, 3, 3))
    out[:, 0] = new_d1
    out[:, 1] = np.cross(t, new_d1)
    out[:, 2] = t
    return x, out


def rodphase_problem(rod, positions, directors, contact_on, dt, steps, relax=False):
    force = end_load(rod)
    controls = Controls(end_force=constant(force),
                        end_rotation=constant(0.0) if relax else
                        ramp(0.0, TWIST_TIME, 0.0, TWIST_RATE * TWIST_TIME))
    contact = Contact(enabled=contact_on, penetration_limit=2.0 if relax else 0.5)
    damping, factor = RELAX_DAMPING if relax else (DAMPING, ROTATIONAL_FACTOR)
    solver = Solver(dt=dt, damping=damping, rotational_damping=factor * rotational_damping_auto(rod),
                    history_interval=0.01 if relax else 0.05)
    return Problem(rod=rod, state=state_from(positions, directors),
                   ends=Ends(end_held=(True, True, False), end_frame_held=True),
                   controls=controls, contact=contact, solver=solver,
                   stages=(Stage(RELAX_TIME if relax else steps * dt),), name="bench")


def start_state(source, n, dt):
    """Resampled plectoneme relaxed by rodphase at n elements: (positions, directors, contacts)."""
    x, d = resample(source[0], source[1], n)
    result = simulate(rodphase_problem(rod_for(n), x, d, True, dt, 0, relax=True))
    if not result.ok:
        raise RuntimeError(f"relaxing the resampled plectoneme at n = {n}: {result.message}")
    return result.positions, result.directors, int(result.history["contacts"][-1])


# ---------------------------------------------------------------- PyElastica

@njit(cache=False)
def _pe_hold_values(x, Q, ref, angle):
    """ref (3, 8): start node, start frame (3 cols), end node, end frame (3 cols)."""
    n = Q.shape[2]
    for c in range(3):
        x[c, 0] = ref[c, 0]
        for r in range(3):
            Q[r, c, 0] = ref[r, 1 + c]
    x[0, n] = ref[0, 4]
    x[1, n] = ref[1, 4]
    # the end frame: the initial one turned by `angle` about the lab z axis (d_r <- R d_r)
    cs = math.cos(angle)
    sn = math.sin(angle)
    for r in range(3):
        a = ref[r, 5]
        b = ref[r, 6]
        Q[r, 0, n - 1] = cs * a - sn * b
        Q[r, 1, n - 1] = sn * a + cs * b
        Q[r, 2, n - 1] = ref[r, 7]


@njit(cache=False)
def _pe_hold_rates(v, w, Q, rate):
    n = Q.shape[2]
    for c in range(3):
        v[c, 0] = 0.0
        w[c, 0] = 0.0
        # lab angular velocity rate·ẑ in the end element's material frame
        w[c, n - 1] = rate * Q[c, 2, n - 1]
    v[0, n] = 0.0
    v[1, n] = 0.0


def pyelastica_sim(n, positions, directors, contact_on, dt):
    """(simulator, stepper, rod) of the benchmark scene in PyElastica 1.0, finalized."""
    import elastica as ea

    class TwistedEnds(ea.ConstraintBase):
        """Node 0 and element 0 clamped; node n held in x, y; element n-1 turned about z."""

        def __init__(self, reference, rate, ramp_time, **kwargs):
            super().__init__(**kwargs)
            self.reference = reference
            self.rate, self.ramp_time = rate, ramp_time

        def constrain_values(self, system, time):
            angle = self.rate * min(float(time), self.ramp_time)
            _pe_hold_values(system.position_collection, system.director_collection,
                            self.reference, angle)

        def constrain_rates(self, system, time):
            rate = self.rate if time < self.ramp_time else 0.0
            _pe_hold_rates(system.velocity_collection, system.omega_collection,
                           system.director_collection, rate)

    class Bench(ea.BaseSystemCollection, ea.Constraints, ea.Forcing, ea.Damping, ea.Contact):
        pass

    rod_spec = rod_for(n)
    sim = Bench()
    rod = ea.CosseratRod.straight_rod(n, np.zeros(3), np.array([0.0, 0.0, 1.0]),
                                      np.array([1.0, 0.0, 0.0]), LENGTH, RADIUS, DENSITY,
                                      youngs_modulus=YOUNG, shear_modulus=SHEAR)
    # rodphase's shear stiffness 4GA/3 (PyElastica's default is 27/28 GA)
    area = math.pi * RADIUS**2
    rod.shear_matrix[0, 0, :] = rod.shear_matrix[1, 1, :] = 4.0 * SHEAR * area / 3.0
    # the start shape: rest state stays the straight rod of length L0
    x = np.ascontiguousarray(positions.T)
    Q = np.ascontiguousarray(np.transpose(directors, (1, 2, 0)))
    rod.position_collection[...] = x
    rod.director_collection[...] = Q
    rod.velocity_collection[...] = 0.0
    rod.omega_collection[...] = 0.0
    sim.append(rod)

    reference = np.empty((3, 8))
    reference[:, 0], reference[:, 1:4] = x[:, 0], Q[:, :, 0]
    reference[:, 4], reference[:, 5:8] = x[:, -1], Q[:, :, -1]
    sim.constrain(rod).using(TwistedEnds, reference=reference, rate=TWIST_RATE,
                             ramp_time=TWIST_TIME)
    sim.add_forcing_to(rod).using(ea.EndpointForces, np.zeros(3),
                                  np.array([0.0, 0.0, end_load(rod_spec)]), ramp_up_time=1e-12)
    # matched damping: v ← v·exp(-ν dt); ω_c ← ω_c·exp(-ν_c dt)^e with ν = (ν_r, ν_r, ν_r/2)
    nu_r = ROTATIONAL_FACTOR * rotational_damping_auto(rod_spec)
    moi = np.diagonal(rod.mass_second_moment_of_inertia).T.copy()  # (3, n)
    sim.dampen(rod).using(ea.AnalyticalLinearDamper,
                          translational_damping_constant=DAMPING * rod.mass.copy(),
                          rotational_damping_constant=np.array([nu_r, nu_r, 0.5 * nu_r])[:, None] * moi,
                          time_step=np.float64(dt))
    if contact_on:
        k = 10.0 * YOUNG * rod_spec.element_length  # rodphase's Contact.stiffness·E·l0
        m_element = DENSITY * area * rod_spec.element_length
        sim.detect_contact_between(rod, rod).using(ea.RodSelfContact, k=k,
                                                   nu=math.sqrt(k * m_element))
    sim.finalize()
    return sim, ea.PositionVerlet(), rod


@njit(cache=False)
def touching_pairs(x, radius, lengths, pyelastica_skip):
    """Element pairs whose capsules overlap, with PyElastica's neighbour skip rule."""
    n = x.shape[1] - 1
    count = 0
    for i in range(n):
        skip = int(1 + np.ceil(0.8 * np.pi * radius[i] / lengths[i])) if pyelastica_skip else 1
        for j in range(i - skip, -1, -1):
            u0, u1, u2 = x[0, i + 1] - x[0, i], x[1, i + 1] - x[1, i], x[2, i + 1] - x[2, i]
            w0, w1, w2 = x[0, j + 1] - x[0, j], x[1, j + 1] - x[1, j], x[2, j + 1] - x[2, j]
            s, t = closest_parameters(x[0, i] - x[0, j], x[1, i] - x[1, j], x[2, i] - x[2, j],
                                      u0, u1, u2, w0, w1, w2, 1.0 / (u0 * u0 + u1 * u1 + u2 * u2),
                                      1.0 / (w0 * w0 + w1 * w1 + w2 * w2))
            d0 = x[0, i] + s * u0 - x[0, j] - t * w0
            d1 = x[1, i] + s * u1 - x[1, j] - t * w1
            d2 = x[2, i] + s * u2 - x[2, j] - t * w2
            if np.sqrt(d0 * d0 + d1 * d1 + d2 * d2) < radius[i] + radius[j]:
                count += 1
    return count


def pyelastica_healthy(rod) -> bool:
    c_axial = math.sqrt(YOUNG / DENSITY)
    return bool(np.isfinite(rod.position_collection).all()
                and np.abs(rod.velocity_collection).max() < c_axial
                and np.abs(rod.position_collection).max() < 10 * LENGTH)


# ---------------------------------------------------------------- timing

def rodphase_timer(rod, start, contact_on, dt, seconds):
    """(steps, run): `run()` times one rodphase run of `steps` steps from the start state and
    returns (CPU µs per step, result). Compiles (or loads the cache) first."""
    x, d = start
    simulate(rodphase_problem(rod, x, d, contact_on, dt, 500))  # compile / load cache
    t0 = time.process_time()
    calib = simulate(rodphase_problem(rod, x, d, contact_on, dt, 2000))
    guess = 1e6 * (time.process_time() - t0) / calib.diagnostics["steps"]
    steps = max(2000, math.ceil(1.1 * seconds * 1e6 / guess))

    def run():
        t0 = time.process_time()
        result = simulate(rodphase_problem(rod, x, d, contact_on, dt, steps))
        cpu = time.process_time() - t0
        if not result.ok:
            raise RuntimeError(f"rodphase n = {rod.elements}, contact = {contact_on}: {result.message}")
        return 1e6 * cpu / result.diagnostics["steps"], result

    return steps, run


def rodphase_summary(times, results, steps, dt, contact_on):
    last = results[-1]
    hist = np.concatenate([r.history["contacts"] for r in results])
    return {"us": statistics.median(times), "all_us": times, "steps": steps,
            "contacts_median": float(np.median(hist)) if contact_on else 0.0,
            "contacts_final": int(last.history["contacts"][-1]) if contact_on else 0,
            "candidates": int(last.diagnostics["max_pairs"]),
            "rebuilds": int(last.diagnostics["rebuilds"]),
            "near_rebuilds": int(last.diagnostics["near_rebuilds"]),
            "end_rotation": float(last.history["end_rotation"][-1]),
            "asked_rotation": TWIST_RATE * min(steps * dt, TWIST_TIME),
            "sim_time": steps * dt}


def pyelastica_timer(n, start, contact_on, dt, seconds, min_steps):
    """(steps, run, finish): `run()` advances one PyElastica simulation by `steps` steps and
    returns CPU µs per step, or None once the rod has blown up; `finish()` counts the
    touching pairs at the end. Runs continue the same simulation."""
    x, d = start
    sim, stepper, rod = pyelastica_sim(n, x, d, contact_on, dt)
    clock = {"t": np.float64(0.0)}
    for _ in range(5):  # compile / load numba caches
        clock["t"] = stepper.step(sim, clock["t"], dt)
    t0 = time.process_time()
    k = 0
    while k < 20 or time.process_time() - t0 < 0.2:
        clock["t"] = stepper.step(sim, clock["t"], dt)
        k += 1
    guess = (time.process_time() - t0) / k
    steps = max(min_steps, math.ceil(1.1 * seconds / guess))

    def run():
        t = clock["t"]
        t0 = time.process_time()
        for _ in range(steps):
            t = stepper.step(sim, t, dt)
        cpu = time.process_time() - t0
        clock["t"] = t
        return 1e6 * cpu / steps if pyelastica_healthy(rod) else None

    def finish():
        xs = np.ascontiguousarray(rod.position_collection)
        return touching_pairs(xs, np.ascontiguousarray(rod.radius),
                              np.ascontiguousarray(rod.lengths), True) if contact_on else 0

    return steps, run, finish


def time_both(rod, n, start, contact_on, dt, seconds, repeats, with_pyelastica):
    """Both codes on one configuration, their timed runs interleaved (rodphase first in even
    rounds, PyElastica first in odd ones), so that load from elsewhere slows both alike.
    Returns (rodphase entry, PyElastica entry or None if it blew up / was not asked)."""
    rp_steps, rp_run = rodphase_timer(rod, start, contact_on, dt, seconds)
    pe_timer = (pyelastica_timer(n, start, contact_on, dt, seconds, 200 if contact_on else 1000)
                if with_pyelastica else None)
    rp_times, rp_results, pe_times = [], [], []
    for r in range(repeats):
        order = ("rp", "pe") if r % 2 == 0 else ("pe", "rp")
        for code in order:
            if code == "rp":
                us, result = rp_run()
                rp_times.append(us)
                rp_results.append(result)
            elif pe_timer is not None:
                us = pe_timer[1]()
                if us is None:
                    return rodphase_summary(rp_times or [np.nan], rp_results or [result], rp_steps,
                                            dt, contact_on), None
                pe_times.append(us)
    rp = rodphase_summary(rp_times, rp_results, rp_steps, dt, contact_on)
    pe = None
    if pe_timer is not None:
        pe = {"us": statistics.median(pe_times), "all_us": pe_times, "steps": pe_timer[0],
              "touching": pe_timer[2](), "sim_time": None}
    return rp, pe


def _spread(entry) -> str:
    return "runs " + ", ".join(f"{u:.1f}" for u in entry["all_us"])


def measure(n, source, seconds, repeats, log, with_pyelastica=True):
    rod = rod_for(n)
    bound = stable_time_step(rod, Contact(enabled=True))
    dt = DT_FACTOR * bound
    note = ""
    for attempt in range(4):
        x, d, relaxed_contacts = start_state(source, n, dt)
        start = (x, d)
        xs = np.ascontiguousarray(x.T)
        lengths = np.linalg.norm(np.diff(xs, axis=1), axis=0)
        radii = RADIUS * np.sqrt(rod.element_length / lengths)
        row = {"n": n, "dt": dt, "bound": bound, "start_contacts": relaxed_contacts, "note": note,
               "start_contacts_pyelastica": touching_pairs(xs, radii, lengths, True)}
        rp, pe = {}, {}
        for on in (False, True):
            rp[on], pe[on] = time_both(rod, n, start, on, dt, seconds, repeats, with_pyelastica)
            if with_pyelastica and pe[on] is None:
                break
        if with_pyelastica and (pe.get(False) is None or pe.get(True) is None):
            note = (f"PyElastica unstable at dt = {dt:.3g} s; dt halved for both codes "
                    f"({dt / bound:.3g} × bound)")
            log(f"  n = {n}: {note}")
            dt *= 0.5
            continue
        if not with_pyelastica:
            pe = {}
        row["rp"] = rp
        row["pe"] = pe
        row["dt"] = dt
        row["note"] = note
        return row
    raise RuntimeError(f"PyElastica unstable at n = {n} down to dt = {dt:.3g} s")


# ---------------------------------------------------------------- report

def _f(v, digits=1):
    return "—" if v is None else f"{v:.{digits}f}"


def report(machine, source_info, rows, extra, args, total) -> str:
    lines = [SECTION, ""]
    lines.append(f"Measured {machine['date']} by `python benchmarks/bench_kernel.py"
                 f"{' --quick' if args.quick else ''}` in {total:.0f} s: {machine['cpu']}, "
                 f"{machine['nproc']} CPUs, one thread (NUMBA_NUM_THREADS=1); Python "
                 f"{machine['python']}, numpy {machine['numpy']}, numba {machine['numba']}, "
                 f"PyElastica {machine['pyelastica']}, rodphase {machine['rodphase']}. The "
                 f"process had {100 * machine['cpu_share']:.0f} % of a CPU over the run"
                 + (" (the machine was busy: timings are inflated)."
                    if machine["cpu_share"] < 0.95 else "."))
    why = ""
    if DAMPING > 20.0:
        why = (" (heavier than rodphase's scene defaults, so that both codes, PyElastica "
               "having no speed-dependent drag, hold the same plectoneme while timed; this "
               "choice predates the contact-thinning and contact time-step fixes, which cured "
               "the energy growth seen then at n ≥ 200 with 20/s)")
    elif DAMPING <= 2.0:
        why = (" (the damping of PyElastica's PlectonemesCase, ν = 2/s on velocities and "
               "4ν/a² on angular velocities, with no speed-dependent drag: the strands keep "
               "moving while timed, as in that example)")
    lines.append("")
    lines.append(
        f"Scene: L0 = {LENGTH:g} m, a = {RADIUS:g} m, E = {YOUNG:.0e} Pa, G = 2E/3, "
        f"ρ = {DENSITY:g} kg/m³; clamped at node 0, node n held laterally under "
        f"{LOAD_MULTIPLE:g} F_C along the axis and twisted on at 0.1 turns/s for "
        f"{TWIST_TIME:g} s; damping {DAMPING:g}/s on velocities and {ROTATIONAL_FACTOR:g} × "
        f"rodphase's automatic rotational damping, in both codes{why}. Both codes start from the "
        f"same plectoneme: rodphase's "
        f"twist_under_load ({SOURCE_ELEMENTS} elements, Φa = {SOURCE_TWIST_DENSITY}, "
        f"{source_info['turns']:.2f} turns; end rotation applied {source_info['end_rotation']:.12f}"
        f" rad, asked {source_info['asked_rotation']:.12f} rad; {source_info['contacts']} "
        f"touching pairs) resampled to n (positions by spline in the material coordinate, "
        f"directors from tangents with a parallel-transported d1 turned by the source's twist) "
        f"and relaxed {RELAX_TIME:g} s by rodphase at that n. Same dt in both, "
        f"{DT_FACTOR:g} × rodphase's stable bound with contact. Contact springs matched "
        f"(k = 10 E l0 per pair, dashpot √(k m)); PyElastica's shear stiffness set to 4GA/3. "
        f"CPU time, median of {args.repeats} timed runs of ≥ {args.seconds:g} s each "
        f"(PyElastica with contact ≥ 200 steps) after a warm-up run, the two codes' runs "
        f"interleaved.")
    lines.append("")
    lines.append("| n | dt [s] | touching pairs rodphase / PyElastica | rodphase no contact | "
                 "rodphase contact | PyElastica no contact | PyElastica contact | "
                 "speed-up no contact | speed-up contact |")
    lines.append("|---|---|---|---|---|---|---|---|---|")
    notes = []
    for row in rows:
        rp, pe = row["rp"], row["pe"]
        pe_no = pe.get(False, {}).get("us") if pe else None
        pe_c = pe.get(True, {}).get("us") if pe else None
        pairs = f"{rp[True]['contacts_median']:.0f} / " + (
            f"{pe[True]['touching']}" if pe else "—")
        lines.append(
            f"| {row['n']} | {row['dt']:.3g} | {pairs} | {_f(rp[False]['us'])} | "
            f"{_f(rp[True]['us'])} | {_f(pe_no)} | {_f(pe_c)} | "
            f"{_f(pe_no / rp[False]['us'] if pe_no else None)}× | "
            f"{_f(pe_c / rp[True]['us'] if pe_c else None)}× |")
        if row["note"]:
            notes.append(f"n = {row['n']}: {row['note']}.")
    lines.append("")
    lines.append("µs per step; speed-up = PyElastica / rodphase. Touching pairs: rodphase's "
                 "median over its timed runs (history `contacts`), PyElastica's counted at the "
                 "end of its timed runs with its own neighbour skip.")
    lines.append("")
    lines.append("Cost of n against 2n (ideal O(n): 2.0). Each element of a plectoneme touches "
                 "more elements of the other strand as elements get shorter than the radius, so "
                 "the number of touching pairs grows faster than n; its ratio is given with the "
                 "cost ratio:")
    lines.append("")
    lines.append("| n → 2n | rodphase no contact | rodphase contact | touching pairs (rodphase) | "
                 "PyElastica no contact | PyElastica contact |")
    lines.append("|---|---|---|---|---|---|")
    by_n = {row["n"]: row for row in rows + extra}
    for a in (150, 200):
        b = 2 * a
        if a not in by_n or b not in by_n:
            continue
        ra, rb = by_n[a], by_n[b]
        cells = [f"{rb['rp'][on]['us'] / ra['rp'][on]['us']:.2f}" for on in (False, True)]
        pa, pb = ra["rp"][True]["contacts_median"], rb["rp"][True]["contacts_median"]
        cells.append(f"{pb / pa:.2f} ({pa:.0f} → {pb:.0f})" if pa > 0 else "—")
        for on in (False, True):
            if ra["pe"] and rb["pe"]:
                cells.append(f"{rb['pe'][on]['us'] / ra['pe'][on]['us']:.2f}")
            else:
                cells.append("—")
        lines.append(f"| {a} → {b} | " + " | ".join(cells) + " |")
    lines.append("")
    if 150 in by_n and 400 in by_n:
        # issue #16's targets: >= 150x PyElastica at n = 150 with contact, n -> 2n <= 2.2x
        a, b = by_n[150]["rp"], by_n[400]["rp"]
        pa, pb = a[True]["contacts_median"], b[True]["contacts_median"]
        per_pair = [1e3 * (r[True]["us"] - r[False]["us"]) / max(p, 1) for r, p in ((a, pa), (b, pb))]
        speedup = (by_n[150]["pe"][True]["us"] / a[True]["us"]) if by_n[150]["pe"] else float("nan")
        lines.append(
            f"Targets (#16): n = 150 with contact {a[True]['us']:.1f} µs per step, "
            f"{speedup:.0f}× PyElastica (target ≥ 150×); n → 2n with contact in the table above "
            f"(target ≤ 2.2×). n = 400 against n = 150: {b[True]['us'] / a[True]['us']:.2f}× "
            f"with contact, {b[False]['us'] / a[False]['us']:.2f}× without, for {pb / pa:.2f}× "
            f"the touching pairs. Contact's share of a step per touching pair: "
            f"{per_pair[0]:.0f} ns at n = 150, {per_pair[1]:.0f} ns at n = 400.")
        lines.append("")
    if extra:
        lines.append("rodphase only (for the ratio): " + "; ".join(
            f"n = {r['n']}: {r['rp'][False]['us']:.1f} / {r['rp'][True]['us']:.1f} µs per step "
            f"without / with contact ({r['rp'][True]['contacts_median']:.0f} touching pairs), "
            f"dt = {r['dt']:.3g} s" for r in extra) + ".")
        lines.append("")
    if notes:
        lines += [*notes, ""]
    return "\n".join(lines)


def write_section(path: Path, section: str) -> None:
    if path.exists():
        text = path.read_text()
    else:
        text = "# Benchmarks\n\nMeasured numbers of rodphase; each section says how to reproduce it.\n"
    lines = text.splitlines()
    start = next((i for i, line in enumerate(lines) if line.strip() == SECTION), None)
    if start is None:
        new = text.rstrip("\n") + "\n\n" + section.rstrip("\n") + "\n"
    else:
        end = next((i for i in range(start + 1, len(lines)) if lines[i].startswith("## ")),
                   len(lines))
        head = "\n".join(lines[:start]).rstrip("\n")
        tail = "\n".join(lines[end:])
        new = (head + "\n\n" if head else "") + section.rstrip("\n") + "\n"
        if tail:
            new += "\n" + tail.rstrip("\n") + "\n"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(new)


DEFAULT_SETTINGS = (DAMPING, ROTATIONAL_FACTOR)  # the current figures' row is measured at these


def main(argv=None) -> int:
    global DAMPING, ROTATIONAL_FACTOR, SECTION
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--write", metavar="PATH", help="write/replace the section in this Markdown file")
    parser.add_argument("--quick", action="store_true", help="n = 50 and 150 only, one timed run each")
    parser.add_argument("--seconds", type=float, default=1.0, help="minimum CPU time of a timed run")
    parser.add_argument("--repeats", type=int, default=None, help="timed runs per configuration "
                        "(median reported; default 3, 1 with --quick)")
    parser.add_argument("--damping", type=float, default=DAMPING,
                        help="1/s on velocities in the timed runs (both codes)")
    parser.add_argument("--rotational-factor", type=float, default=ROTATIONAL_FACTOR,
                        help="factor on rodphase's automatic rotational damping (both codes)")
    parser.add_argument("--sizes", default=None,
                        help="comma-separated n to time against PyElastica (default 50,100,150,200,400)")
    args = parser.parse_args(argv)
    if (args.damping, args.rotational_factor) != (DAMPING, ROTATIONAL_FACTOR):
        # another damping is another table: its own section, so --write keeps both
        SECTION = (f"{SECTION}, damping {args.damping:g}/s, rotational "
                   f"{args.rotational_factor:g} × automatic")
    DAMPING, ROTATIONAL_FACTOR = args.damping, args.rotational_factor
    if args.repeats is None:
        args.repeats = 1 if args.quick else 3
    try:
        import elastica  # noqa: F401
    except ImportError:
        print("PyElastica is not installed: pip install -e '.[bench]'", file=sys.stderr)
        return 2

    def log(msg):
        print(msg, flush=True)

    wall0 = time.perf_counter()
    cpu0 = time.process_time()
    warnings.simplefilter("ignore")
    machine = machine_note()
    log("machine: " + ", ".join(f"{k} {v}" for k, v in machine.items()))
    log(f"plectoneme: twist_under_load, {SOURCE_ELEMENTS} elements, Φa = {SOURCE_TWIST_DENSITY} ...")
    positions, directors, source_info = make_plectoneme()
    log(f"  {source_info['status']}, {source_info['turns']:.3f} turns, end rotation applied "
        f"{source_info['end_rotation']:.12f} vs asked {source_info['asked_rotation']:.12f} rad "
        f"(error {source_info['end_rotation'] - source_info['asked_rotation']:.1e}), "
        f"{source_info['contacts']} touching pairs, end at z = {source_info['end_height']:.3f} m, "
        f"{source_info['sim_time']:.1f} s simulated in {source_info['wall']:.1f} s")
    if source_info["contacts"] == 0:
        log("  warning: the source shape has no contacts")
    source = (positions, directors)

    sizes = [50, 150] if args.quick else [50, 100, 150, 200, 400]
    only_rodphase = [300]
    if args.sizes:
        sizes, only_rodphase = [int(v) for v in args.sizes.split(",")], []
    rows, extra = [], []
    for n in sizes + only_rodphase:
        with_pe = n in sizes
        log(f"n = {n} ...")
        row = measure(n, source, args.seconds, args.repeats, log, with_pyelastica=with_pe)
        (rows if with_pe else extra).append(row)
        rp = row["rp"]
        log(f"  start: {row['start_contacts']} touching pairs (rodphase), "
            f"{row['start_contacts_pyelastica']} with PyElastica's neighbour skip")
        msg = (f"  dt = {row['dt']:.3g} s ({row['dt'] / row['bound']:.3g} × bound); rodphase "
               f"{rp[False]['us']:.1f} / {rp[True]['us']:.1f} µs/step without / with contact "
               f"[{_spread(rp[False])} / {_spread(rp[True])}] ({rp[True]['steps']} steps, touching pairs median {rp[True]['contacts_median']:.0f}"
               f", final {rp[True]['contacts_final']}, Verlet-list pairs {rp[True]['candidates']}, "
               f"{rp[True]['rebuilds']} grid / {rp[True]['near_rebuilds']} near-list rebuilds; end rotation {rp[True]['end_rotation']:.12f} "
               f"vs asked {rp[True]['asked_rotation']:.12f} rad)")
        if with_pe:
            pe = row["pe"]
            msg += (f"; PyElastica {pe[False]['us']:.1f} / {pe[True]['us']:.1f} µs/step "
                    f"[{_spread(pe[False])} / {_spread(pe[True])}] "
                    f"({pe[True]['steps']} steps, {pe[True]['touching']} touching pairs at the end)")
        log(msg)

    total = time.perf_counter() - wall0
    # a single-threaded benchmark should have the CPU to itself: below ~95 % it was sharing
    machine["cpu_share"] = (time.process_time() - cpu0) / total
    machine["load"] = _load()
    if machine["cpu_share"] < 0.95:
        log(f"warning: this process got {100 * machine['cpu_share']:.0f} % of a CPU over the run "
            f"(load average now {machine['load']}): other work was running, timings are inflated")
    text = report(machine, source_info, rows, extra, args, total)
    print()
    print(text)
    if args.write:
        write_section(Path(args.write), text)
        log(f"wrote the section to {args.write}")
        at150 = [r for r in rows if r["n"] == 150] if (DAMPING, ROTATIONAL_FACTOR) == (
            DEFAULT_SETTINGS) else []
        if at150:  # the headline row of the current figures
            from rodphase.studytools import record_current

            rp, pe = at150[0]["rp"], at150[0]["pe"]
            record_current("step_cost_vs_pyelastica", (
                f"with self-contact {rp[True]['us']:.1f} µs (PyElastica {pe[True]['us']:.1f} µs: "
                f"{pe[True]['us'] / rp[True]['us']:.0f}×); without {rp[False]['us']:.1f} µs "
                f"(PyElastica {pe[False]['us']:.1f} µs: {pe[False]['us'] / rp[False]['us']:.1f}×)"),
                source="`make bench-kernel`")
    log(f"total {total:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
