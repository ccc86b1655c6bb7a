"""Run the paper's scenes and draw their figures: `python scripts/figures.py --out DIR`.

Each figure is one shipped scene (rodphase/configs/scenes/); its run goes to DIR/<fig>.h5
and its pictures to DIR/<fig>_*.png. `--only fig2a,fig4a` picks some; `--set key=value`
applies to every scene (e.g. --set rod.elements=60 for a quick look).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

# figure → (scene, plots to draw)
FIGURES = {
    "fig2a": ("fig2a_plectoneme", ("topology", "shape")),
    "fig2b": ("fig2b_solenoid", ("topology", "shape")),
    "fig4a": ("solenoid_loss", ("force", "shape")),
    "fig4b": ("stiffening", ("response", "shape")),
    "fig4c_homochiral": ("muscle", ("response", "shape")),
    "fig4c_heterochiral": ("muscle", ("response", "shape")),
    "figS9": ("active_agent", ("topology", "shape")),
}
EXTRA = {"fig4c_heterochiral": ["--set", "muscle.chirality=heterochiral"]}


def rodphase(*args: str) -> int:
    command = [str(Path(sys.executable).with_name("rodphase")), *args]
    print("$", " ".join(command), flush=True)
    return subprocess.call(command)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="out", help="output folder")
    parser.add_argument("--only", default="", help="comma-separated figures: " + ", ".join(FIGURES))
    parser.add_argument("--jobs", type=int, default=1, help="unused: scenes run one by one")
    parser.add_argument("--set", dest="sets", action="append", default=[],
                        help="key=value applied to every scene")
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    chosen = [f for f in args.only.split(",") if f] or list(FIGURES)
    unknown = sorted(set(chosen) - set(FIGURES))
    if unknown:
        parser.error(f"unknown figure(s) {unknown}; choose from {', '.join(FIGURES)}")
    sets = [x for s in args.sets for x in ("--set", s)]
    worst = 0
    for name in chosen:
        scene, plots = FIGURES[name]
        store = out / f"{name}.h5"
        start = time.perf_counter()
        # exit 1 = the run finished but did not settle or went unstable: still drawn
        status = rodphase("run", scene, "-o", str(store), "--force", *EXTRA.get(name, []), *sets)
        print(f"{name}: {time.perf_counter() - start:.0f} s wall, exit {status}", flush=True)
        if status > 1:
            worst = max(worst, status)
            continue
        for kind in plots:
            rodphase("plot", str(store), "--kind", kind, "-o", str(out / f"{name}_{kind}.png"))
    return worst


if __name__ == "__main__":
    sys.exit(main())
