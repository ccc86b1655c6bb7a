"""Where does a failing hold of Fig 3's corner get its energy? (issue #29, item 1)

    python studies/energy_audit.py                # the corner point, ~15 s after the compile
        [--point PHI_A L/L0 ...] [--samples 8] [--set KEY=VALUE ...] [--write FILE.md]

Runs one point of Fig 3 as `make fig3` runs it (configs/fig3_paper.yaml: n = 80 refined to
160 from a second before a trip, slowed to 0.25 turns/s if a guard stops it while the end
turns, straight start at 0.8 of the onset), and where a guard stopped the run, replays its
last try up to evenly spaced times of the second before the trip (`max_steps` as the clock)
and audits each state:

- the kinetic energy (the rotary inertia J/e, as the kick has it);
- the power the bend-twist law puts into the rod that no energy of the model accounts for.
  The paper's incompressible law gives each Voronoi domain the couple B·(κ − κ0)/ε³: the
  rotational gradient of V_b = ½·(κ − κ0)·B·(κ − κ0)·D0/ε³. V_b also depends on the
  domain's dilatation ε, but the law applies no axial force −∂V_b/∂ε to the nodes, so along
  any motion the law's couples do P = −(3/2)·Σ (κ − κ0)·B·(κ − κ0)·D0·ε̇/ε⁴ more work than
  V_b gives up (split below into the bending components 1, 2 and the twist component 3;
  P > 0: bent domains shortening, for free); and the same for the stretch-shear law, whose
  force and couple carry 1/e: (1 − 1/e)·dV_s/dt against the recorded quadratic energy V_s
  (unaccounted_stretch_power says why that one depends on its reference).
  tests/test_studies_smoke.py checks both against the naive twin's loads and central
  differences of V_b and V_s;
- the power that the damping takes out, each law as the kernel integrates it: the linear
  drag of the nodes (solver.damping), of the element spins (solver.rotational_damping, half
  of it on the twist axis), the quadratic drag of both (solver.quadratic_drag) and the axial
  Kelvin–Voigt dashpot (solver.strain_rate_damping). The contact dashpot is not counted: the
  losses are a lower bound;
- the largest element stretch e = l/l0 and where it is.

A state where the unaccounted powers outgrow the counted losses is one where the law puts
energy into the rod faster than the damping takes it out. docs/history/fig3-corner.md, "Where the corner's failures get their energy", reads the table.
"""

import argparse
from pathlib import Path

import numpy as np

from rodphase import api, runner
from rodphase import config as C
from rodphase.rod.simulate import _rod_arrays, rotational_damping_auto
from rodphase.scenes import SCENES, build, measured_curvature
from rodphase.studytools import write_block
from rodphase.sweep import scene_for

BLOCK = "energy_audit"
FIG3 = Path(__file__).resolve().parents[1] / "configs" / "fig3_paper.yaml"


def scene(twist_density: float, extension: float, sets: list[str]):
    """The run of configs/fig3_paper.yaml at one point, a history row every 0.1 s, with the
    --set items on top, as a validated config."""
    _, base = api.load_sweep(FIG3)
    cfg = scene_for(base, {"twist_density": twist_density, "extension": extension})
    items = [("output.history_interval", 0.1)] + [C.parse_override(s) for s in sets]
    return C.validate_scene(C.apply_overrides(cfg.plain(), items), SCENES)


def length_rates(x: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(l, dl/dt) of each element, (n,) each, from positions and velocities (n+1, 3)."""
    edge = np.diff(x, axis=0)
    length = np.linalg.norm(edge, axis=1)
    return length, np.einsum("ij,ij->i", edge / length[:, None], np.diff(v, axis=0))


def unaccounted_bend_power(x, v, Q, rest_length, bend_stiffness, rest_curvature):
    """(n-1, 3) [W] per Voronoi domain and component (d1, d2 bending; d3 twist): the power
    the incompressible bend-twist law puts into the rod beyond −dV_b/dt,
    −(3/2)·(κ − κ0)_c²·B_c·D0·ε̇/ε⁴. x, v (n+1, 3); Q (n, 3, 3) rows d1 d2 d3; rest_length
    (n,); bend_stiffness and rest_curvature (n-1, 3) (the rod's factors folded in)."""
    rest_voronoi = 0.5 * (rest_length[1:] + rest_length[:-1])
    length, rate = length_rates(x, v)
    eps = 0.5 * (length[:-1] + length[1:]) / rest_voronoi
    eps_dot = 0.5 * (rate[:-1] + rate[1:]) / rest_voronoi
    d = measured_curvature(Q, rest_length) - rest_curvature
    return -1.5 * d ** 2 * bend_stiffness * (rest_voronoi * eps_dot / eps ** 4)[:, None]


def unaccounted_stretch_power(x, v, Q, w, rest_length, shear_stiffness, rest_shear):
    """(n,) [W] per element: the power the incompressible stretch-shear law puts into the rod
    beyond −dV_s/dt, V_s = ½·l0·(σ − σ0)·S·(σ − σ0) the energy the history records as
    stretch_energy. The law's force and shear couple are that energy's gradient times 1/e, so
    this is (1 − 1/e)·dV_s/dt, with dV_s/dt = l0·S(σ − σ0)·σ̇ and
    σ̇ = (Q·ṫ − ω × Q·t)/l0 (t the element's edge, ω material). Unlike the bend-twist law's,
    it depends on the energy it is measured against: a pure stretch has the exact potential
    S·l0·(e − 1 − ln e), against which its power is zero. x, v (n+1, 3); Q (n, 3, 3);
    w (n, 3); rest_length (n,); shear_stiffness and rest_shear (n, 3)."""
    edge, edge_rate = np.diff(x, axis=0), np.diff(v, axis=0)
    material = np.einsum("iab,ib->ia", Q, edge)
    strain = material / rest_length[:, None] - np.array([0.0, 0.0, 1.0]) - rest_shear
    strain_rate = (np.einsum("iab,ib->ia", Q, edge_rate)
                   - np.cross(w, material)) / rest_length[:, None]
    rate = rest_length * np.sum(shear_stiffness * strain * strain_rate, axis=1)
    e = np.linalg.norm(edge, axis=1) / rest_length
    return (1.0 - 1.0 / e) * rate


def audit(problem, result) -> dict:
    """The audit of one state (the final state of `result`, a run of `problem`: the paper's
    incompressible law, stiffness and radius factors 1, no local twist, as in
    twist_under_load)."""
    rod = problem.rod
    if not rod.incompressible or rod.law != "paper":
        raise ValueError("the audit is of the paper's incompressible law (material.law: "
                         f"paper, material.incompressible: true); got {rod.law}, "
                         f"incompressible {rod.incompressible}")
    arrays = _rod_arrays(problem)
    solver = problem.solver
    x, v = result.positions, result.velocities
    Q, w = result.directors, result.angular_velocities
    history = result.history
    for factor in ("stiffness_factor", "radius_factor"):
        if factor in history and not np.all(history[factor] == 1.0):
            raise ValueError(f"the audit assumes {factor} 1 throughout")
    l0 = arrays["rest_length"]
    length, ldot = length_rates(x, v)
    source = unaccounted_bend_power(x, v, Q, l0,
                                    arrays["bend_stiffness"].T, arrays["rest_curvature"].T)
    stretch_source = unaccounted_stretch_power(x, v, Q, w, l0, arrays["shear_stiffness"].T,
                                               arrays["rest_shear"].T)
    # the kick turns a torque into spin with the inertia J/e of the thinned section
    mass, inertia = arrays["node_mass"], arrays["inertia"].T / (length / l0)[:, None]
    speed2 = np.sum(v ** 2, axis=1)
    spin2 = w ** 2
    spin = float(rod.radius) * np.sqrt(spin2.sum(axis=1))
    c_rot = (rotational_damping_auto(problem.rod) if solver.rotational_damping is None
             else solver.rotational_damping)
    axial = problem.rod.axial_stiffness * solver.strain_rate_damping / length  # c_i = EA·η/l
    losses = {
        "linear": solver.damping * float(np.sum(mass * speed2))
        + c_rot * float(np.sum(inertia[:, :2] * spin2[:, :2]))
        + 0.5 * c_rot * float(np.sum(inertia[:, 2] * spin2[:, 2])),
        "quadratic": solver.quadratic_drag * float(np.sum(mass * speed2 ** 1.5)
                                                   + np.sum(spin * (inertia * spin2).sum(1))),
        "axial": float(np.sum(axial * ldot ** 2)),
    }
    kinetic = 0.5 * float(np.sum(mass * speed2)) + 0.5 * float(np.sum(inertia * spin2))
    return dict(time=float(result.diagnostics["final_time"]), kinetic=kinetic,
                bend=float(source[:, :2].sum()), twist=float(source[:, 2].sum()),
                stretch_law=float(stretch_source.sum()),
                losses=losses, stretch=float((length / l0).max()),
                at=int(np.argmax(length / l0)), elements=len(l0))


def states(cfg, samples: int):
    """(the run as the map makes it, the audits of `samples` states evenly spread over the
    last REFINE_BACK (1 s) before its trip, the stop message); no audits if no refinable guard
    stopped it."""
    # the map's run, slowed down as the runner slows it (solver.slow_down_to); the audit
    # replays its last try, at that try's twist rate
    rates = runner.run_scene(cfg).diagnostics.get("twist_rates_tried")
    if rates:
        cfg = C.validate_scene(C.apply_overrides(cfg.plain(), [("loading.twist_rate", rates[-1])]),
                               SCENES)
    origin = build(cfg)
    first = runner.run(origin)
    guard = first.diagnostics.get("guard")
    fine = cfg.solver.refine_up_to
    rows = []
    if guard not in runner.REFINABLE_GUARDS:
        return first, rows, first.message
    refine = fine > cfg.rod.elements
    if refine:
        cfg = C.validate_scene(C.apply_overrides(cfg.plain(), [("rod.elements", fine)]), SCENES)
        problem = build(cfg)
        last = runner.refined_from_trip(first, origin, problem, False)
        if last is None:
            return first, rows, first.message
        start = float(last.diagnostics["refined_at"])
    else:
        problem, last = origin, first
        start = max(float(first.history["time"][0]),
                    float(first.diagnostics["final_time"]) - runner.REFINE_BACK)

    def up_to(steps: int):
        if refine:
            return runner.refined_from_trip(first, origin, build(cfg), False, max_steps=steps)
        return runner.run(build(cfg), max_steps=steps)

    end = float(last.diagnostics["final_time"])
    dt = float(last.diagnostics["dt"])
    # the budget counts the resumed run's steps (refined) or the whole run's, whose last
    # second runs at the step of awake contact (not refined): back from the trip by time
    for k in range(1, samples + 1):
        before = (end - start) * (samples - k) / samples + 0.5 * dt
        if refine:
            steps = int(round((end - before - start) / dt))
        else:
            steps = int(last.diagnostics["steps"]) - int(round(before / dt))
        result = up_to(max(1, steps))
        rows.append(audit(problem, result))
        if result.status == "unstable":
            break
    return last, rows, last.message


def table(rows: list[dict]) -> str:
    lines = ["| t [s] | kinetic energy [J] | law's unaccounted power: bending, twist; "
             "stretch-shear [W] | damping losses: linear, quadratic, axial [W] | "
             "largest stretch l/l0 (element) |",
             "|---|---|---|---|---|"]
    for r in rows:
        loss = r["losses"]
        lines.append(f"| {r['time']:.3f} | {r['kinetic']:.3g} | {r['bend']:+.3g}, {r['twist']:+.3g}; "
                     f"{r['stretch_law']:+.3g} "
                     f"| {loss['linear']:.3g}, {loss['quadratic']:.3g}, {loss['axial']:.3g} "
                     f"| {r['stretch']:.3f} ({r['at']} of {r['elements']}) |")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--point", nargs=2, type=float, action="append", metavar=("PHI_A", "L/L0"),
                        help="a point of Fig 3 (repeatable; default the corner's 2.5577 1.0525)")
    parser.add_argument("--samples", type=int, default=8,
                        help="states audited in the last second before the trip")
    parser.add_argument("--set", dest="sets", action="append", default=[],
                        help="KEY=VALUE for the scene (repeatable)")
    parser.add_argument("--write", type=Path, help="write the tables into this Markdown file")
    args = parser.parse_args(argv)
    sections = []
    for twist_density, extension in args.point or [(2.557734097540379, 1.0524589744396509)]:
        last, rows, message = states(scene(twist_density, extension, args.sets), args.samples)
        head = (f"**Φa {twist_density:.4f}, L/L0 {extension:.4f}**: {last.status}"
                f" ({message.split('; dt =')[0] if message else 'no message'})")
        text = table(rows) if rows else "no guard stopped the run: nothing to audit"
        print(head + "\n" + text, flush=True)
        sections.append(head + "\n\n" + text)
    if args.write:
        write_block(args.write, BLOCK, "\n\n".join(sections))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
