"""Cross-check rodphase against the authors' own code: PyElastica's self-contact examples.

The settings are those of GazzolaLab/PyElastica (commit 024194e0959f85a22710acffb8a69e7fbf009018)

    examples/RodContactCase/RodSelfContact/SolenoidsCase/solenoid_case.py
    examples/RodContactCase/RodSelfContact/PlectonemesCase/plectoneme_case.py

re-expressed here (the settings carry over, the code is written anew) for PyElastica 1.0.

    python scripts/crosscheck_pyelastica.py reference solenoid     # ~20-60 min on one core
    python scripts/crosscheck_pyelastica.py reference plectoneme   # ~1 h on one core
    python scripts/crosscheck_pyelastica.py rodphase solenoid      # minutes
    python scripts/crosscheck_pyelastica.py compare solenoid       # table + docs/img/crosscheck_solenoid.png

`reference` keeps every 0.05 s frame in /tmp/crosscheck_raw_CASE.npz (MBs) and writes the
reduced record tests/data/crosscheck_CASE.npz (0.5 s samples, final shape; < 300 kB).
`reduce CASE` redoes the reduction from the raw file. Run with NUMBA_NUM_THREADS=1.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np

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

CASES = {
    "solenoid": dict(
        turns=13, time_start_twist=10.0, time_twist=5.0 * 13, time_relax=50.0,
        n_elem=100, force=300.0, initial_kick=False,
    ),
    "plectoneme": dict(
        turns=10, time_start_twist=0.0, time_twist=5.0 * 10, time_relax=50.0,
        n_elem=150, force=0.0, initial_kick=True,
    ),
}


def settings(case: str) -> dict:
    c = dict(CASES[case])
    c["final_time"] = c["time_start_twist"] + c["time_twist"] + c["time_relax"]
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


def run_reference(case: str, final_time: float | None, frame_interval: float, raw: Path) -> None:
    import elastica as ea
    from elastica._rotations import _get_rotation_matrix

    from _common import machine

    c = settings(case)
    if final_time is not None:
        c["final_time_requested"] = c["final_time"]
        c["final_time"] = float(final_time)
    n = c["n_elem"]
    dt = c["dt"]  # the example steps with final_time / total_steps (of its full run)
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
                          time_step=c["dt_nominal"])

    t0, tt, turns = c["time_start_twist"], c["time_twist"], c["turns"]

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
            self.x0 = position_start.copy()
            self.Q0 = director_start.copy()

        def constrain_values(self, system, time):
            if time > tt + t0:
                system.position_collection[..., 0] = self.x0
                system.position_collection[0, -1] = 0.0
                system.position_collection[2, -1] = 0.0
                system.director_collection[..., 0] = self.Q0
                system.director_collection[..., -1] = self.final_end

        def constrain_rates(self, system, time):
            system.velocity_collection[..., 0] = 0.0
            system.omega_collection[..., 0] = 0.0
            if time > tt + t0:
                system.velocity_collection[..., -1] = 0.0
                system.omega_collection[..., -1] = 0.0
            elif time >= t0:
                system.velocity_collection[0, -1] = 0.0
                system.velocity_collection[2, -1] = 0.0
                system.omega_collection[..., -1] = -self.ang_vel
                system.velocity_collection[2, system.n_elems // 2] -= KICK

    sim.constrain(rod).using(TwistEnd, constrained_position_idx=(0, -1),
                             constrained_director_idx=(0, -1))
    if c["force"]:
        sim.add_forcing_to(rod).using(ea.EndpointForces, np.zeros(3), c["force"] * y,
                                      ramp_up_time=t0 - 1)
    sim.detect_contact_between(rod, rod).using(ea.RodSelfContact, k=CONTACT_K, nu=CONTACT_NU)

    frames = {"time": [], "x": [], "d1": [], "omega_end": []}

    class Record(ea.CallBackBaseClass):
        def make_callback(self, system, time, current_step):
            if current_step % every == 0:
                frames["time"].append(time)
                frames["x"].append(system.position_collection.T.copy())
                frames["d1"].append(system.director_collection[0].T.copy())
                frames["omega_end"].append(system.omega_collection[:, -1].copy())

    sim.collect_diagnostics(rod).using(Record)
    sim.finalize()

    info = {"case": case, "settings": c, "machine": machine(), "elastica": "1.0.0",
            "source": f"GazzolaLab/PyElastica@{SOURCE_COMMIT}:{SOURCE[case]}",
            "frame_interval": every * dt, "steps": steps}

    def save(done: bool) -> None:
        info["cpu_time"] = time.process_time() - cpu0
        info["wall_time"] = time.perf_counter() - wall0
        info["finished"] = done
        np.savez(raw, time=np.array(frames["time"]), x=np.array(frames["x"]),
                 d1=np.array(frames["d1"]), omega_end=np.array(frames["omega_end"]),
                 info=json.dumps(info))

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
    np.savez_compressed(
        out, time=t[idx], end_rotation=rot[idx], link=lk, twist=tw, writhe=wr,
        end_position=X[idx, -1, :], final_positions=X[-1], final_d1=D[-1],
        info=json.dumps(info))
    print(f"wrote {out} ({out.stat().st_size / 1e3:.0f} kB, {len(idx)} samples); "
          f"final Lk={lk[-1]:.3f} Tw={tw[-1]:.3f} Wr={wr[-1]:.3f}, "
          f"end rotation {rot[-1] / (2 * np.pi):.3f} turns")


# ------------------------------------------------------------------ command line


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True)
    a = sub.add_parser("reference", help="run the case in PyElastica 1.0")
    a.add_argument("case", choices=sorted(CASES))
    a.add_argument("--final-time", type=float, default=None, help="stop early (s)")
    a.add_argument("--frame-interval", type=float, default=0.05, help="raw frames (s)")
    a.add_argument("--raw", type=Path, default=None)
    a.add_argument("-o", "--out", type=Path, default=None)
    b = sub.add_parser("reduce", help="raw PyElastica frames -> tests/data npz")
    b.add_argument("case", choices=sorted(CASES))
    b.add_argument("--raw", type=Path, default=None)
    b.add_argument("-o", "--out", type=Path, default=None)
    args = p.parse_args(argv)

    raw = args.raw or Path(f"/tmp/crosscheck_raw_{args.case}.npz")
    out = args.out or DATA / f"crosscheck_{args.case}.npz"
    if args.cmd == "reference":
        run_reference(args.case, args.final_time, args.frame_interval, raw)
        out.parent.mkdir(parents=True, exist_ok=True)
        reduce_reference(args.case, raw, out)
    elif args.cmd == "reduce":
        reduce_reference(args.case, raw, out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
