"""Scenes: a validated config → a rod Problem (initial state, ends, staged controls).

Scenes are data builders looked up by name in SCENES; each switches on only the physics
its experiment needs. Orientation: the rod starts at the origin along +z; the start
(node 0) is the clamped end, the end (node n) is loaded, pulled, twisted or free.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import numpy as np
from scipy.spatial.transform import Rotation

from . import config as C
from . import units
from .rod import Contact, Controls, Ends, Problem, Rod, Solver, Stage, constant, ramp
from .rod.model import state_from, straight_state

TURN = units.TURN


def rod_from(cfg) -> Rod:
    r, m = cfg.rod, cfg.material
    return Rod(length=r.length, radius=r.radius, elements=r.elements, density=r.density,
               youngs_modulus=m.youngs_modulus, shear_modulus=C.shear_modulus(cfg),
               incompressible=m.incompressible, law=m.law, bend_stiffness_given=m.bend_stiffness,
               twist_stiffness_given=m.twist_stiffness, shear_stiffness_given=m.shear_stiffness,
               axial_stiffness_given=m.axial_stiffness)


def contact_from(cfg) -> Contact:
    c = cfg.contact
    return Contact(enabled=cfg.physics.self_contact, stiffness=c.stiffness,
                   damping_ratio=c.damping_ratio, dashpot=c.dashpot,
                   friction=cfg.physics.friction,
                   exclusion=c.exclusion, fold=c.fold, thinning_force=c.thinning_force,
                   sleep=c.sleep,
                   skin=c.skin, near_skin=c.near_skin, penetration_limit=c.penetration_limit)


def solver_from(cfg) -> Solver:
    s = cfg.solver
    return Solver(dt=None if s.dt == "auto" else s.dt, safety=s.safety, damping=s.damping,
                  rotational_damping=None if s.rotational_damping == "auto" else s.rotational_damping,
                  history_interval=cfg.output.history_interval, hold_tolerance=s.hold_tolerance,
                  quadratic_drag=s.quadratic_drag, strain_rate_damping=s.strain_rate_damping,
                  settle_window=s.settle_window,
                  stability_probe=s.stability_probe, probe_size=s.probe_size,
                  static_stability=s.static_stability, probe_seed=cfg.rod.seed)


def ends_from(cfg) -> Ends:
    e = cfg.ends
    start_held = (e.start == "clamped",) * 3
    lateral = e.end_lateral == "held"
    return Ends(start_held=start_held, start_frame_held=e.start == "clamped",
                end_held=(lateral, lateral, e.end_axial == "displacement"),
                end_frame_held=e.end_rotation == "held",
                start_body=e.start == "clamped" and e.start_body == "rod",
                end_body=lateral and e.end_body == "rod", body_radius=e.body_radius)


def imperfection(cfg, rod: Rod) -> np.ndarray:
    """(n-1, 3) random rest curvature (κ1, κ2 only), RMS = rod.imperfection / L0, seeded.

    A perfectly straight rod is an equilibrium at any twist; real filaments are not perfect,
    and with damping an initial kick alone decays before a slow instability grows. A frozen-in
    imperfection makes the bifurcation imperfect and the onset of buckling unambiguous.
    """
    n = rod.elements
    rng = np.random.default_rng(cfg.rod.seed)
    kappa = np.zeros((n - 1, 3))
    kappa[:, :2] = rng.standard_normal((n - 1, 2)) * cfg.rod.imperfection / rod.length / math.sqrt(2)
    return kappa


def hold_stage(cfg, controls: Controls, label="hold", sample: int | None = None) -> Stage:
    s = cfg.solver
    return Stage(s.hold_max_time, until_equilibrium=s.hold_until == "equilibrium", label=label,
                 controls=controls, sample=sample)


def _problem(cfg, rod, state, stages, ends=None, rest_curvature=None, force_scale=None) -> Problem:
    return Problem(rod=rod, state=state, ends=ends or ends_from(cfg), contact=contact_from(cfg),
                   solver=solver_from(cfg), stages=tuple(stages), name=cfg.scene,
                   rest_curvature=rest_curvature, force_scale=force_scale)


def _with_gravity(cfg, problem: Problem) -> Problem:
    """physics.gravity acts in every stage, whatever controls the scene built for it."""
    gravity = tuple(cfg.physics.gravity)
    problem.controls = dataclasses.replace(problem.controls, gravity=gravity)
    problem.stages = tuple(
        s if s.controls is None else
        dataclasses.replace(s, controls=dataclasses.replace(s.controls, gravity=gravity))
        for s in problem.stages)
    return problem


def twist_stages(cfg, force: float, turns_from: float, turns_to: float, label="twist",
                 **extra) -> Stage:
    duration = abs(turns_to - turns_from) / cfg.loading.twist_rate
    return Stage(duration, label=label, controls=Controls(
        end_force=constant(force),
        end_rotation=ramp(0.0, duration, TURN * turns_from, TURN * turns_to), **extra))


def twist_under_load(cfg, twist_targets: list[float] | None = None) -> Problem:
    """Fig 2 and Fig 3: clamp, constant end load (ramped), twist the end, hold to equilibrium.

    With `twist_targets` (turns, ascending), a continuation: one load ramp, then twist to
    each target and hold there; each hold's end is one sample.

    With loading.quasi_static_below = s > 0 the run starts where the paper's protocol would
    be, had it been slow enough, at s times the straight rod's buckling twist: the straight
    rod in its loaded equilibrium (stretched to e, twisted uniformly), with the load on and no
    load ramp; the twist ramp starts there (or, for a target below that twist, the hold).
    Below its buckling twist the straight rod is the only equilibrium the ramp can follow, so
    this changes no final state; the margin 1 − s covers the theory's distance from the
    discrete rod's onset (docs/history/performance.md, "A quasi-static straight start").
    """
    rod = rod_from(cfg)
    force = C.load_force(cfg) or 0.0
    targets = twist_targets if twist_targets is not None else [C.twist_turns(cfg)]
    fraction = cfg.loading.quasi_static_below
    offset = 0.0
    if fraction > 0:
        state, clamps, previous = _quasi_static_start(cfg, rod, force, fraction, targets[0])
        stages = []
        # the end starts where the load has put it: the recorded end displacement counts
        # from the rest length, as in the whole protocol
        offset = float(state.x[2, -1]) - rod.length
    else:
        ramp_time = cfg.loading.force_ramp_time
        stages = [Stage(ramp_time, label="load",
                        controls=Controls(end_force=ramp(0, ramp_time, 0, force)))]
        state, clamps, previous = straight_state(rod), None, 0.0
    for k, turns in enumerate(targets):
        if turns != previous:
            stages.append(twist_stages(cfg, force, previous, turns, label=f"twist {k}"))
        stages.append(hold_stage(cfg, Controls(end_force=constant(force),
                                               end_rotation=constant(TURN * turns)), f"hold {k}",
                                  sample=k))
        previous = turns
    problem = _problem(cfg, rod, state, stages, rest_curvature=imperfection(cfg, rod))
    problem.clamp_reference = clamps
    problem.end_displacement_offset = offset
    return problem


def _quasi_static_start(cfg, rod: Rod, force: float, fraction: float, first_target: float):
    """(state, clamp reference, turns) of a twist_under_load run started on the straight
    branch: the rod stretched to the load's extension e (its nodes evenly spaced, as the
    uniform equilibrium has them) and twisted uniformly by `fraction` of the model's own
    buckling twist (rod/onset.py: the perfect rod at this resolution, with its shear and
    stretch), or by the first target if that is less; the clamp reference is the untwisted
    frame, so that the end rotation control carries the turns already in."""
    from .rod.onset import straight_equilibrium, straight_start_turns

    check_straight_start(cfg)
    extension = C.straight_extension(cfg)
    try:
        turns = straight_start_turns(rod, extension, first_target, fraction)
    except ValueError as error:  # under-resolved for the onset's twist
        raise C.ConfigError("rod.elements", rod.elements,
                            f"{error}, with loading.quasi_static_below > 0") from None
    # along the axis from the origin, every element stretched to the load's extension e; the
    # clamp reference is the untwisted straight rod's frame (all its frames are alike, and so
    # are the frames clamp_frames would extrapolate from them)
    start = straight_equilibrium(rod, extension, turns)
    return start.state, start.clamp_reference, turns


def check_straight_start(cfg) -> None:
    """Refuse (ConfigError) a scene whose straight loaded rod is not the branch the straight
    start knows: clamped, pulled by a force, the paper's incompressible law, no gravity."""
    e = cfg.ends
    needs = {"ends.start": (e.start, "clamped"), "ends.end_axial": (e.end_axial, "force"),
             "ends.end_lateral": (e.end_lateral, "held"),
             "ends.end_rotation": (e.end_rotation, "held"),
             "material.law": (cfg.material.law, "paper"),
             "material.incompressible": (cfg.material.incompressible, True)}
    for key, (value, allowed) in needs.items():
        if value != allowed:
            raise C.ConfigError(key, value, f"{allowed!r} with loading.quasi_static_below > 0 "
                                "(the straight rod's buckling twist is known for that rod only)")
    # given bending, twist and shear stiffnesses are the rod's own (rod_from), and so is its
    # onset; a given axial stiffness is not what the load's extension e assumes (E·A0)
    if cfg.material.axial_stiffness is not None:
        raise C.ConfigError("material.axial_stiffness", cfg.material.axial_stiffness,
                            "null with loading.quasi_static_below > 0 (the straight start "
                            "stretches the rod by the load's extension of E·A0)")
    if any(cfg.physics.gravity):
        raise C.ConfigError("physics.gravity", list(cfg.physics.gravity),
                            "[0, 0, 0] with loading.quasi_static_below > 0")


def solenoid_loss(cfg) -> Problem:
    """Fig 4a: form a solenoid as in twist_under_load, then pull the end by a distance at a
    steady rate; the reaction force is the result. With the end rotation held this is a
    horizontal path through the phase diagram (Φa = θ·a0/L0 fixed); `pull.extra_turns` turns
    the end on during the pull (a diagonal path); `pull.release` moves the end back to where
    the pull started, at the same rate and with the same rotation (a hysteresis loop)."""
    base = twist_under_load(cfg)
    force = C.load_force(cfg) or 0.0
    turns = C.twist_turns(cfg)
    p = cfg.pull
    duration = p.distance / p.rate
    pull_ends = dataclasses.replace(ends_from(cfg), start_held=(True,) * 3, start_frame_held=True,
                                    end_held=(True, True, True), end_frame_held=True)
    final = turns + p.extra_turns
    pull = Stage(duration, label="pull", ends=pull_ends, controls=Controls(
        end_rotation=ramp(0, duration, TURN * turns, TURN * final),
        end_displacement=ramp(0, duration, 0, p.distance)))
    base.stages = base.stages + (pull,)
    if p.release:
        # a stage with its own clock holds the end where it finds it: move it back by distance
        release = Stage(duration, label="release", ends=pull_ends, controls=Controls(
            end_rotation=ramp(0, duration, TURN * final, TURN * turns),
            end_displacement=ramp(0, duration, 0, -p.distance)))
        base.stages = base.stages + (release,)
    base.force_scale = max(force, rod_from(cfg).buckling_force)
    return base


def stiffening(cfg) -> Problem:
    """Fig 4b: a solenoid under constant load; E (and G) ramp up, the end lifts in steps."""
    base = twist_under_load(cfg)
    force = C.load_force(cfg) or 0.0
    turns = C.twist_turns(cfg)
    t = cfg.stiffen.time
    grow = Controls(end_force=constant(force), end_rotation=constant(TURN * turns),
                    stiffness=ramp(0, t, 1.0, cfg.stiffen.factor))
    settled = Controls(end_force=constant(force), end_rotation=constant(TURN * turns),
                       stiffness=constant(cfg.stiffen.factor))
    base.stages = base.stages + (Stage(t, label="stiffen", controls=grow),
                                 hold_stage(cfg, settled, "hold stiff"))
    return base


def helix_state(radius: float, pitch: float, loops: float, n: int, handedness: int,
                twist_per_length: float):
    """Nodes (n+1, 3) and directors (n, 3, 3) of a helix along +z starting at the origin's
    side, d3 along each segment, d1 turned about d3 from the inward normal so that the
    fibre's own twist density κ3 = d1'·d2 equals `twist_per_length` (rad/m). Returns
    (positions, directors, length)."""
    c = pitch / TURN
    per_loop = TURN * math.hypot(radius, c)
    length = loops * per_loop
    s = np.linspace(0.0, length, n + 1)
    phi = s / math.hypot(radius, c)
    x = np.stack([radius * np.cos(phi), handedness * radius * np.sin(phi), c * phi], axis=1)
    x[:, 0] -= radius  # the first node on the axis line x = 0 is not needed; start at origin
    t = np.diff(x, axis=0)
    t /= np.linalg.norm(t, axis=1)[:, None]
    mid = 0.5 * (phi[1:] + phi[:-1])
    inward = -np.stack([np.cos(mid), handedness * np.sin(mid), np.zeros_like(mid)], axis=1)
    d1 = inward - np.sum(inward * t, axis=1)[:, None] * t
    d1 /= np.linalg.norm(d1, axis=1)[:, None]
    d2 = np.cross(t, d1)
    # The inward normal already turns about the tangent at the helix's torsion
    # c/(R² + c²) (signed by handedness); the inserted twist is the fibre's twist, so the
    # frame is turned back by the torsion. Without this a homochiral fibre would carry
    # inserted + torsion and a heterochiral one inserted − torsion.
    torsion = handedness * c / (radius**2 + c**2)
    psi = (twist_per_length - torsion) * 0.5 * (s[1:] + s[:-1])
    c_, s_ = np.cos(psi)[:, None], np.sin(psi)[:, None]
    directors = np.stack([c_ * d1 + s_ * d2, -s_ * d1 + c_ * d2, t], axis=1)
    return x, directors, length


def measured_curvature(directors: np.ndarray, rest_lengths: np.ndarray) -> np.ndarray:
    """(n-1, 3) curvature of a frame sequence, log(Q_j Q_{j+1}ᵀ)/D0: "annealing" a shape."""
    rel = np.einsum("jab,jcb->jac", directors[:-1], directors[1:])
    d0 = 0.5 * (rest_lengths[1:] + rest_lengths[:-1])
    return Rotation.from_matrix(rel).as_rotvec() / d0[:, None]


def muscle(cfg) -> Problem:
    """Fig 4c: a twisted fibre annealed into a coil with gaps (rest shape = the coil), then
    its radius grows with a·κ3⁰ kept constant; homochiral coils contract, heterochiral ones
    elongate. The free end may carry a load along the coil axis."""
    m = cfg.muscle
    handedness = 1
    twist_sign = 1 if m.chirality == "homochiral" else -1
    twist = twist_sign * TURN * m.inserted_twist
    n = cfg.rod.elements
    x, d, length = helix_state(m.helix_radius, m.pitch, m.loops, n, handedness, twist)
    r = cfg.rod
    rod = Rod(length=length, radius=r.radius, elements=n, density=r.density,
              youngs_modulus=cfg.material.youngs_modulus, shear_modulus=C.shear_modulus(cfg),
              incompressible=cfg.material.incompressible)
    kappa = measured_curvature(d, np.full(n, length / n))
    axis = (0.0, 0.0, 1.0)
    ends = Ends(start_held=(True,) * 3, start_frame_held=True, end_held=(False,) * 3,
                end_frame_held=False, axis=axis)
    t = m.growth_time
    grow = Controls(end_force=constant(m.load), radius=ramp(0, t, 1.0, m.growth_factor))
    settled = Controls(end_force=constant(m.load), radius=constant(m.growth_factor))
    stages = [Stage(1.0, label="settle", controls=Controls(end_force=ramp(0, 1.0, 0, m.load))),
              Stage(t, label="grow", controls=grow), hold_stage(cfg, settled, "hold grown")]
    problem = _problem(cfg, rod, state_from(x, d), stages, ends=ends, rest_curvature=kappa,
                       force_scale=max(m.load, rod.buckling_force))
    return problem


def active_agent(cfg) -> Problem:
    """Fig S9: twist a loaded rod part way, let an agent relax the tension (a pair of forces
    pulling two points together) and/or add twist over a segment, then twist on."""
    rod = rod_from(cfg)
    n = rod.elements
    force = C.load_force(cfg) or 0.0
    a = cfg.agent
    segment = (int(round(a.first * n)), int(round(a.last * n)))
    pull = a.pull_multiple * rod.buckling_force
    extra = a.extra_twist_density / rod.radius  # rad/m
    at_turns = units.turns_for_twist_density(a.at_twist_density, rod.radius, rod.length)
    final = C.twist_turns(cfg)
    ramp_time = cfg.loading.force_ramp_time
    on = dict(segment=segment, local_pull=constant(pull), local_twist=constant(extra))
    stages = [Stage(ramp_time, label="load", controls=Controls(end_force=ramp(0, ramp_time, 0, force))),
              twist_stages(cfg, force, 0.0, at_turns, "twist to agent"),
              Stage(1.0, label="agent on", controls=Controls(
                  end_force=constant(force), end_rotation=constant(TURN * at_turns), segment=segment,
                  local_pull=ramp(0, 1.0, 0, pull), local_twist=ramp(0, 1.0, 0, extra))),
              hold_stage(cfg, Controls(end_force=constant(force), end_rotation=constant(TURN * at_turns),
                                       **on), "hold agent"),
              twist_stages(cfg, force, at_turns, final, "twist on", **on),
              hold_stage(cfg, Controls(end_force=constant(force), end_rotation=constant(TURN * final),
                                       **on), "hold")]
    return _problem(cfg, rod, straight_state(rod), stages, rest_curvature=imperfection(cfg, rod))


def helical_buckling(cfg) -> Problem:
    """The helical buckling benchmark (van der Heijden et al. 2003; PyElastica's
    HelicalBucklingCase): a rod clamped at both ends whose ends approach by `compress.slack`
    while each clamp turns by half of `loading.twist_turns` in opposite senses, over
    `compress.time`; then held. It buckles into a localised helix whose twist and writhe
    have closed forms (Tw + Wr = the turns put in)."""
    rod = rod_from(cfg)
    turns = C.twist_turns(cfg)
    t = cfg.compress.time
    slack = cfg.compress.slack
    ends = Ends(start_held=(True,) * 3, start_frame_held=True, end_held=(True,) * 3,
                end_frame_held=True, start_body=False, end_body=False)
    twist = Controls(start_rotation=ramp(0, t, 0, -0.5 * TURN * turns),
                     end_rotation=ramp(0, t, 0, 0.5 * TURN * turns),
                     end_displacement=ramp(0, t, 0, -slack))
    # a stage with its own clock holds the end where the stage finds it (displacement 0
    # from there); rotations are absolute
    held = Controls(start_rotation=constant(-0.5 * TURN * turns),
                    end_rotation=constant(0.5 * TURN * turns))
    stages = [Stage(t, label="compress and twist", controls=twist),
              hold_stage(cfg, held, "hold")]
    return _problem(cfg, rod, straight_state(rod), stages, ends=ends,
                    rest_curvature=imperfection(cfg, rod))


def hat_curve(cfg) -> Problem:
    """The hat curve of single-molecule experiments: at a constant load, turn the end slowly
    up to +twist_turns, down through zero to −twist_turns and back to zero, recording the
    extension and the end torque; the rod buckles in both senses on the way."""
    rod = rod_from(cfg)
    force = C.load_force(cfg) or 0.0
    turns = abs(C.twist_turns(cfg))
    ramp_time = cfg.loading.force_ramp_time
    stages = [Stage(ramp_time, label="load", controls=Controls(end_force=ramp(0, ramp_time, 0, force))),
              twist_stages(cfg, force, 0.0, turns, label="up"),
              twist_stages(cfg, force, turns, -turns, label="down"),
              twist_stages(cfg, force, -turns, 0.0, label="back")]
    return _problem(cfg, rod, straight_state(rod), stages, rest_curvature=imperfection(cfg, rod))


SCENES: dict[str, Callable] = {
    "hat_curve": hat_curve,
    "helical_buckling": helical_buckling,
    "twist_under_load": twist_under_load,
    "solenoid_loss": solenoid_loss,
    "stiffening": stiffening,
    "muscle": muscle,
    "active_agent": active_agent,
}


def build(cfg, **kwargs) -> Problem:
    try:
        builder = SCENES[cfg.scene]
    except KeyError:
        raise C.ConfigError("scene", cfg.scene, "one of " + ", ".join(sorted(SCENES))) from None
    return _with_gravity(cfg, builder(cfg, **kwargs))
