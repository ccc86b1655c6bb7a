"""How the straight rod's onset line moves with the shear stiffness and with G (issue #29, 4a-b).

The paper calls shear unimportant and states G = 2E/3 (E/(1 + ν) with ν = ½, twice the
textbook E/3 of an incompressible solid). The model's own onset (rod/onset.py: the perfect
discrete rod at n elements, from its stiffness) answers both for the phase map's lowest
boundary, the straight rod's loss of stability, without a sweep:

    python studies/onset_study.py                     # table to stdout, n = 80
    python studies/onset_study.py --write             # also docs/img/onset_study.png and the
                                                      # table block of docs/history/onset.md
    make onset-study                                  # the same as --write

Variants: the paper's rod; its shear stiffness (4GA/3) × 10 and × 100; G = E/3 (the textbook
incompressible solid: both the shear and the twist stiffness halve). The unsheared clamped
Greenhill twist of the paper's rod (theory.stretched_greenhill_turns) is the shear → ∞ limit
of the first three at n → ∞.
"""

from __future__ import annotations

import argparse
import math
import re
from pathlib import Path

import numpy as np

from rodphase.rod.model import Rod
from rodphase.rod.onset import greenhill_turns, straight_onset_turns

ROOT = Path(__file__).resolve().parent.parent
E, A0, L0 = 1.0e6, 0.025, 1.0


def variants(n: int) -> dict[str, Rod]:
    paper = Rod(length=L0, radius=A0, elements=n, youngs_modulus=E)
    return {
        "paper (G = 2E/3)": paper,
        "shear x 10": Rod(length=L0, radius=A0, elements=n, youngs_modulus=E,
                          shear_stiffness_given=10 * paper.shear_stiffness),
        "shear x 100": Rod(length=L0, radius=A0, elements=n, youngs_modulus=E,
                           shear_stiffness_given=100 * paper.shear_stiffness),
        "G = E/3": Rod(length=L0, radius=A0, elements=n, youngs_modulus=E,
                       shear_modulus=E / 3.0),
    }


def onset_phi_a(rod: Rod, extension: float) -> float:
    """The onset as the paper's rest Φa = θ·a0/L0."""
    return straight_onset_turns(rod, extension, tolerance=1e-5) * 2 * math.pi * A0 / L0


def study(n: int, extensions) -> dict[str, np.ndarray]:
    rods = variants(n)
    lines = {name: np.array([onset_phi_a(rod, e) for e in extensions])
             for name, rod in rods.items()}
    paper = rods["paper (G = 2E/3)"]
    lines["Greenhill, unsheared"] = np.array(
        [greenhill_turns(paper, e) * 2 * math.pi * A0 / L0 for e in extensions])
    return lines


def table(extensions, lines: dict[str, np.ndarray], n: int) -> str:
    names = list(lines)
    head = "| L/L0 | " + " | ".join(names) + " |\n|---|" + "---|" * len(names) + "\n"
    rows = []
    base = lines["paper (G = 2E/3)"]
    for i, e in enumerate(extensions):
        cells = [f"{lines[k][i]:.3f}" + ("" if k.startswith("paper") else
                                         f" ({lines[k][i] / base[i]:.3f}×)") for k in names]
        rows.append(f"| {e:.2f} | " + " | ".join(cells) + " |")
    return (head + "\n".join(rows) + f"\n\nΦa = θ·a0/L0 at the onset, n = {n}; in brackets the "
            "ratio to the paper's rod. `studies/onset_study.py --write`.\n")


def figure(extensions, lines, path: Path, n: int) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.0, 3.8))
    styles = {"paper (G = 2E/3)": "k-", "shear x 10": "C0-", "shear x 100": "C1-",
              "G = E/3": "C2-", "Greenhill, unsheared": "k--"}
    for name, values in lines.items():
        ax.plot(extensions, values, styles.get(name, "-"), label=name, lw=1.2)
    ax.set_xlabel(r"extension $L/L_0$")
    ax.set_ylabel(r"onset $\Phi a = \theta a_0/L_0$ (rad)")
    ax.set_title(f"straight rod's onset, model n = {n}", fontsize=9)
    ax.legend(frameon=False, fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=150)
    plt.close(fig)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--elements", type=int, default=80)
    parser.add_argument("--extensions", default="1.0,1.05,1.1,1.15,1.2,1.25,1.3")
    parser.add_argument("--write", action="store_true",
                        help="write docs/img/onset_study.png and the docs table block")
    parser.add_argument("--docs", default=str(ROOT / "docs" / "history" / "onset.md"))
    parser.add_argument("--figure", default=str(ROOT / "docs" / "img" / "onset_study.png"))
    args = parser.parse_args(argv)
    extensions = [float(v) for v in args.extensions.split(",")]
    lines = study(args.elements, extensions)
    text = table(extensions, lines, args.elements)
    print(text)
    if args.write:
        figure(extensions, lines, Path(args.figure), args.elements)
        docs = Path(args.docs)
        old = docs.read_text()
        block = re.compile(r"(<!-- onset_study:begin -->\n).*?(<!-- onset_study:end -->)", re.S)
        if not block.search(old):
            raise SystemExit(f"{docs}: no <!-- onset_study:begin/end --> block to write into")
        docs.write_text(block.sub(lambda m: m.group(1) + text + m.group(2), old))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
