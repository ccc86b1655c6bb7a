"""Cross-check rodphase against the authors' own code: PyElastica's self-contact examples.

The settings are those of GazzolaLab/PyElastica (commit 024194e0959f85a22710acffb8a69e7fbf009018)

    examples/RodContactCase/RodSelfContact/SolenoidsCase/solenoid_case.py
    examples/RodContactCase/RodSelfContact/PlectonemesCase/plectoneme_case.py

re-expressed here (the settings carry over, the code is written anew) for PyElastica 1.0.

    python studies/crosscheck_pyelastica.py reference solenoid     # ~20-60 min on one core
    python studies/crosscheck_pyelastica.py reference plectoneme   # ~1 h on one core
    python studies/crosscheck_pyelastica.py rodphase solenoid      # minutes
    python studies/crosscheck_pyelastica.py compare solenoid       # table + docs/img/crosscheck_solenoid.png
    python studies/crosscheck_pyelastica.py fig3 2.5577 1.0525     # a Fig 3 point from rest (minutes)

`reference` keeps every 0.05 s frame in /tmp/crosscheck_raw_CASE.npz (MBs) and writes the
reduced record tests/data/crosscheck_CASE.npz (0.5 s samples, final shape; < 300 kB).
`reduce CASE` redoes the reduction from the raw file. Run with NUMBA_NUM_THREADS=1.
`--final-time T` stops `reference` and `rodphase` at T seconds (tests/test_studies_smoke.py
runs the first moments of each).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

if __name__ == "__main__":
    # one thread per process for the benchmarks; not when a test imports this module, where
    # changing numba's thread count after its pool started breaks every later parallel call
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")
    os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np
from numba import njit

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data"
IMG = ROOT / "docs" / "img"
sys.path.insert(0, str(Path(__file__).resolve().parent))

SOURCE_COMMIT = "024194e0959f85a22710acffb8a69e7fbf009018"
SOURCE = {
    "solenoid": "examples/RodContactCase/RodSelfContact/SolenoidsCase/solenoid_case.py",
    "plectoneme": "examples/RodContactCase/RodSelfContact/PlectonemesCase/plectoneme_case.py",
}

# ------------------------------------------------------------------ the examples' settings
# Every number as the example file states it (derived values in the comments).
BASE_LENGTH = 1.0
BASE_RADIUS = 0.025
MASS = 1.0  # kg -> density = mass / (pi a^2 L) = 509.3 kg/m^3
E = 1e6
POISSON = 0.5  # shear_modulus = E / (poisson + 1) = 2E/3
CONTACT_K = 1e4  # RodSelfContact(k=1e4, nu=10)
CONTACT_NU = 10.0
KICK = 1e-4  # velocity_collection[2, n_elem // 2] -= 1e-4, every step of the twist
# the SolenoidsCase end's rate as run, over the nominal 0.2 turns/s: the damper's
# exp(-2 dt 3200)^e per step (tests/data/crosscheck_solenoid.npz: 1.0403781 rad/s from 10 s)
AS_RUN_RATE = 0.8279066

CASES = {
    "solenoid": dict(
        turns=13, time_start_twist=10.0, time_twist=5.0 * 13, time_relax=50.0,
        n_elem=100, force=300.0, initial_kick=False,
    ),
    "plectoneme": dict(
        turns=10, time_start_twist=0.0, time_twist=5.0 * 10, time_relax=50.0,
        n_elem=150, force=0.0, initial_kick=True,
    ),
    # Fig 4a through the authors' code (issue #49): the SolenoidsCase with its 13 turns
    # actually put in (the end frame prescribed during the twist, so the damper cannot eat
    # 2 of them), held 10 s, then the end pulled 0.4 m at 5 mm/s with its frame held, as
    # rodphase's solenoid_loss scene pulls. Not an example of PyElastica's: its own settings
    # (n, dt, contact, damping, 300 N) with the paper's pull appended.
    "solenoid_pull": dict(
        turns=13, time_start_twist=10.0, time_twist=5.0 * 13, time_relax=10.0,
        n_elem=100, force=300.0, initial_kick=False,
        prescribed_twist=True, pull_distance=0.4, pull_rate=0.005,
    ),
    # the same at rodphase's Fig 4a twist, Φa = 1.6: 10.19 turns (rodphase's side of
    # `reference solenoid_pull --turns 10.19`)
    "solenoid_pull_10": dict(
        turns=10.19, time_start_twist=10.0, time_twist=5.0 * 10.19, time_relax=10.0,
        n_elem=100, force=300.0, initial_kick=False,
        prescribed_twist=True, pull_distance=0.4, pull_rate=0.005,
    ),
}


def settings(case: str) -> dict:
    c = dict(CASES[case])
    c.setdefault("prescribed_twist", False)
    c.setdefault("pull_distance", 0.0)
    c.setdefault("pull_rate", 1.0)
    c["time_pull"] = c["pull_distance"] / c["pull_rate"]
    c["final_time"] = c["time_start_twist"] + c["time_twist"] + c["time_relax"] + c["time_pull"]
    n = c["n_elem"]
    c["dt_nominal"] = 0.0025 * BASE_LENGTH / n
    c["total_steps"] = int(c["final_time"] / c["dt_nominal"])
    c["dt"] = c["final_time"] / c["total_steps"]
    area = math.pi * BASE_RADIUS**2
    c["density"] = MASS / (area * BASE_LENGTH)
    c["damping_constant"] = 2.0 / c["density"] / area  # "nu" of the example: = 2.0 1/s
    c["shear_modulus"] = E / (POISSON + 1.0)
    c["rate_turns_per_s"] = c["turns"] / c["time_twist"]
    return c


# ------------------------------------------------------------------ PyElastica reference


def run_reference(case: str, final_time: float | None, frame_interval: float, raw: Path,
                  thinning: float = 0.0, contact_from: float = 0.0,
                  dt_override: float | None = None, prescribe_twist: float | None = None,
                  contact_split: bool = False, turns: float | None = None,
                  kick_shape: str = "point") -> None:
    """The case in PyElastica 1.0; `thinning` 1.0 adds rodphase's thinning force to the
    self-contact (studies/pyelastica_thinning.py), 0.0 is the example's RodSelfContact.
    `contact_from` > 0 skips the contact loop while the rod is straight (its force is then
    exactly zero; the pairs within reach at the switch-on are printed and stored).
    `dt_override` replaces the example's step (the damper is exact per step, whatever the step; the
    twist-phase kick, a velocity taken off every step, is scaled by dt/dt_example so that it
    stays the same 0.04 N point force). `prescribe_twist` F turns the end frame at exactly F
    times the nominal rate during the twist (F = AS_RUN_RATE reproduces the example's damped
    rate, which a larger step would damp further), then the example's snap to the final frame."""
    import elastica as ea
    from elastica._rotations import _get_rotation_matrix

    from rodphase.studytools import machine

    c = settings(case)
    c["thinning"] = thinning
    c["contact_from"] = contact_from
    c["contact_split"] = contact_split
    if turns is not None:  # at the same rate: the twist takes 5 s per turn, as the example's
        c["turns"] = float(turns)
        c["time_twist"] = 5.0 * float(turns)
        c["final_time"] = c["time_start_twist"] + c["time_twist"] + c["time_relax"] + c["time_pull"]
    if final_time is not None:
        c["final_time_requested"] = c["final_time"]
        c["final_time"] = float(final_time)
    n = c["n_elem"]
    dt = c["dt"]  # the example steps with final_time / total_steps (of its full run)
    kick = KICK
    # rodphase's stand-in for the point kick (build_problem): a uniform lateral acceleration
    # with the same first-mode projection, (π/2)·F/M, F = m_node·KICK/dt the point force
    uniform_kick = (math.pi / 2) * (MASS / c["n_elem"] * KICK / dt) / MASS
    c["kick_shape"] = kick_shape
    if dt_override is not None:
        kick = KICK * dt_override / dt
        dt = c["dt"] = float(dt_override)
        c["kick_velocity_per_step"] = kick
    steps = int(round(c["final_time"] / dt))
    every = max(1, int(round(frame_interval / dt)))

    class Sim(ea.BaseSystemCollection, ea.Constraints, ea.Contact, ea.Forcing,
              ea.CallBacks, ea.Damping):
        pass

    sim = Sim()
    y = np.array([0.0, 1.0, 0.0])
    rod = ea.CosseratRod.straight_rod(
        n, np.zeros(3), y, np.array([0.0, 0.0, 1.0]), BASE_LENGTH, BASE_RADIUS,
        c["density"], youngs_modulus=E, shear_modulus=c["shear_modulus"])
    if c["initial_kick"]:
        rod.velocity_collection[2, n // 2] -= KICK
    sim.append(rod)
    sim.dampen(rod).using(ea.AnalyticalLinearDamper, damping_constant=c["damping_constant"],
                          time_step=dt if dt_override is not None else c["dt_nominal"])

    t0, tt, turns = c["time_start_twist"], c["time_twist"], c["turns"]
    prescribed = c["prescribed_twist"] or prescribe_twist is not None
    rate_factor = 1.0 if prescribe_twist is None else float(prescribe_twist)
    c["twist_rate_factor"] = rate_factor
    t_pull, pull_rate = t0 + tt + c["time_relax"], c["pull_rate"]
    pulled = c["pull_distance"] > 0

    class TwistEnd(ea.ConstraintBase):
        """Start clamped; end free before the twist, sliding along y and spun during it,
        clamped at the final frame after it (the examples' SelonoidsBC)."""

        def __init__(self, position_start, position_end, director_start, director_end, **kw):
            super().__init__(**kw)
            theta = 2.0 * turns * np.pi
            axis = director_end @ (-(position_end - position_start)
                                   / np.linalg.norm(position_end - position_start))
            axis /= np.linalg.norm(axis)
            self.final_end = _get_rotation_matrix(-theta, axis.reshape(3, 1)).reshape(3, 3) @ director_end
            self.ang_vel = theta / tt * axis
            self.axis = axis.reshape(3, 1)
            self.Q_end0 = director_end.copy()
            self.x0 = position_start.copy()
            self.Q0 = director_start.copy()
            self.y_pull0 = None

        def constrain_values(self, system, time):
            if pulled and time > t_pull:
                # the pull: the end's axial position prescribed, its frame held
                if self.y_pull0 is None:
                    self.y_pull0 = float(system.position_collection[1, -1])
                system.position_collection[1, -1] = self.y_pull0 + pull_rate * (time - t_pull)
            if time > tt + t0:
                system.position_collection[..., 0] = self.x0
                system.position_collection[0, -1] = 0.0
                system.position_collection[2, -1] = 0.0
                system.director_collection[..., 0] = self.Q0
                system.director_collection[..., -1] = self.final_end
            elif prescribed and time >= t0:
                # the end frame turned by exactly the nominal angle so far: the damper
                # (which scales the end's omega after the constraint) cannot eat twist
                angle = rate_factor * 2.0 * turns * np.pi * (time - t0) / tt
                system.director_collection[..., -1] = (
                    _get_rotation_matrix(-angle, self.axis).reshape(3, 3) @ self.Q_end0)

        def constrain_rates(self, system, time):
            system.velocity_collection[..., 0] = 0.0
            system.omega_collection[..., 0] = 0.0
            if time > tt + t0:
                system.velocity_collection[..., -1] = 0.0
                system.omega_collection[..., -1] = 0.0
                if pulled and time > t_pull:
                    system.velocity_collection[1, -1] = pull_rate
            elif time >= t0:
                system.velocity_collection[0, -1] = 0.0
                system.velocity_collection[2, -1] = 0.0
                system.omega_collection[..., -1] = -self.ang_vel
                if kick_shape == "uniform":
                    system.velocity_collection[2, 1:-1] -= uniform_kick * dt
                else:
                    system.velocity_collection[2, system.n_elems // 2] -= kick

    sim.constrain(rod).using(TwistEnd, constrained_position_idx=(0, -1),
                             constrained_director_idx=(0, -1))
    if c["force"]:
        sim.add_forcing_to(rod).using(ea.EndpointForces, np.zeros(3), c["force"] * y,
                                      ramp_up_time=t0 - 1)
    contact_holder = {}
    if thinning or contact_from > 0 or contact_split:
        class Gated(thinning_self_contact()):  # keeps a handle on the instance PyElastica makes
            def __init__(self, *a, **kw):
                super().__init__(*a, **kw)
                contact_holder["contact"] = self

        sim.detect_contact_between(rod, rod).using(Gated, k=CONTACT_K, nu=CONTACT_NU,
                                                   thinning=thinning, active_from=contact_from,
                                                   split=contact_split)
    else:
        sim.detect_contact_between(rod, rod).using(ea.RodSelfContact, k=CONTACT_K, nu=CONTACT_NU)

    # the end node's internal and external force at each frame: with the end held, the
    # force the puller must apply is −(internal + contact) along the axis
    frames = {"time": [], "x": [], "d1": [], "omega_end": [], "internal_end": [], "external_end": []}

    class Record(ea.CallBackBaseClass):
        def make_callback(self, system, time, current_step):
            if current_step % every == 0:
                frames["time"].append(time)
                frames["x"].append(system.position_collection.T.copy())
                frames["d1"].append(system.director_collection[0].T.copy())
                frames["omega_end"].append(system.omega_collection[:, -1].copy())
                frames["internal_end"].append(system.internal_forces[:, -1].copy())
                frames["external_end"].append(system.external_forces[:, -1].copy())

    sim.collect_diagnostics(rod).using(Record)
    sim.finalize()

    info = {"case": case, "settings": c, "machine": machine(), "elastica": "1.0.0",
            "source": f"GazzolaLab/PyElastica@{SOURCE_COMMIT}:{SOURCE.get(case, SOURCE['solenoid'])}",
            "frame_interval": every * dt, "steps": steps}

    def save(done: bool) -> None:
        info["cpu_time"] = time.process_time() - cpu0
        info["wall_time"] = time.perf_counter() - wall0
        info["finished"] = done
        if "contact" in contact_holder:
            info["pairs_at_contact_switch_on"] = contact_holder["contact"].pairs_at_switch_on
        np.savez(raw, time=np.array(frames["time"]), x=np.array(frames["x"]),
                 d1=np.array(frames["d1"]), omega_end=np.array(frames["omega_end"]),
                 internal_end=np.array(frames["internal_end"]),
                 external_end=np.array(frames["external_end"]), info=json.dumps(info))

    stepper = ea.PositionVerlet()
    t = np.float64(0.0)
    cpu0, wall0 = time.process_time(), time.perf_counter()
    next_report, next_save = 1.0, 10.0
    print(f"{case}: n={n} dt={dt:.6g} steps={steps} frames every {every} steps; "
          f"{machine()['cpu']}", flush=True)
    for i in range(steps):
        t = stepper.step(sim, t, dt)
        if t >= next_report - 0.5 * dt:
            next_report += 1.0
            x = rod.position_collection
            v = np.abs(rod.velocity_collection).max()
            if not (np.all(np.isfinite(x)) and np.isfinite(v)):
                print(f"t={t:.2f} non-finite state: stop", flush=True)
                save(False)
                return
            print(f"t={t:7.2f} s  cpu={time.process_time() - cpu0:8.1f} s  "
                  f"end=({x[0, -1]:+.4f},{x[1, -1]:+.4f},{x[2, -1]:+.4f})  max|v|={v:.3g}",
                  flush=True)
            if t >= next_save - 0.5 * dt:
                next_save += 10.0
                save(False)
    save(True)
    print(f"done: cpu {info['cpu_time']:.0f} s, wall {info['wall_time']:.0f} s -> {raw}", flush=True)


# ------------------------------------------------------------------ PyElastica's self-contact, + thinning
# rodphase's contact (rod/contact.py, `thinning`) adds the rest of the gradient of ½kδ² for an
# incompressible rod: δ = a_i + a_j − d depends on the element lengths through the radii
# a = a0·√(l0/l), so ∂δ/∂l = −a/(2l), and a touching pair pushes the two nodes of each of its
# elements apart along it by k·δ·a/(2l). PyElastica 1.0 thins its radius too
# (cosserat_rod.py: radius = √(volume/length/π)) but its _calculate_contact_forces_self_rod
# keeps the normal force only. The loop below is PyElastica's own (same skip, bounding test,
# closest points, 4/3–2/3 split at the ends, unclipped dashpot), written anew in scalars:
# with thinning 0 it gives PyElastica's forces bit for bit (tests/test_crosscheck_pyelastica.py)
# at 1/7 of the cost, since PyElastica's allocates 3-vectors in every pair's test.
# `reference --thinning 1` runs the example with the term added (issue #49).

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
    # and the closest points' places along segment i (t) and segment j (s), in [0, 1]
    return (x20 + s * e20 - x10 - t * e10, x21 + s * e21 - x11 - t * e11,
            x22 + s * e22 - x12 - t * e12, t, s)


@njit(cache=True)
def self_contact_with_thinning(x, radius, length, tangent, velocity, external_forces,
                               contact_k, contact_nu, thinning, split=False):
    """PyElastica's self-contact force plus `thinning` × k·γ·a/(2l) along each touching
    element (x: the n element start points (3, n); velocity, external_forces (3, n+1)).
    With thinning 0 its forces equal PyElastica's bit for bit (tests/test_crosscheck_pyelastica.py)."""
    n = x.shape[1]
    edge = length * tangent  # PyElastica's _batch_product_k_ik_to_ik, the same products
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
            d0, d1, d2, ti, sj = _closest(x, edge, i, j)
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
            if split:
                # rodphase's split: the pair's force (2 net per element) at the closest points,
                # (1 − t, t) between each element's nodes, so that the spring is the gradient
                # of ½kγ² in the node positions (PyElastica's equal split is not)
                external_forces[0, i] -= 2.0 * (1.0 - ti) * net0
                external_forces[1, i] -= 2.0 * (1.0 - ti) * net1
                external_forces[2, i] -= 2.0 * (1.0 - ti) * net2
                external_forces[0, i + 1] -= 2.0 * ti * net0
                external_forces[1, i + 1] -= 2.0 * ti * net1
                external_forces[2, i + 1] -= 2.0 * ti * net2
                external_forces[0, j] += 2.0 * (1.0 - sj) * net0
                external_forces[1, j] += 2.0 * (1.0 - sj) * net1
                external_forces[2, j] += 2.0 * (1.0 - sj) * net2
                external_forces[0, j + 1] += 2.0 * sj * net0
                external_forces[1, j + 1] += 2.0 * sj * net1
                external_forces[2, j + 1] += 2.0 * sj * net2
            elif i == n - 1:
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
            if split:
                pass
            elif j == 0:
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
    edge = length * tangent  # PyElastica's _batch_product_k_ik_to_ik, the same products
    count = 0
    for i in range(n):
        skip = int(1 + np.ceil(0.8 * np.pi * radius[i] / length[i]))
        for j in range(i - skip, -1, -1):
            d0, d1, d2, _, _ = _closest(x, edge, i, j)
            if np.sqrt(d0 * d0 + d1 * d1 + d2 * d2) < radius[i] + radius[j] + margin:
                count += 1
    return count



def thinning_self_contact():
    """`ThinningSelfContact`, made when PyElastica is imported (the bench extra): its
    `RodSelfContact(k, nu)` with the pair loop above, plus the thinning force (`thinning` 1.0
    as rodphase's incompressible rod; 0.0 gives PyElastica's force bit for bit), acting from
    `active_from` seconds on.

    Before a twisted rod buckles no pair is within reach and the contact force is exactly
    zero, but PyElastica still pays its O(n²) pair loop every step. `active_from` skips that
    loop while the rod is straight; at the switch-on the pairs within reach + a/10 are counted
    and printed, and must be 0 for the run to equal one with contact throughout."""
    import elastica as ea

    class ThinningSelfContact(ea.RodSelfContact):
        def __init__(self, k: float, nu: float, thinning: float = 1.0, active_from: float = 0.0,
                     split: bool = False) -> None:
            super().__init__(k, nu)
            self.thinning = float(thinning)
            self.split = bool(split)
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
                self.k, self.nu, self.thinning, self.split)

    return ThinningSelfContact


def end_rotation(t, d1_end, omega_end, axis=np.array([0.0, 1.0, 0.0])):
    """Unwrapped angle (rad) of the end frame's d1 about `axis`, from frames close enough
    (≤ 0.05 turns apart) to unwrap."""
    d = d1_end - np.sum(d1_end * axis, axis=1)[:, None] * axis
    ref = d[0] / np.linalg.norm(d[0])
    other = np.cross(axis, ref)
    phi = np.unwrap(np.arctan2(d @ other, d @ ref))
    return phi - phi[0]


def reduce_reference(case: str, raw: Path, out: Path, sample: float = 0.5) -> None:
    from rodphase.topology import topology_history

    r = np.load(raw)
    info = json.loads(str(r["info"]))
    t, X, D = r["time"], r["x"], r["d1"]
    rot = end_rotation(t, D[:, -1], r["omega_end"])
    stride = max(1, int(round(sample / info["frame_interval"])))
    idx = np.arange(0, len(t), stride)
    if idx[-1] != len(t) - 1:
        idx = np.append(idx, len(t) - 1)
    lk, tw, wr = topology_history(X[idx], D[idx])
    forces = {}
    if "internal_end" in r.files:  # every raw frame: a force drop can be short
        forces = {"force_time": t, "internal_end": r["internal_end"],
                  "external_end": r["external_end"], "end_position_all": X[:, -1, :]}
    np.savez_compressed(
        out, time=t[idx], end_rotation=rot[idx], link=lk, twist=tw, writhe=wr,
        end_position=X[idx, -1, :], final_positions=X[-1], final_d1=D[-1],
        info=json.dumps(info), **forces)
    print(f"wrote {out} ({out.stat().st_size / 1e3:.0f} kB, {len(idx)} samples); "
          f"final Lk={lk[-1]:.3f} Tw={tw[-1]:.3f} Wr={wr[-1]:.3f}, "
          f"end rotation {rot[-1] / (2 * np.pi):.3f} turns")


# ------------------------------------------------------------------ rodphase

# rodphase runs along +z; PyElastica's examples along +y. The cyclic relabelling
# (x, y, z)_rodphase = (z, x, y)_PyElastica is a proper rotation that takes PyElastica's
# initial frame (d1 = z, d2 = x, d3 = y) to rodphase's straight_state (d1 = x, d2 = y, d3 = z).
def to_pyelastica(p):
    """(..., 3) rodphase coordinates -> PyElastica's."""
    p = np.asarray(p)
    return p[..., [1, 2, 0]]


def contact_mapping(case: str) -> dict:
    """PyElastica's RodSelfContact(k, nu) in rodphase's units.

    PyElastica (elastica/_contact_functions.py, _calculate_contact_forces_self_rod): for each
    pair of elements (i, j) with i - j >= skip = 1 + ceil(0.8 pi a / l) whose capsules
    overlap by gamma > 0, a force k*gamma + nu*(dv . n) along the line of closest approach,
    half on each node of each element: k [N/m] and nu [N s/m] are per PAIR, not per length.
    rodphase (rod/simulate.py _rod_arrays, rod/contact.py): pair spring k = stiffness*E*l0,
    dashpot c = 2*damping_ratio*sqrt(k*m_e), m_e = rho*A*l0; pairs with j > i + ceil(exclusion*a/l0).
    So stiffness = k/(E l0), damping_ratio = nu/(2 sqrt(k m_e)), exclusion = 0.8 pi.
    """
    c = settings(case)
    l0 = BASE_LENGTH / c["n_elem"]
    m_e = c["density"] * math.pi * BASE_RADIUS**2 * l0
    return {"stiffness": CONTACT_K / (E * l0),
            "damping_ratio": CONTACT_NU / (2.0 * math.sqrt(CONTACT_K * m_e)),
            "exclusion": 0.8 * math.pi}


def rotational_damping_equivalent(case: str) -> float:
    """PyElastica's deprecated damping_constant protocol scales omega by
    exp(-nu dt m_e / J) per step: a rate nu*A/I = 4 nu / a^2 about d1, d2 and half of it
    about d3 (J3 = 2 J1), which is exactly rodphase's solver.rotational_damping convention."""
    return 4.0 * settings(case)["damping_constant"] / BASE_RADIUS**2


def rodphase_sets(case: str, contact: str, dt: str, rotation_damping: str,
                  bodies: str = "none") -> list[tuple[str, object]]:
    """The --set keys (SCENE_SCHEMA) of twist_under_load that carry the example's settings."""
    c = settings(case)
    sets = [("rod.elements", c["n_elem"]), ("rod.density", c["density"]),
            ("rod.imperfection", 0.0), ("material.youngs_modulus", E),
            ("material.shear_modulus", c["shear_modulus"]),
            ("loading.force_multiple", None), ("loading.twist_density", None),
            ("loading.force", c["force"]), ("loading.force_ramp_time", max(c["time_start_twist"] - 1, 1.0)),
            ("loading.twist_turns", float(c["turns"])), ("loading.twist_rate", c["rate_turns_per_s"]),
            ("physics.self_contact", True), ("physics.friction", 0.0),
            ("ends.start_body", bodies), ("ends.end_body", bodies),
            ("solver.damping", c["damping_constant"]), ("solver.quadratic_drag", 0.0),
            # PyElastica's contact dashpot is explicit and its rod has no internal viscosity;
            # the scene's implicit dashpot and strain-rate damping are rodphase's own
            ("contact.dashpot", "explicit"), ("solver.strain_rate_damping", 0.0),
            ("solver.hold_until", "time"), ("solver.hold_max_time", c["time_relax"]),
            ("output.history_interval", 0.1)]
    if contact == "example":
        m = contact_mapping(case)
        sets += [("contact.stiffness", m["stiffness"]), ("contact.damping_ratio", m["damping_ratio"]),
                 ("contact.exclusion", m["exclusion"])]
    elif contact != "rodphase":
        for item in contact.split(","):  # e.g. "stiffness=15,damping_ratio=0.6"
            key, value = item.split("=")
            sets.append((f"contact.{key}", float(value)))
    if dt == "example":
        sets.append(("solver.dt", c["dt"]))
    elif dt != "auto":
        sets.append(("solver.dt", float(dt)))
    if rotation_damping == "example":
        sets.append(("solver.rotational_damping", rotational_damping_equivalent(case)))
    elif rotation_damping != "auto":
        sets.append(("solver.rotational_damping", float(rotation_damping)))
    return sets


def reference_rotation(case: str, path: Path | None = None):
    """(times, rad) of the end rotation PyElastica actually applied, from the stored
    reference (0.5 s samples: the rotation is linear in time during the twist, so
    interpolating them is exact up to the one-step snap at the end of the twist)."""
    ref = np.load(path or DATA / f"crosscheck_{case}.npz")
    return ref["time"], ref["end_rotation"]


def build_problem(case: str, sets, twist: str, kick: str, kick_scale: float = 1.0,
                  reference: Path | None = None):

    from rodphase import config as C
    from rodphase import scenes
    from rodphase.rod import Controls, Ends, Stage, constant, ramp

    cfg = C.load_scene("twist_under_load", sets, registered=scenes.SCENES)
    problem = scenes.twist_under_load(cfg)
    problem.rest_curvature = None  # PyElastica's rod is perfectly straight
    c = settings(case)
    n = c["n_elem"]
    turn = 2 * math.pi
    t0, tt, force = c["time_start_twist"], c["time_twist"], c["force"]
    # the twist-phase kick: velocity_collection[2, n//2] -= 1e-4 every step is a point force
    # m_node*1e-4/dt (0.04 N) along -z of PyElastica (-x here); rodphase has no point force,
    # so a uniform load with the same projection on the first mode, (pi/2)*F/M
    point = c["density"] * math.pi * BASE_RADIUS**2 * (BASE_LENGTH / n) * KICK / c["dt"]
    g = (-(math.pi / 2) * point / MASS * kick_scale, 0.0, 0.0) if kick == "load" else (0.0, 0.0, 0.0)
    if c["initial_kick"] and kick != "none":
        problem.state.v[0, n // 2] -= KICK
    if twist == "as-run":
        tr, rot = reference_rotation(case, reference)
        keep = (tr >= t0) & (tr <= t0 + tt + 1e-9)
        ts, vs = list(tr[keep] - t0), list(rot[keep])
        if ts[-1] < tt:  # to the end of the twist at the last sampled rate
            vs.append(vs[-1] + (vs[-1] - vs[-2]) / (ts[-1] - ts[-2]) * (tt - ts[-1]))
            ts.append(tt)
        table = (tuple(ts), tuple(vs))
        final = vs[-1]
        # after the twist PyElastica sets the end frame to R(-2 pi turns) Q_end: the
        # nearest whole turn, reached in one step
        final_turns = round(final / turn)
        final = turn * final_turns
    else:
        table = ramp(0.0, tt, 0.0, turn * c["turns"])
        final = turn * c["turns"]
    # PyElastica has nothing beyond the clamped ends ("none"); rodphase's default ("rod")
    # fixes them to holder cylinders that take part in contact
    base = dict(start_held=(True,) * 3, start_frame_held=True, axis=(0.0, 0.0, 1.0),
                start_body=cfg.ends.start_body == "rod", end_body=cfg.ends.end_body == "rod",
                body_radius=cfg.ends.body_radius)
    free = Ends(end_held=(False,) * 3, end_frame_held=False, **base)
    sliding = Ends(end_held=(True, True, False), end_frame_held=True, **base)
    clamped = Ends(end_held=(True, True, True), end_frame_held=True, **base)
    stages = []
    if t0 > 0:
        ramp_time = t0 - 1
        stages += [Stage(ramp_time, label="load", ends=free,
                         controls=Controls(end_force=ramp(0, ramp_time, 0, force))),
                   Stage(1.0, label="hold load", ends=free, controls=Controls(end_force=constant(force)))]
    stages += [Stage(tt, label="twist", ends=sliding,
                     controls=Controls(end_force=constant(force), end_rotation=table, gravity=g)),
               Stage(c["time_relax"], label="relax", ends=clamped,
                     controls=Controls(end_force=constant(force), end_rotation=constant(final)))]
    if c["pull_distance"] > 0:
        # Fig 4a (case solenoid_pull): the end pulled at a steady rate, its frame held; the
        # stage holds the end where it finds it, and its reaction is the history's end_force
        stages.append(Stage(c["time_pull"], label="pull", ends=clamped, controls=Controls(
            end_rotation=constant(final),
            end_displacement=ramp(0, c["time_pull"], 0, c["pull_distance"]))))
    problem.stages = tuple(stages)
    problem.ends = sliding
    return problem


def stop_at(problem, final_time: float):
    """The problem with its protocol cut at `final_time` seconds (the stages up to it, the
    last one shortened): a smoke test runs the first moments of a case."""
    import dataclasses

    stages, start = [], 0.0
    for stage in problem.stages:
        if start >= final_time:
            break
        stages.append(dataclasses.replace(stage, duration=min(stage.duration, final_time - start)))
        start += stage.duration
    problem.stages = tuple(stages)
    return problem


def pyelastica_clamp_sets(case: str) -> list[tuple[str, object]]:
    """The example's clamps, emulated in rodphase without touching its kernel (issue #49).

    PyElastica prescribes the end elements' frames (and the end nodes): its first and last
    elements are rigid, and the rod bends and twists only between nodes 1 and n-1. rodphase
    clamps the frame at the end nodes themselves (a spring over half an element), so all of
    its n elements deform. The rod that deforms in PyElastica is therefore emulated by a
    rodphase rod two elements shorter at the same element length (n-2 elements, L - 2 L/n),
    whose clamps sit where PyElastica's second and last-but-one nodes are; its end lies
    one stretched element short of PyElastica's end node at each end, 2 l e in all
    (`clamp_end_offset`)."""
    c = settings(case)
    n = c["n_elem"]
    return [("rod.elements", n - 2), ("rod.length", BASE_LENGTH * (n - 2) / n)]


def run_rodphase(case: str, contact: str, dt: str, twist: str, kick: str, rotation_damping: str,
                 out: Path, bodies: str = "none", kick_scale: float = 1.0,
                 reference: Path | None = None, final_time: float | None = None,
                 extra_sets=(), clamp: str = "rodphase") -> dict:
    """The case in rodphase; `extra_sets` ((key, value) pairs of SCENE_SCHEMA) go on top of
    the mapped settings, and `clamp` "pyelastica" emulates the example's clamps
    (`pyelastica_clamp_sets`)."""
    from rodphase import classify
    from rodphase.runner import run
    from rodphase.studytools import machine
    from rodphase.topology import topology_history

    sets = rodphase_sets(case, contact, dt, rotation_damping, bodies)
    if clamp == "pyelastica":
        sets += pyelastica_clamp_sets(case)
    sets += list(extra_sets)
    problem = build_problem(case, sets, twist, kick, kick_scale, reference)
    if final_time is not None:
        problem = stop_at(problem, final_time)
    cpu0 = time.process_time()
    result = run(problem, topology=True)
    cpu = time.process_time() - cpu0
    h = result.history
    X = result.snapshot_positions
    D = result.snapshot_d1
    # the reference's estimator (nodes + d1 of the elements, no clamp half-elements)
    lk, tw, wr = topology_history(X, D) if len(X) else (np.zeros(0),) * 3
    al = classify.alignment(result.positions, BASE_RADIUS, rest_length=BASE_LENGTH)
    d = result.diagnostics
    info = {"case": case, "sets": [[k, v] for k, v in sets], "twist": twist, "kick": kick, "kick_scale": kick_scale,
            "contact": contact, "bodies": bodies, "rotational_damping": rotation_damping,
            "clamp": clamp,
            "status": result.status, "message": result.message, "cpu_time": cpu,
            "dt": d["dt"], "dt_bound": d["dt_bound"], "steps": d["steps"],
            "us_per_step": d["us_per_step"], "max_pairs": d.get("max_pairs"),
            "max_penetration": d.get("max_penetration"), "guard": d.get("guard"),
            "final_time": d.get("final_time"), "notes": d.get("notes"),
            "alignment": al, "phase": classify.phase(al), "machine": machine()}
    np.savez_compressed(
        out, time=h["time"], end_rotation=h["end_rotation"], link=lk, twist=tw, writhe=wr,
        link_rodphase=h.get("link", np.zeros(0)), twist_rodphase=h.get("twist", np.zeros(0)),
        writhe_rodphase=h.get("writhe", np.zeros(0)), contacts=h["contacts"],
        penetration=h["penetration"], kinetic=h["kinetic_energy"], end_force=h["end_force"],
        end_displacement=h["end_displacement"], stage=h["stage"],
        end_position=to_pyelastica(X[:, -1]) if len(X) else np.zeros((0, 3)),
        final_positions=to_pyelastica(result.positions),
        final_d1=to_pyelastica(result.directors[:, 0]), info=json.dumps(info, default=str))
    print(f"rodphase {case}: {result.status} ({result.message}); dt={d['dt']:.3g} "
          f"(bound {d['dt_bound']:.3g}), {d['steps']} steps, {d['us_per_step']:.1f} us/step, "
          f"cpu {cpu:.0f} s; max pairs {d.get('max_pairs')}, max penetration "
          f"{d.get('max_penetration', 0):.3f}; final Lk={lk[-1] if len(lk) else np.nan:.3f} "
          f"Tw={tw[-1] if len(tw) else np.nan:.3f} Wr={wr[-1] if len(wr) else np.nan:.3f}; "
          f"alignment {al:.2f} ({classify.phase(al)}) -> {out}", flush=True)
    return info


# ------------------------------------------------------------------ comparison


def _at(t, y, when):
    return float(np.interp(when, t, y)) if len(t) and t[0] <= when <= t[-1] + 1e-9 else math.nan


def onset(t, wr, threshold=0.5):
    above = np.flatnonzero(np.abs(wr) > threshold)
    return float(t[above[0]]) if len(above) else math.nan


def compare(case: str, ref_path: Path, rp_path: Path, png: Path | None) -> str:
    from rodphase import classify

    ref = np.load(ref_path)
    rp = np.load(rp_path)
    ri, pi = json.loads(str(ref["info"])), json.loads(str(rp["info"]))
    c = settings(case)
    t_end = min(ref["time"][-1], rp["time"][-1])
    t0, tt = c["time_start_twist"], c["time_twist"]
    times = sorted({t0 + f * tt for f in (0.25, 0.5, 0.75, 1.0)} | {t0 + tt + 10.0, t0 + tt + 25.0, t_end})
    times = sorted({round(t, 1) for t in times if t <= t_end + 1e-9})
    lines = [f"### {case}: PyElastica 1.0 (reference) vs rodphase", "",
             f"rodphase: {pi['status']}, twist {pi['twist']}, kick {pi['kick']}, dt = {pi['dt']:.3g} s; "
             f"reference: {'finished' if ri.get('finished') else 'NOT finished'}", "",
             "| t [s] | end rot. [turns] ref / rp | Lk ref / rp | Tw ref / rp | Wr ref / rp | end axial [m] ref / rp |",
             "|---|---|---|---|---|---|"]
    ax = 1  # PyElastica's y
    for t in times:
        row = [f"{t:.1f}"]
        for key, scale in (("end_rotation", 2 * np.pi), ("link", 1), ("twist", 1), ("writhe", 1)):
            a = _at(ref["time"], ref[key] / scale, t)
            b = _at(rp["time"], rp[key] / scale, t)
            row.append(f"{a:.3f} / {b:.3f}")
        a = _at(ref["time"], ref["end_position"][:, ax], t)
        b = _at(rp["time"][: len(rp["end_position"])], rp["end_position"][:, ax], t)
        row.append(f"{a:.4f} / {b:.4f}")
        lines.append("| " + " | ".join(row) + " |")
    on_r, on_p = onset(ref["time"], ref["writhe"]), onset(rp["time"], rp["writhe"])
    al_r = classify.alignment(ref["final_positions"], BASE_RADIUS, rest_length=BASE_LENGTH)
    al_p = classify.alignment(rp["final_positions"], BASE_RADIUS, rest_length=BASE_LENGTH)
    own = rp["link_rodphase"]
    lines += ["",
              f"- rodphase's own final Lk (clamp half-elements included, as `rodphase run` reports): "
              f"{own[-1] if len(own) else math.nan:.3f}; the columns above use one estimator for both "
              f"(nodes + d1 of the elements, closure by rays along the end tangents)",
              f"- buckling onset (first |Wr| > 0.5 turns): reference {on_r:.2f} s, rodphase {on_p:.2f} s",
              f"- final alignment / phase: reference {al_r:.3f} ({classify.phase(al_r)}), "
              f"rodphase {al_p:.3f} ({classify.phase(al_p)})",
              f"- CPU time: reference {ri.get('cpu_time', math.nan):.0f} s "
              f"({ri['steps']} steps to t = {ri['settings']['final_time']:g} s, "
              f"PyElastica 1.0), rodphase {pi['cpu_time']:.1f} s ({pi['steps']} steps, "
              f"{pi['us_per_step']:.1f} us/step); machine: {ri['machine']['cpu']}"]
    text = "\n".join(lines)
    print(text)
    if png is not None:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, axes = plt.subplots(2, 1, figsize=(7, 6), sharex=True)
        for key, name, col in (("link", "Lk", "C0"), ("twist", "Tw", "C1"), ("writhe", "Wr", "C2")):
            axes[0].plot(ref["time"], ref[key], color=col, lw=2, alpha=0.5, label=f"{name} PyElastica")
            axes[0].plot(rp["time"], rp[key], color=col, lw=1, ls="--", label=f"{name} rodphase")
        axes[0].set_ylabel("turns")
        axes[0].legend(ncol=3, fontsize=7)
        axes[1].plot(ref["time"], ref["end_position"][:, ax], lw=2, alpha=0.5, label="PyElastica")
        axes[1].plot(rp["time"][: len(rp["end_position"])], rp["end_position"][:, ax], lw=1, ls="--",
                     label="rodphase")
        axes[1].set_ylabel("free end, axial position [m]")
        axes[1].set_xlabel("time [s]")
        axes[1].legend(fontsize=7)
        for a in axes:
            a.axvline(t0 + tt, color="0.7", lw=0.8)
            if t0 > 0:
                a.axvline(t0, color="0.7", lw=0.8)
        fig.suptitle(f"{case}: PyElastica 1.0 example vs rodphase ({pi['twist']} twist)")
        fig.tight_layout()
        png.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(png, dpi=110)
        print(f"wrote {png}")
    return text


# ------------------------------------------------------------------ Fig 3's corner in PyElastica
# Issue #29 item 1: four Fig 3 points (Φa ≥ 2.49) trip rodphase's 45° shear guard; is the
# runaway the model's (PyElastica runs away too) or rodphase's? `fig3 PHI EXT` runs, in
# PyElastica 1.0, rodphase's twist_under_load protocol from rest (loading.quasi_static_below
# = 0: PyElastica cannot start on the straight branch) with the Fig 3 settings. Every number
# comes from the scene as rodphase builds it (config, units, scenes), so the two runs share
# the rod, the load, the imperfection and the ramps by construction, not by copy.

# The points that fail in the map of 2026-12-04 (sweep.sample_points of configs/fig3_paper.yaml,
# full precision: Φa, L/L0), docs/history/fig3-corner.md "The triple point's failures"
FIG3_FAILED = ((2.4905348515138033, 1.1090010169893503), (2.5258821224793793, 1.079950714390725),
               (2.557734097540379, 1.0524589744396509), (2.5985506212338807, 1.1349544170312584))
# configs/fig3_paper.yaml's run settings that matter here; refine_up_to and slow_down_to are
# the runner's retries, not the model, and are left out (one resolution, one rate per run)
FIG3_SETS = (("loading.force_multiple", None), ("loading.quasi_static_below", 0.0))
BLOW_UP_SHEAR = 80.0  # degrees; rodphase's guard trips at 45, its test build ran to 89
FIG3_ROW = 0.01  # s between history rows (the runaway e-folds in ~0.02 s)
FIG3_FRAME = 0.1  # s between stored shapes (writhe, alignment)
FIG3_CHECK = 0.001  # s between blow-up checks


def fig3_config(phi: float, extension: float, elements: int):
    from rodphase import config as C
    from rodphase import scenes

    sets = list(FIG3_SETS) + [("loading.extension", extension), ("loading.twist_density", phi),
                              ("rod.elements", elements)]
    return C.load_scene("twist_under_load", sets, registered=scenes.SCENES)


def fig3_settings(phi: float, extension: float, elements: int) -> dict:
    """The scene's settings at one Fig 3 point, in PyElastica's terms (SI), with what does
    not carry over named in "unmapped"."""
    from rodphase import config as C
    from rodphase import scenes
    from rodphase.rod.simulate import _rod_arrays, rotational_damping_auto, time_step

    cfg = fig3_config(phi, extension, elements)
    rod = scenes.rod_from(cfg)
    problem = scenes.twist_under_load(cfg)
    r, s, k = cfg.rod, cfg.solver, cfg.contact
    # rodphase's pair spring and dashpot, per pair as PyElastica's RodSelfContact(k, nu) (the
    # inverse of contact_mapping above): the kernel's own arrays, the same for every element
    arrays = _rod_arrays(problem)
    k_pair, nu_pair = float(arrays["contact_k"][0]), float(arrays["contact_c"][0])
    turns = C.twist_turns(cfg)
    return {
        "phi": phi, "extension": extension, "n_elem": elements,
        "length": r.length, "radius": r.radius, "density": r.density,
        "E": cfg.material.youngs_modulus, "G": C.shear_modulus(cfg),
        # rodphase's shear stiffness 4GA/3 (model.Rod.shear_stiffness); PyElastica 1.0's
        # straight_rod uses 27/28·G·A (Kaneko's factor for ν = 1/2), 1.38 times softer
        "shear_stiffness": rod.shear_stiffness,
        "shear_stiffness_pyelastica": 27.0 / 28.0 * C.shear_modulus(cfg) * math.pi * r.radius**2,
        "force": C.load_force(cfg), "force_ramp_time": cfg.loading.force_ramp_time,
        "turns": turns, "twist_rate": cfg.loading.twist_rate,
        "twist_time": turns / cfg.loading.twist_rate, "hold": s.hold_max_time,
        "damping": s.damping,
        "rotational_damping": (rotational_damping_auto(rod) if s.rotational_damping == "auto"
                               else s.rotational_damping),
        "quadratic_drag": s.quadratic_drag,
        "contact_k": k_pair, "contact_nu": nu_pair,
        # rodphase's own step with contact awake; PyElastica's position Verlet has the same
        # explicit bound for the axial waves that set it
        "dt_rodphase": time_step(problem)[0],
        "imperfection": problem.rest_curvature,  # (n-1, 3) κ1, κ2 in the material frame
        "unmapped": {
            "strain_rate_damping": s.strain_rate_damping,  # Kelvin-Voigt axial, rodphase only
            "contact.exclusion": k.exclusion,  # PyElastica: 0.8π current radii, fixed
            "contact.fold": k.fold,  # no fold contact in PyElastica
            "contact.dashpot": k.dashpot,  # PyElastica's dashpot is explicit
            "ends.bodies": (cfg.ends.start_body, cfg.ends.end_body),  # nothing beyond the clamps
            "hold_until": s.hold_until,  # PyElastica holds the full hold_max_time
            "stability_probe": s.stability_probe,
        },
    }


def _shear_and_stretch(x, Q, rest_lengths):
    """(angle between d3 and the tangent of each element [deg], stretch of each element)."""
    edge = np.diff(x, axis=1)
    length = np.linalg.norm(edge, axis=0)
    cos = np.einsum("ij,ij->j", Q[2], edge) / length
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))), length / rest_lengths


def run_fig3(phi: float, extension: float, elements: int, out: Path, dt: float | None = None,
             hold: float | None = None, final_time: float | None = None,
             shear: str = "rodphase") -> dict:
    import elastica as ea

    from rodphase.studytools import machine

    c = fig3_settings(phi, extension, elements)
    c["shear"] = shear
    if hold is not None:
        c["hold"] = hold
    n = elements
    dt = float(dt or c["dt_rodphase"])
    ramp_t, twist_t, theta = c["force_ramp_time"], c["twist_time"], 2 * math.pi * c["turns"]
    total = ramp_t + twist_t + c["hold"] if final_time is None else float(final_time)
    steps = int(math.ceil(total / dt))

    def rotation(t):
        # the scene's end rotation: held at 0 while the load ramps in, then ramped at the
        # twist rate, then held (rodphase's twist_stages/hold_stage)
        return theta * min(max((t - ramp_t) / twist_t, 0.0), 1.0)

    def spin(t):
        return theta / twist_t if ramp_t <= t < ramp_t + twist_t else 0.0

    class Sim(ea.BaseSystemCollection, ea.Constraints, ea.Contact, ea.Forcing,
              ea.CallBacks, ea.Damping):
        pass

    sim = Sim()
    y = np.array([0.0, 1.0, 0.0])  # PyElastica's axis, as in the examples (to_pyelastica)
    rod = ea.CosseratRod.straight_rod(
        n, np.zeros(3), y, np.array([0.0, 0.0, 1.0]), c["length"], c["radius"], c["density"],
        youngs_modulus=c["E"], shear_modulus=c["G"])
    # the scene's frozen-in rest curvature (seeded, RMS 1e-3/L0); PyElastica's d1 is the
    # normal z, rodphase's x: the same material axis under the relabelling, so κ1, κ2 carry over
    rod.rest_kappa[:] = c["imperfection"].T
    if shear == "rodphase":
        # the same rod: rodphase's 4GA/3 in both shear directions (axial EA, bend EI and
        # twist 2GI are the same in both codes already)
        rod.shear_matrix[0, 0, :] = c["shear_stiffness"]
        rod.shear_matrix[1, 1, :] = c["shear_stiffness"]
    sim.append(rod)

    class SceneDamping(ea.DamperBase):
        """rodphase's drag: velocities decay at `damping` [1/s], spins at
        `rotational_damping` about d1, d2 and half of it about d3, uniformly (PyElastica's
        physical protocol divides by each node's mass, doubling the rate at the end nodes),
        then the implicit speed-proportional drag 1/(1 + c·|v|·dt), spin × radius for
        rotation (kernel._kick)."""

        def __init__(self, **kw):
            super().__init__(**kw)
            self.v = math.exp(-c["damping"] * dt)
            w = c["rotational_damping"] * dt
            self.w = np.exp(-np.array([w, w, 0.5 * w]))[:, None]

        def dampen_rates(self, system, time):
            v, w = system.velocity_collection, system.omega_collection
            v *= self.v
            w *= self.w
            if c["quadratic_drag"] > 0:
                v /= 1.0 + c["quadratic_drag"] * dt * np.linalg.norm(v, axis=0)
                w /= 1.0 + c["quadratic_drag"] * dt * c["radius"] * np.linalg.norm(w, axis=0)

    sim.dampen(rod).using(SceneDamping)

    class SceneEnds(ea.ConstraintBase):
        """twist_under_load's ends: start clamped (node and first element's frame); end node
        held laterally and free along the axis under the load; last element's frame set to
        the end rotation about the axis at every step (by value, so no damper eats twist)."""

        def __init__(self, position_start, position_end, director_start, director_end, **kw):
            super().__init__(**kw)
            self.x0 = position_start.copy()
            self.Q0 = director_start.copy()
            self.Qn = director_end.copy()

        def constrain_values(self, system, time):
            system.position_collection[:, 0] = self.x0
            system.director_collection[..., 0] = self.Q0
            system.position_collection[0, -1] = 0.0
            system.position_collection[2, -1] = 0.0
            a = rotation(time)
            # the end frame turned by a about the axis y (rows of Q are d1, d2, d3)
            R = np.array([[math.cos(a), 0.0, math.sin(a)], [0.0, 1.0, 0.0],
                          [-math.sin(a), 0.0, math.cos(a)]])
            system.director_collection[..., -1] = self.Qn @ R.T

        def constrain_rates(self, system, time):
            system.velocity_collection[:, 0] = 0.0
            system.omega_collection[:, 0] = 0.0
            system.velocity_collection[0, -1] = 0.0
            system.velocity_collection[2, -1] = 0.0
            system.omega_collection[:, -1] = (0.0, 0.0, spin(time))

    sim.constrain(rod).using(SceneEnds, constrained_position_idx=(0, -1),
                             constrained_director_idx=(0, -1))
    # EndpointForces ramps as min(1, t/ramp): the scene's ramp(0, ramp_time, 0, F)
    sim.add_forcing_to(rod).using(ea.EndpointForces, np.zeros(3), c["force"] * y,
                                  ramp_up_time=ramp_t)
    sim.detect_contact_between(rod, rod).using(ea.RodSelfContact, k=c["contact_k"],
                                               nu=c["contact_nu"])
    sim.finalize()

    rows = {k: [] for k in ("time", "end_rotation", "max_shear", "shear_element", "max_stretch",
                            "kinetic", "kinetic_rotational", "end_axial")}
    # per-element shear and stretch with each shape: where along the rod the shear sits
    frames = {"time": [], "x": [], "d1": [], "shear": [], "stretch": []}
    # rows and frames are taken at checks, so their strides are whole numbers of checks
    check_every = max(1, int(round(FIG3_CHECK / dt)))
    row_every = check_every * max(1, int(round(FIG3_ROW / (check_every * dt))))
    frame_every = check_every * max(1, int(round(FIG3_FRAME / (check_every * dt))))
    blew_up = None
    peak = {"shear": 0.0, "stretch": 0.0, "shear_time": 0.0}

    def sample(t):
        sh, st = _shear_and_stretch(rod.position_collection, rod.director_collection,
                                    rod.rest_lengths)
        return sh, st

    stepper = ea.PositionVerlet()
    t = np.float64(0.0)
    cpu0, wall0 = time.process_time(), time.perf_counter()
    print(f"fig3 Φa={phi:.4f} L/L0={extension:.4f}: n={n} dt={dt:.4g} (rodphase's "
          f"{c['dt_rodphase']:.4g}) F={c['force']:.2f} N turns={c['turns']:.3f} shear S="
          f"{rod.shear_matrix[0, 0, 0]:.1f} N ({shear}) "
          f"to t={total:g} s ({steps} steps); {machine()['cpu']}", flush=True)
    next_report = 1.0
    for i in range(steps + 1):
        if i % check_every == 0 or i == steps:
            x = rod.position_collection
            finite = np.all(np.isfinite(x)) and np.all(np.isfinite(rod.director_collection))
            sh, st = sample(t) if finite else (np.array([np.nan]), np.array([np.nan]))
            worst = float(np.nanmax(sh)) if finite else math.nan
            if finite and worst > peak["shear"]:
                peak.update(shear=worst, shear_time=float(t))
            if finite:
                peak["stretch"] = max(peak["stretch"], float(st.max()))
            record = i % row_every == 0 or i == steps or not finite or worst > BLOW_UP_SHEAR
            if record:
                rows["time"].append(float(t))
                rows["end_rotation"].append(rotation(t))
                rows["max_shear"].append(worst)
                rows["shear_element"].append(int(np.nanargmax(sh)) if finite else -1)
                rows["max_stretch"].append(float(st.max()) if finite else math.nan)
                # the two parts apart: a spin-shear chatter of elements shows in the second
                spin_energy = float(rod.compute_rotational_energy()) if finite else math.nan
                rows["kinetic"].append(float(rod.compute_translational_energy()) + spin_energy
                                       if finite else math.nan)
                rows["kinetic_rotational"].append(spin_energy)
                rows["end_axial"].append(float(x[1, -1]))
            if i % frame_every == 0 and finite:
                frames["time"].append(float(t))
                frames["x"].append(x.T.copy())
                frames["d1"].append(rod.director_collection[0].T.copy())
                frames["shear"].append(sh)
                frames["stretch"].append(st)
            if not finite or worst > BLOW_UP_SHEAR:
                blew_up = {"time": float(t), "why": "non-finite state" if not finite else
                           f"shear {worst:.1f} deg at element {int(np.nanargmax(sh))}"}
                print(f"t={t:.4f} blew up: {blew_up['why']}", flush=True)
                break
            if t >= next_report - 0.5 * dt:
                next_report += 1.0
                print(f"t={t:6.2f} s cpu={time.process_time() - cpu0:7.1f} s  rot="
                      f"{rotation(t) / (2 * math.pi):6.3f} turns  shear={worst:5.1f} deg "
                      f"(el {rows['shear_element'][-1]})  stretch={st.max():.3f}  "
                      f"KE={rows['kinetic'][-1]:.3g} J (spin {rows['kinetic_rotational'][-1]:.3g})  "
                      f"end={x[1, -1]:.4f} m", flush=True)
        if i == steps:
            break
        t = stepper.step(sim, t, dt)

    cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
    from rodphase import classify
    from rodphase.topology import topology_history

    X, D = np.array(frames["x"]), np.array(frames["d1"])
    lk, tw, wr = topology_history(X, D) if len(X) else (np.zeros(0),) * 3
    al = classify.alignment(X[-1], c["radius"], rest_length=c["length"]) if len(X) else math.nan
    info = {k: v for k, v in c.items() if k != "imperfection"}
    info.update(dt=dt, steps=i, cpu_time=cpu, wall_time=wall, machine=machine(),
                elastica="1.0.0", blew_up=blew_up, final_time=float(t),
                peak_shear=peak["shear"], peak_shear_time=peak["shear_time"],
                peak_stretch=peak["stretch"], alignment=al, phase=classify.phase(al),
                final_writhe=float(wr[-1]) if len(wr) else math.nan)
    np.savez_compressed(out, **{k: np.array(v) for k, v in rows.items()},
                        frame_time=np.array(frames["time"]), x=X, d1=D,
                        frame_shear=np.array(frames["shear"]),
                        frame_stretch=np.array(frames["stretch"]), link=lk, twist=tw,
                        writhe=wr, info=json.dumps(info, default=str))
    late = np.array(rows["time"]) >= float(t) - 1.0
    ke_late = np.array(rows["kinetic"])[late]
    ending = (f"BLEW UP at t = {blew_up['time']:.3f} s ({blew_up['why']})" if blew_up
              else f"ran to t = {t:.2f} s")
    print(f"fig3 Φa={phi:.4f} L/L0={extension:.4f} n={n}: {ending}; "
          f"peak shear {peak['shear']:.1f} deg (t = {peak['shear_time']:.2f} s), peak stretch "
          f"{peak['stretch']:.3f}; last-second KE {ke_late.min():.3g}-{ke_late.max():.3g} J; "
          f"Wr {info['final_writhe']:.2f}, alignment {al:.2f} ({classify.phase(al)}); "
          f"cpu {cpu:.0f} s, {1e6 * cpu / max(i, 1):.0f} us/step -> {out}", flush=True)
    return info


# ------------------------------------------------------------------ command line


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True)
    a = sub.add_parser("reference", help="run the case in PyElastica 1.0")
    a.add_argument("case", choices=sorted(CASES))
    a.add_argument("--final-time", type=float, default=None, help="stop early (s)")
    a.add_argument("--frame-interval", type=float, default=0.05, help="raw frames (s)")
    a.add_argument("--thinning", type=float, default=0.0,
                   help="1.0 adds rodphase's thinning force to PyElastica's self-contact (issue #49)")
    a.add_argument("--sample", type=float, default=0.5, help="s between the reduced record's topology samples")
    a.add_argument("--dt", type=float, default=None,
                   help="s; replaces the example's step (the kick is scaled to the same force)")
    a.add_argument("--prescribe-twist", type=float, default=None, metavar="FACTOR",
                   help="turn the end frame at FACTOR x the nominal rate (the SolenoidsCase as run: 0.8279066)")
    a.add_argument("--kick-shape", choices=("point", "uniform"), default="point",
                   help="point: the example's mid-node kick; uniform: rodphase's stand-in for it")
    a.add_argument("--turns", type=float, default=None,
                   help="turns put in instead of the case's, at its 0.2 turns/s (Fig 4a at 10.2 turns)")
    a.add_argument("--contact-split", action="store_true",
                   help="the pair force at the closest points, (1-t, t) per element, as rodphase's "
                        "(PyElastica: half on each node)")
    a.add_argument("--contact-from", type=float, default=0.0,
                   help="s; skip the contact loop before it (the straight rod touches nowhere)")
    a.add_argument("--raw", type=Path, default=None)
    a.add_argument("-o", "--out", type=Path, default=None)
    b = sub.add_parser("reduce", help="raw PyElastica frames -> tests/data npz")
    b.add_argument("case", choices=sorted(CASES))
    b.add_argument("--raw", type=Path, default=None)
    b.add_argument("--sample", type=float, default=0.5, help="s between topology samples")
    b.add_argument("--thinning", type=float, default=0.0, help="names the files as `reference --thinning`")
    b.add_argument("-o", "--out", type=Path, default=None)
    r = sub.add_parser("rodphase", help="run the case's settings in rodphase")
    r.add_argument("case", choices=sorted(CASES))
    r.add_argument("--contact", default="example",
                   help="example (k, nu mapped), rodphase (its defaults), or key=value,... of contact.*")
    r.add_argument("--dt", default="example", help="example (PyElastica's), auto, or seconds")
    r.add_argument("--twist", choices=("as-run", "nominal"), default="as-run",
                   help="as-run: the end rotation PyElastica applied (needs the raw reference); "
                        "nominal: turns at the nominal rate")
    r.add_argument("--kick", choices=("load", "none"), default="load",
                   help="load: the example's mid-node kick as a uniform lateral load of the same "
                        "first-mode projection; none: no perturbation")
    r.add_argument("--kick-scale", type=float, default=1.0, help="factor on that load")
    r.add_argument("--rotational-damping", default="example", help="example (4 nu/a^2), auto, or 1/s")
    r.add_argument("--end-bodies", choices=("none", "rod"), default="none",
                   help="none: nothing beyond the clamps, as in PyElastica; rod: rodphase's "
                        "holder cylinders (ends.start_body/end_body), which stop loops slipping off")
    r.add_argument("--reference", type=Path, default=None,
                   help="reduced reference npz for --twist as-run (default tests/data/crosscheck_CASE.npz)")
    r.add_argument("--final-time", type=float, default=None, help="stop early (s)")
    r.add_argument("-o", "--out", type=Path, default=None)
    q = sub.add_parser("compare", help="table and figure: reference vs rodphase")
    q.add_argument("case", choices=sorted(CASES))
    q.add_argument("--rodphase", type=Path, default=None)
    q.add_argument("--png", type=Path, default=None)
    f = sub.add_parser("fig3", help="a Fig 3 point of twist_under_load, from rest, in PyElastica 1.0")
    f.add_argument("phi", type=float, help="Φa = θ·a0/L0 (rest), as loading.twist_density")
    f.add_argument("extension", type=float, help="L/L0, as loading.extension")
    f.add_argument("--elements", type=int, default=80, help="rod.elements (Fig 3: 80, refined to 160)")
    f.add_argument("--dt", type=float, default=None, help="s; default: rodphase's step at this n")
    f.add_argument("--hold", type=float, default=None,
                   help="s of hold after the twist (default: the scene's hold_max_time)")
    f.add_argument("--final-time", type=float, default=None, help="stop early (s)")
    f.add_argument("--shear", choices=("rodphase", "pyelastica"), default="rodphase",
                   help="rodphase: its shear stiffness 4GA/3 (the same rod); pyelastica: "
                        "PyElastica 1.0's own 27/28·G·A")
    f.add_argument("-o", "--out", type=Path, default=None)
    args = p.parse_args(argv)
    if args.cmd == "fig3":
        out = args.out or Path(f"/tmp/crosscheck_fig3_{args.phi:.3f}_{args.extension:.3f}_n{args.elements}.npz")
        run_fig3(args.phi, args.extension, args.elements, out, args.dt, args.hold, args.final_time,
                 args.shear)
        return 0
    if args.cmd == "rodphase":
        out = args.out or Path(f"/tmp/crosscheck_rodphase_{args.case}.npz")
        run_rodphase(args.case, args.contact, args.dt, args.twist, args.kick,
                     args.rotational_damping, out, args.end_bodies, args.kick_scale, args.reference,
                     args.final_time)
        return 0
    if args.cmd == "compare":
        compare(args.case, DATA / f"crosscheck_{args.case}.npz",
                args.rodphase or Path(f"/tmp/crosscheck_rodphase_{args.case}.npz"),
                args.png or IMG / f"crosscheck_{args.case}.png")
        return 0

    tag = args.case + ("_thinning" if getattr(args, "thinning", 0.0) else "")
    raw = args.raw or Path(f"/tmp/crosscheck_raw_{tag}.npz")
    out = args.out or DATA / f"crosscheck_{tag}.npz"
    if args.cmd == "reference":
        run_reference(args.case, args.final_time, args.frame_interval, raw, args.thinning,
                      args.contact_from, args.dt, args.prescribe_twist, args.contact_split, args.turns,
                      args.kick_shape)
        out.parent.mkdir(parents=True, exist_ok=True)
        reduce_reference(args.case, raw, out, args.sample)
    elif args.cmd == "reduce":
        reduce_reference(args.case, raw, out, args.sample)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
