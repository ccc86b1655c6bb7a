"""Hat curves from a store (scene hat_curve, or the sweep configs/hat_forces.yaml).

    python studies/hat_curve.py OUT.h5 [--plot DIR]

Per run: the force; the buckling torque on the way up (the peak |end torque| before the
writhe first exceeds 0.2 turns) against the
clamped Greenhill moment and 2√(BF) (rod of B/e², length e·L0); the turns at buckling and
the jump in extension there; the post-buckling torque plateau M_p and slope dz/dn (metres
per turn, fitted from one turn past buckling to the top) against the Maxwell relation of a
reversible branch, dz/dn = −2π·∂M_p/∂F (= −π·M_p/F if M_p ∝ √F; evaluated across the runs
when there are several forces); the hysteresis: turns at buckling going up against turns
at which the rod comes straight again going down (writhe below 0.2 turns).
"""

import argparse
from pathlib import Path

import numpy as np

from rodphase import plot as P
from rodphase import units
from rodphase.result import rotation_put_in
from rodphase.store import read_store
from rodphase.theory import stretched_rod_buckling_moments

WRITHE_BUCKLED = 0.2  # turns: above it the rod has left the straight branch


def measure(result) -> dict:
    h, d = result.history, result.diagnostics
    labels = [s["label"] for s in d["stages"]]
    stage = np.asarray(h["stage"])
    turns = rotation_put_in(h) / (2 * np.pi)
    z = h["end_displacement"] + d["rest_length"]
    torque, writhe = h["end_torque"], h["writhe"]
    force = float(np.max(h["applied_force"]))
    radius, length, young = d["rest_radius"], d["rest_length"], d["youngs_modulus"]
    e, greenhill, two_sqrt_bf = stretched_rod_buckling_moments(force, young, radius, length)
    up = np.flatnonzero(stage == labels.index("up"))
    down = np.flatnonzero(stage == labels.index("down"))
    # buckling: the torque peak before the rod first leaves the straight branch (a post-
    # buckled plectoneme can carry more torque again later in the ramp)
    left = up[writhe[up] > WRITHE_BUCKLED]
    before = up[turns[up] <= (turns[left[0]] if len(left) else np.inf)]
    peak = before[np.argmax(np.abs(torque[before]))]
    after = up[(turns[up] > turns[peak]) & (turns[up] < turns[peak] + 0.5)]
    fit = up[turns[up] > turns[peak] + 1.0]
    slope, plateau = (np.polyfit(turns[fit], z[fit], 1)[0], float(np.mean(torque[fit]))) if len(fit) > 5 \
        else (np.nan, np.nan)
    going_down = down[turns[down] > 0]
    straight_again = going_down[writhe[going_down] < WRITHE_BUCKLED]
    return {
        "force_N": force, "force_FC": force / units.critical_force(young, radius, length), "extension": e,
        "buckling_torque": float(abs(torque[peak])),
        "greenhill": greenhill, "two_sqrt_BF": two_sqrt_bf,
        "buckling_turns": float(turns[peak]),
        "jump_m": float(z[peak] - z[after].min()) if len(after) else np.nan,
        "plateau_torque": plateau, "slope_m_per_turn": float(slope),
        "maxwell_sqrtF": float(-np.pi * plateau / force),
        "straight_again_turns": float(turns[straight_again].max()) if len(straight_again) else np.nan,
        "link_error": float(np.max(np.abs(h["link"] - turns))),
    }


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("store")
    parser.add_argument("--plot", type=Path, help="folder for one hat-curve figure per run")
    args = parser.parse_args(argv)
    rows = []
    with read_store(args.store) as store:
        for rid in store.run_ids():
            result = store.read_run(rid)
            rows.append((rid, measure(result)))
            if args.plot:
                P.hat_curve(result, args.plot / f"hat_{rid}.png")
    print("| run | F/F_C | L/L0 | M buckling | Greenhill | 2√(BF) | turns | jump (mm) | M_p | "
          "dz/dn (mm/turn) | −πM_p/F (mm/turn) | straight again at | max |Lk−turns| |")
    print("|" + "---|" * 13)
    for rid, m in rows:
        print(f"| {rid} | {m['force_FC']:.1f} | {m['extension']:.3f} | {m['buckling_torque']:.4f} | "
              f"{m['greenhill']:.4f} | {m['two_sqrt_BF']:.4f} | {m['buckling_turns']:.2f} | "
              f"{1e3 * m['jump_m']:.1f} | {m['plateau_torque']:.4f} | {1e3 * m['slope_m_per_turn']:.1f} | "
              f"{1e3 * m['maxwell_sqrtF']:.1f} | {m['straight_again_turns']:.2f} | {m['link_error']:.3f} |")
    if len(rows) >= 3:
        forces = np.array([m["force_N"] for _, m in rows])
        plateaus = np.array([m["plateau_torque"] for _, m in rows])
        order = np.argsort(forces)
        dm_df = np.gradient(plateaus[order], forces[order])
        for k, i in enumerate(order):
            print(f"{rows[i][0]}: Maxwell −2π·dM_p/dF = {-2e3 * np.pi * dm_df[k]:.1f} mm/turn "
                  f"(measured slope {1e3 * rows[i][1]['slope_m_per_turn']:.1f})")


if __name__ == "__main__":
    main()
