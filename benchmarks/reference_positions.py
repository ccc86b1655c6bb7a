"""Final state, history and snapshots of short, coarse versions of the shipped scenes, to an .npz.

A refactor of the kernel that changes no physics must leave these bit-identical:

    python benchmarks/reference_positions.py /tmp/ref_before.npz      # on the old code
    python benchmarks/reference_positions.py /tmp/ref_after.npz       # on the new code
    python benchmarks/reference_positions.py --compare /tmp/ref_before.npz /tmp/ref_after.npz

The comparison is np.array_equal (exact), per array; it exits 1 if any differs.
Each run is short (a few seconds once numba's cache is warm); the set covers contact
(plectoneme, solenoid), stage controls (pull, stiffening, growth), the active segment, both
clamps turning and the stability probe.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

# scene name -> overrides: coarse and short, each still doing what the scene is about
SCENES = {
    "twist_under_load": {"rod.elements": 48, "loading.twist_density": 1.0,
                         "loading.twist_rate": 1.0, "solver.hold_max_time": 1.5},
    "fig2b_solenoid": {"rod.elements": 48, "loading.twist_density": 1.55,
                       "loading.twist_rate": 1.0, "solver.hold_max_time": 1.0},
    "solenoid_loss": {"rod.elements": 48, "loading.twist_density": 1.55,
                      "loading.twist_rate": 1.0, "solver.hold_max_time": 0.5,
                      "pull.distance": 0.05, "pull.rate": 0.05},
    "stiffening": {"rod.elements": 48, "loading.twist_rate": 1.0,
                   "solver.hold_max_time": 0.5, "stiffen.time": 1.0},
    "muscle": {"rod.elements": 48, "muscle.loops": 2, "muscle.growth_factor": 1.25,
               "muscle.growth_time": 1.0, "solver.hold_max_time": 0.5},
    "active_agent": {"rod.elements": 48, "loading.twist_density": 0.8,
                     "loading.twist_rate": 1.0, "solver.hold_max_time": 1.0},
    "helical_buckling": {"rod.elements": 40, "solver.hold_max_time": 2.0},
}


def run_all(only=None, extra=()) -> dict[str, np.ndarray]:
    from rodphase import config as C
    from rodphase.runner import run_scene
    from rodphase.scenes import SCENES as BUILDERS

    out = {}
    for name, overrides in SCENES.items():
        if only and name not in only:
            continue
        cfg = C.load_scene(name, list(overrides.items()) + list(extra), BUILDERS)
        r = run_scene(cfg.plain(), topology=False)
        print(f"{name:18s} {r.status:14s} steps {r.diagnostics['steps']:7d}  "
              f"max contacts {int(r.history['contacts'].max()) if len(r.history['time']) else 0}",
              flush=True)
        out[f"{name}/positions"] = r.positions
        out[f"{name}/directors"] = r.directors
        out[f"{name}/steps"] = np.array(r.diagnostics["steps"])
        out[f"{name}/status"] = np.array(r.status)
        for column, values in r.history.items():
            out[f"{name}/history/{column}"] = values
        # the snapshots too: a refined run goes on from one (runner.refined_from_trip)
        out[f"{name}/snapshot_positions"] = r.snapshot_positions
        out[f"{name}/snapshot_d1"] = r.snapshot_d1
    return out


def compare(a_path: str, b_path: str) -> bool:
    a = np.load(a_path)
    b = np.load(b_path)
    same = True
    for key in sorted(set(a.files) & set(b.files)):
        if key not in a.files or key not in b.files:
            print(f"{key}: only in one file")
            same = False
            continue
        equal = a[key].shape == b[key].shape and np.array_equal(a[key], b[key], equal_nan=a[key].dtype.kind == "f")
        if not equal:
            same = False
            diff = (np.max(np.abs(a[key] - b[key])) if a[key].shape == b[key].shape
                    and a[key].dtype.kind == "f" else "shape/dtype")
            print(f"{key}: DIFFERS (max abs {diff})")
        elif key.endswith("/positions"):
            print(f"{key}: bit-identical")
    print("ALL BIT-IDENTICAL" if same else "DIFFERENT")
    return same


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("paths", nargs="+")
    parser.add_argument("--compare", action="store_true", help="compare two saved .npz files")
    parser.add_argument("--only", nargs="+", choices=sorted(SCENES), help="run these scenes only")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="an override for every scene (e.g. a new key at the value that "
                        "keeps the old behaviour)")
    args = parser.parse_args(argv)
    if args.compare:
        return 0 if compare(*args.paths) else 1
    import yaml

    extra = [(key, yaml.safe_load(value)) for key, value in
             (item.split("=", 1) for item in args.set)]
    np.savez(args.paths[0], **run_all(args.only, extra))
    return 0


if __name__ == "__main__":
    sys.exit(main())
