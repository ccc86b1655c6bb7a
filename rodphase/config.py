"""YAML → validated, frozen configuration; `--set key.path=value` overrides; unit mapping.

Every error names the key's path, the value and what is allowed, and is raised as
ConfigError (the CLI turns it into exit status 2 without a traceback).
"""

from __future__ import annotations

import copy
import difflib
import hashlib
import json
import math
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import yaml

from . import units

PACKAGE_CONFIGS = Path(__file__).resolve().parent / "configs"


class ConfigError(ValueError):
    def __init__(self, path: str, value: Any, allowed: str):
        self.path, self.value, self.allowed = path, value, allowed
        super().__init__(f"{path}: {value!r} (allowed: {allowed})")


class Frozen(dict):
    """A read-only mapping with attribute access: validated config sections."""

    def __getattr__(self, name):
        try:
            return self[name]
        except KeyError as exc:
            raise AttributeError(name) from exc

    def _blocked(self, *args, **kwargs):
        raise TypeError("configuration is read-only; use --set to change it")

    __setitem__ = __delitem__ = update = pop = popitem = setdefault = clear = _blocked  # type: ignore
    __setattr__ = __delattr__ = _blocked  # cfg.rod.elements = 40 would be silently ignored

    def __reduce__(self):
        # pickled (to sweep workers) as a dict handed to the constructor: the default
        # protocol would rebuild it key by key through the blocked __setitem__
        return (type(self), (dict(self),))

    def plain(self) -> dict:
        def convert(v):
            if isinstance(v, Frozen):
                return v.plain()
            return list(v) if isinstance(v, tuple) else v

        return {k: convert(v) for k, v in self.items()}


# ---------------------------------------------------------------- field checks

Check = Callable[[str, Any], Any]


def number(minimum: float | None = None, maximum: float | None = None, *, strict_min=False,
           integer=False, unit: str = "", nullable=False) -> Check:
    lo = "" if minimum is None else (f"> {minimum:g}" if strict_min else f">= {minimum:g}")
    hi = "" if maximum is None else f"<= {maximum:g}"
    kind = "an integer" if integer else "a number"
    text = " ".join(s for s in (kind, lo, ("and " + hi) if lo and hi else hi) if s)
    if unit:
        text += f", in {unit}"
    if nullable:
        text += ", or null"

    def check(path, value):
        if value is None and nullable:
            return None
        if isinstance(value, str):
            # PyYAML (YAML 1.1) reads 1.0e6 (no sign in the exponent) as text
            try:
                value = float(value)
            except ValueError:
                raise ConfigError(path, value, text) from None
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(path, value, text)
        if integer and not float(value).is_integer():
            raise ConfigError(path, value, text)
        if not math.isfinite(value):
            raise ConfigError(path, value, text)
        if minimum is not None and (value < minimum or (strict_min and value == minimum)):
            raise ConfigError(path, value, text)
        if maximum is not None and value > maximum:
            raise ConfigError(path, value, text)
        return int(value) if integer else float(value)

    return check


def choice(*options) -> Check:
    def check(path, value):
        if value not in options:
            raise ConfigError(path, value, "one of " + ", ".join(map(str, options)))
        return value

    return check


def boolean(path, value):
    if not isinstance(value, bool):
        raise ConfigError(path, value, "true or false")
    return value


def auto_or(inner: Check) -> Check:
    def check(path, value):
        return "auto" if value in ("auto", None) else inner(path, value)

    return check


def vector3(path, value):
    if not isinstance(value, (list, tuple)) or len(value) != 3:
        raise ConfigError(path, value, "a list of three numbers")
    return tuple(number()(f"{path}[{i}]", v) for i, v in enumerate(value))


def text(path, value):
    if not isinstance(value, str) or not value:
        raise ConfigError(path, value, "a non-empty string")
    return value


def interval(minimum: float, maximum: float, unit: str) -> Check:
    def check(path, value):
        allowed = f"[low, high] with {minimum:g} <= low < high <= {maximum:g} ({unit})"
        if not isinstance(value, (list, tuple)) or len(value) != 2:
            raise ConfigError(path, value, allowed)
        lo, hi = (number(minimum, maximum)(path, v) for v in value)
        if not lo < hi:
            raise ConfigError(path, value, allowed)
        return (lo, hi)

    return check


# ---------------------------------------------------------------- scene schema
# The paper's dimensionless controls are bounded alike wherever they are given, as a scene key
# (loading.twist_density) or as a sweep axis (sweep.axes.twist_density): one range each.
# |Φa| = a0·θ/L0 is the twisted rod's surface shear strain; 3 is past any elastic solid and
# past the paper's box (Φa ≤ 2.6).
TWIST_DENSITY_RANGE = (-3.0, 3.0)
EXTENSION_RANGE = (1.0, 2.0)  # L/L0 of the straight loaded rod
FORCE_MULTIPLE_RANGE = (0.0, 1000.0)  # F / F_C
# section → key → (check, default). A default of REQUIRED must be given by the user.
REQUIRED = object()
positive = number(0.0, strict_min=True)

def _snapshot_policy(path: str, value: Any):
    if value in ("auto", "all", "final"):
        return value
    if isinstance(value, int) and not isinstance(value, bool) and value >= 1:
        return value
    raise ConfigError(path, value, "auto, all, final, or every k-th history row as an "
                      "integer k >= 1")


def _engine_field(cls: str, name: str):
    """The dataclasses.Field of rodphase.rod.model.<cls>.<name> (importing the engine loads
    numba, so this runs when a scene is validated, not when the CLI starts)."""
    import dataclasses

    from .rod import model

    return {f.name: f for f in dataclasses.fields(getattr(model, cls))}[name]


class EngineDefault:
    """A schema default that is the engine's own: the default of a field of one of the
    dataclasses of rodphase.rod.model (Rod, Contact, Solver), so that a config and a Problem
    built in Python without that key mean the same thing. None there is "auto" here."""

    def __init__(self, cls: str, field: str):
        self.cls, self.field = cls, field

    def value(self):
        default = _engine_field(self.cls, self.field).default
        return "auto" if default is None else default

    def __repr__(self) -> str:
        return f"{self.cls}.{self.field}"


class EngineCheck:
    """The check of an engine field, built from its `model.setting` metadata (unit, bounds):
    true/false for a bool field, a number in the field's range otherwise, "auto" too where
    the engine's default is None (derived)."""

    def __init__(self, cls: str, field: str):
        self.cls, self.field = cls, field
        self._check: Check | None = None

    def __call__(self, path: str, value: Any):
        if self._check is None:
            spec = _engine_field(self.cls, self.field)
            meta = spec.metadata
            if isinstance(spec.default, bool):
                self._check = boolean
            elif meta.get("choices"):
                self._check = choice(*meta["choices"])
            else:
                check = number(meta["minimum"], meta["maximum"], strict_min=meta["strict_min"],
                               unit=meta["unit"])
                self._check = auto_or(check) if spec.default is None else check
        return self._check(path, value)


def _engine(cls: str, field: str) -> tuple[Check, EngineDefault]:
    """A schema entry whose check and default are the engine field's own."""
    return EngineCheck(cls, field), EngineDefault(cls, field)


SCENE_SCHEMA: dict[str, dict[str, tuple[Check, Any]]] = {
    "rod": {
        "length": (number(0, strict_min=True, unit="m"), 1.0),
        "radius": (number(0, strict_min=True, unit="m"), 0.025),
        # auto: from the rod and its twist (resolved_elements); an integer is kept as given
        "elements": (auto_or(number(4, 5000, integer=True)), "auto"),
        # what rod.elements: auto aims at: elements this many rest radii long, or shorter
        "element_length": (number(0.05, 5, unit="rest radii (used by rod.elements: auto)"), 0.5),
        # how the elements in force were chosen; set by validation (and by --set rod.elements)
        "elements_from": (choice("auto", "given"), "given"),
        "density": _engine("Rod", "density"),
        "imperfection": (number(0, 1, unit="rest curvature x L0 (RMS, random)"), 1e-3),
        "seed": (number(0, integer=True), 0),
    },
    "material": {
        "youngs_modulus": _engine("Rod", "youngs_modulus"),
        "shear_modulus": _engine("Rod", "shear_modulus"),
        "incompressible": _engine("Rod", "incompressible"),
        # paper: Gazzola 2018's incompressible law (the paper's figures); neo_hookean: forces
        # and couples from one strain energy, conserving energy (rod/neo_hookean.py)
        "law": _engine("Rod", "law"),
        # given directly instead of from E, G and the radius (null: derived), for rods that
        # are not solid isotropic cylinders; the radius then sets only mass, inertia, contact
        "bend_stiffness": (number(0, strict_min=True, unit="N m^2 (B = EI)", nullable=True), None),
        "twist_stiffness": (number(0, strict_min=True, unit="N m^2 (C = GJ)", nullable=True), None),
        "shear_stiffness": (number(0, strict_min=True, unit="N (4GA/3)", nullable=True), None),
        "axial_stiffness": (number(0, strict_min=True, unit="N (EA)", nullable=True), None),
    },
    "ends": {
        "start": (choice("clamped", "free"), "clamped"),
        "end_axial": (choice("force", "displacement", "free"), "force"),
        "end_lateral": (choice("held", "free"), "held"),
        "end_rotation": (choice("held", "free"), "held"),
        # the bodies a clamped start and a laterally held end are fixed to take part in
        # contact (a cylinder on the axis beyond the end); "none" lets a loop slip over the end
        "start_body": (choice("rod", "none"), "rod"),
        "end_body": (choice("rod", "none"), "rod"),
        "body_radius": (number(0, 20, strict_min=True, unit="rest radii"), 1.0),
    },
    "loading": {
        "force_multiple": (number(*FORCE_MULTIPLE_RANGE, unit="F_C = pi^2 E I / L0^2",
                                  nullable=True), None),
        "force": (number(0, unit="N", nullable=True), None),
        "extension": (number(*EXTENSION_RANGE, unit="L/L0 under constant load", nullable=True),
                      None),
        "force_ramp_time": (number(0, unit="s"), 1.0),
        "twist_turns": (number(unit="turns", nullable=True), None),
        "twist_density": (number(*TWIST_DENSITY_RANGE,
                                 unit="Phi*a, twist per rest length x rest radius",
                                 nullable=True), None),
        "twist_density_current": (number(*TWIST_DENSITY_RANGE,
                                         unit="Phi*a with the stretched length L = e L0 and "
                                         "radius a0/sqrt(e) of the straight loaded rod",
                                         nullable=True), None),
        "twist_rate": (number(0, strict_min=True, unit="turns/s"), 0.5),
        # twist_under_load: start in the loaded straight rod's equilibrium, twisted up to this
        # fraction of its buckling twist (the model's own onset, rod/onset.py), instead of
        # ramping the load and the twist from rest there; 0 = the paper's protocol, the whole
        # ramp. At most 0.95: a start at the onset itself would be marginally stable
        "quasi_static_below": (number(0, 0.95, unit="fraction of the straight loaded rod's "
                                      "buckling twist (the model's own onset)"), 0.0),
    },
    "physics": {
        "self_contact": (boolean, True),
        "friction": _engine("Contact", "friction"),
        "gravity": (vector3, (0.0, 0.0, 0.0)),
    },
    "contact": {
        "stiffness": _engine("Contact", "stiffness"),
        "damping_ratio": _engine("Contact", "damping_ratio"),
        # explicit | implicit: how the contact dashpot is integrated (see Contact.dashpot)
        "dashpot": _engine("Contact", "dashpot"),
        "exclusion": _engine("Contact", "exclusion"),
        # nodes inside the exclusion kept from folding tighter than the rod (no self-passage)
        "fold": _engine("Contact", "fold"),
        # the contact spring's pull along elements whose radius thins with stretch
        "thinning_force": _engine("Contact", "thinning_force"),
        # the step of a rod without contact until the rod first touches itself
        "sleep": _engine("Contact", "sleep"),
        "skin": _engine("Contact", "skin"),
        "near_skin": _engine("Contact", "near_skin"),
        "penetration_limit": _engine("Contact", "penetration_limit"),
    },
    "solver": {
        "dt": _engine("Solver", "dt"),
        "safety": _engine("Solver", "safety"),
        "damping": _engine("Solver", "damping"),
        "rotational_damping": _engine("Solver", "rotational_damping"),
        "quadratic_drag": _engine("Solver", "quadratic_drag"),
        "strain_rate_damping": _engine("Solver", "strain_rate_damping"),
        "hold_until": (choice("equilibrium", "time"), "equilibrium"),
        "hold_tolerance": _engine("Solver", "hold_tolerance"),
        "hold_max_time": (number(0, strict_min=True, unit="s"), 20.0),
        # a hold also ends once the window-mean shape moves < hold_tolerance × L0 per window
        "settle_window": _engine("Solver", "settle_window"),
        "max_steps": (number(1, integer=True, nullable=True), None),
        # a run stopped as under-resolved is run again with twice the elements, up to this
        "refine_up_to": (number(0, integer=True, unit="elements; 0 = never refine"), 0),
        # the same as a number of doublings of rod.elements (1: up to twice the scene's), so
        # that the limit follows the rod; the larger of the two limits holds
        "refinements": (number(0, 6, integer=True, unit="doublings of rod.elements; 0 = none"),
                        0),
        # a refined run goes on from a second before the trip ("trip") or starts over
        "refine_from": (choice("trip", "start"), "trip"),
        # a run still stopped (clamp lag, resolution, shear) while an end turns is run again
        # from the start at half loading.twist_rate, down to this rate
        "slow_down_to": (number(0, unit="turns/s; 0 = never slow down"), 0.0),
        # a hold ends only at an equilibrium that survives a perturbation of this size
        "stability_probe": _engine("Solver", "stability_probe"),
        "probe_size": _engine("Solver", "probe_size"),
        # with the probe: a candidate not in contact must be stable by the model's stiffness
        "static_stability": _engine("Solver", "static_stability"),
    },
    "output": {
        "history_interval": _engine("Solver", "history_interval"),
        "topology": (boolean, True),
        # which rod shapes a run keeps besides its final state: auto = all for `run`, the
        # final one for sweeps (a sweep's runs are classified by their final shape)
        "snapshots": (_snapshot_policy, "auto"),
    },
    # scene-specific sections: read only by the scenes that use them
    "pull": {
        "distance": (number(0, strict_min=True, unit="m"), 0.3),
        "rate": (number(0, strict_min=True, unit="m/s"), 0.02),
        "extra_turns": (number(unit="turns put in during the pull (diagonal path)"), 0.0),
        "release": (boolean, False),
    },
    "stiffen": {
        "factor": (number(1, 100, strict_min=True, unit="final E / initial E"), 3.0),
        "time": (number(0, strict_min=True, unit="s"), 20.0),
    },
    "compress": {  # helical_buckling: the ends approach while both clamps turn
        "slack": (number(0, unit="m the ends approach"), 3.0),
        "time": (number(0, strict_min=True, unit="s over which slack and turns are put in"), 500.0),
    },
    "muscle": {
        "helix_radius": (number(0, strict_min=True, unit="m"), 0.03),
        "pitch": (number(0, strict_min=True, unit="m"), 0.056),
        "loops": (number(1, 200), 5),
        "inserted_twist": (number(unit="turns per m of fibre"), 2.0),
        "chirality": (choice("homochiral", "heterochiral"), "homochiral"),
        "growth_factor": (number(1, 10, strict_min=True, unit="final radius / a0"), 2.0),
        "growth_time": (number(0, strict_min=True, unit="s"), 10.0),
        "load": (number(0, unit="N"), 0.0),
    },
    "agent": {
        "first": (number(0, 1, unit="fraction of L0"), 0.4),
        "last": (number(0, 1, unit="fraction of L0"), 0.6),
        "pull_multiple": (number(0, 1000, unit="F_C"), 20.0),
        "extra_twist_density": (number(*TWIST_DENSITY_RANGE, unit="Phi*a added over the segment"),
                                0.0),
        "at_twist_density": (number(*TWIST_DENSITY_RANGE, unit="Phi*a when the agent acts"), 0.4),
    },
}

# top-level keys that stay out of the validated config unless given, so that the hash of
# every config without them is what it was before they existed
OPTIONAL_SCENE_KEYS = ("initial_state",)
SCENE_KEYS = ("scene", "description") + tuple(SCENE_SCHEMA) + OPTIONAL_SCENE_KEYS

INITIAL_STATE_FORMAT = ('"FILE.h5#RUN_ID": a rodphase store, "#", and a run id as stored '
                        '(e.g. "out/run.h5#run")')


def initial_state(path: str, value: Any) -> str:
    """The format of `initial_state` (whether the file and the run exist is checked by
    rodphase.restart.checked_initial_state, which reads the file)."""
    if value is None:
        # --set initial_state=#run: YAML reads everything from " #" or a leading "#" as a
        # comment, which leaves no value at all
        raise ConfigError(path, value, INITIAL_STATE_FORMAT + "; the value is empty: YAML reads "
                          "text after # as a comment when # starts the value, so write the "
                          "file before it, and quote the whole value if it has spaces")
    if not isinstance(value, str):
        raise ConfigError(path, value, INITIAL_STATE_FORMAT)
    file, sep, run_id = value.rpartition("#")
    if not sep or not file.strip() or not run_id.strip():
        raise ConfigError(path, value, INITIAL_STATE_FORMAT)
    return value


def split_initial_state(value: str) -> tuple[str, str]:
    """(file, run id) of a valid initial_state."""
    file, _, run_id = value.rpartition("#")
    return file, run_id

SWEEP_SCHEMA: dict[str, tuple[Check, Any]] = {
    "scene": (text, REQUIRED),
    "set": (None, {}),
    "axes": (None, REQUIRED),
    "sampler": (choice("random", "lhs", "sobol", "grid", "continuation", "adaptive", "paths",
                       "boundaries"), "random"),
    "samples": (number(1, 100000, integer=True), 12),
    "seed": (number(0, integer=True), 0),
    # the paths sampler's count of columns (loads); null: the square root of samples. Only
    # kept when given, so that no other sweep's hash moves
    "columns": (number(1, 100000, integer=True, nullable=True), None),
    # the boundaries sampler's settings (rodphase boundaries, boundaries.Settings); only kept
    # when given, so that no other sweep's hash moves
    "boundary": (lambda path, value: boundary_settings(path, value), None),
}

BOUNDARY_SCHEMA: dict[str, Check] = {
    "tolerance": number(1e-4, 0.1, strict_min=False, unit="L/L0, the width of a "
                        "plectoneme-solenoid bracket"),
    "twist_tolerance": number(1e-3, 1.0, unit="Phi*a, the width of the triple point's bracket"),
    "levels": number(2, 40, integer=True, unit="twist levels of the first round"),
    "hysteresis_loads": number(1, 40, integer=True, unit="loads of the return runs "
                               "(--hysteresis)"),
    "hysteresis_step": number(0.005, 0.2, unit="step down in twist between the return's "
                              "holds, a fraction of the onset"),
}


def boundary_settings(path: str, value: Any) -> Frozen | None:
    """sweep.boundary: a mapping of BOUNDARY_SCHEMA's keys, each checked."""
    if value is None:
        return None
    if not isinstance(value, dict):
        raise ConfigError(path, value, "a mapping of " + ", ".join(BOUNDARY_SCHEMA))
    out = {}
    for key, item in value.items():
        if key not in BOUNDARY_SCHEMA:
            raise _unknown(f"{path}.", key, BOUNDARY_SCHEMA, item)
        out[key] = BOUNDARY_SCHEMA[key](f"{path}.{key}", item)
    return Frozen(out)

# sweep axes in the paper's dimensionless units and where they go in the scene
AXES = {
    "twist_density": (interval(*TWIST_DENSITY_RANGE, "Phi*a"), "loading.twist_density"),
    "twist_density_current": (interval(*TWIST_DENSITY_RANGE, "Phi*a of the stretched rod"),
                              "loading.twist_density_current"),
    "extension": (interval(*EXTENSION_RANGE, "L/L0"), "loading.extension"),
    "force_multiple": (interval(*FORCE_MULTIPLE_RANGE, "F_C"), "loading.force_multiple"),
}


def _unknown(path: str, key: str, known, value) -> ConfigError:
    """A key that is not one of `known`: its path and the value given to it, and the keys
    allowed there (the nearest first, if one is near)."""
    named = isinstance(key, str) and key.isprintable() and key.strip() and key == key.strip()
    close = difflib.get_close_matches(key, list(known), n=1) if named else []
    hint = f"; did you mean '{close[0]}'?" if close else ""
    # an empty, blank, multi-line or non-text key (`"": 1`, `null: 1`, `3: 1`): as written
    return ConfigError(f"{path}{key if named else repr(key)}", value,
                       "a known key, one of " + ", ".join(known) + hint)


def validate_scene(raw: Any, registered: dict | None = None) -> Frozen:
    """Check every key of a scene mapping and fill in defaults."""
    if not isinstance(raw, dict):
        raise ConfigError("(top level)", raw, "a mapping with a 'scene' key")
    for key in raw:
        if key not in SCENE_KEYS:
            raise _unknown("", key, SCENE_KEYS, raw[key])
    name = raw.get("scene")
    # a list or a mapping is no scene name (and `in` a dict of names would raise TypeError)
    if registered is not None and (not isinstance(name, str) or name not in registered):
        raise ConfigError("scene", name, "one of " + ", ".join(sorted(registered)))
    description = raw.get("description")
    if description is not None and not isinstance(description, str):
        # kept as given it would carry a NaN, a list or a mapping into the stored config
        raise ConfigError("description", description, "text, a sentence saying what the "
                          "scene is")
    out: dict[str, Any] = {"scene": text("scene", name), "description": description or ""}
    if "initial_state" in raw:
        out["initial_state"] = initial_state("initial_state", raw["initial_state"])
    for section, fields in SCENE_SCHEMA.items():
        given = raw.get(section)
        given = {} if given is None else given  # `rod:` alone; but not [], 0 or "" for one
        if not isinstance(given, dict):
            raise ConfigError(section, given, "a mapping of " + ", ".join(fields))
        values = {}
        for key in given:
            if key not in fields:
                raise _unknown(f"{section}.", key, fields, given[key])
        for key, (check, default) in fields.items():
            path = f"{section}.{key}"
            if key in given:
                values[key] = check(path, given[key])
            else:
                values[key] = default.value() if isinstance(default, EngineDefault) else default
        out[section] = Frozen(values)
    _check_scene_consistency(out)
    out["rod"] = _with_elements(out)  # warns: only once the scene is known to be valid
    return Frozen(out)


# ---------------------------------------------------------------- resolution

class ResolutionWarning(UserWarning):
    """rod.elements was given below what the scene needs (the CLI prints it as a warning)."""


# A straight rod twisted by more than this between neighbouring elements is close to the
# kernel's 135° resolution guard (which counts bend and twist together) before it bends at
# all: rod.elements: auto keeps 45° below the guard, and fewer elements than 120° per
# element (15° below it) draw a warning.
AUTO_TWIST_PER_ELEMENT = math.pi / 2
LEAST_TWIST_PER_ELEMENT = 2 * math.pi / 3


def elements_needed(cfg: dict) -> tuple[int, int, str]:
    """(auto, least, why) for the scene's rod: `auto` the elements rod.elements: auto takes,
    the largest of its slenderness over rod.element_length (L0/(h·a0) elements h rest radii
    long), AUTO_TWIST_PER_ELEMENT of its largest twist, and 8; `least` what a given count
    must reach without a warning: elements no longer than the radius (L0/a0) where contact
    is on, LEAST_TWIST_PER_ELEMENT of the twist, and 4; `why` says which decides."""
    rod = cfg["rod"]
    slender = rod.length / rod.radius
    turns = abs(twist_turns(cfg)) if cfg.get("loading") else 0.0
    angle = units.TURN * turns  # rad of end rotation over the whole rod
    by_length = math.ceil(slender / rod.element_length - 1e-9)
    by_twist = math.ceil(angle / AUTO_TWIST_PER_ELEMENT - 1e-9)
    auto = max(by_length, by_twist, 8)
    contact = bool(cfg["physics"].self_contact)
    least_length = math.ceil(slender - 1e-9) if contact else 0
    least_twist = math.ceil(angle / LEAST_TWIST_PER_ELEMENT - 1e-9)
    least = max(least_length, least_twist, 4)
    why = (f"L0/a0 = {slender:.4g}" + (" with self-contact (elements no longer than the "
                                        "radius)" if contact else "")
           + f"; {turns:.3g} turns of twist ({math.degrees(LEAST_TWIST_PER_ELEMENT):.0f}° "
           f"per element at most, the resolution guard trips at 135°)")
    return min(auto, 5000), least, why


def _with_elements(cfg: dict) -> Frozen:
    """The rod section with rod.elements in force: rod.elements: auto resolved by
    elements_needed (again at every validation, so that a sweep axis or --set that changes
    the radius, length or twist changes it), a given count kept (with a ResolutionWarning
    below what the scene needs). rod.elements_from says which."""
    import warnings

    rod = dict(cfg["rod"])
    # elements_from: auto with a count is a resolved config read back (plain()): the count
    # was auto's, and is recomputed for the rod as it is now
    auto = rod["elements"] == "auto" or rod["elements_from"] == "auto"
    rod["elements_from"] = "auto" if auto else "given"
    wanted, least, why = elements_needed(cfg)  # reads the rod's size and twist, not its count
    if auto:
        rod["elements"] = wanted
    elif rod["elements"] < least:
        warnings.warn(f"rod.elements = {rod['elements']} is below the {least} this rod needs "
                      f"({why}); rod.elements: auto would take {wanted}", ResolutionWarning,
                      stacklevel=3)
    return Frozen(rod)


def _check_scene_consistency(cfg: dict) -> None:
    loading = cfg["loading"]
    chosen = [k for k in ("force_multiple", "force", "extension") if loading[k] is not None]
    if len(chosen) > 1:
        raise ConfigError("loading." + chosen[1], loading[chosen[1]],
                          "only one of force_multiple, force, extension")
    twists = [k for k in ("twist_turns", "twist_density", "twist_density_current")
              if loading[k] is not None]
    if len(twists) > 1:
        raise ConfigError("loading." + twists[1], loading[twists[1]],
                          "only one of twist_turns, twist_density, twist_density_current")
    if loading.quasi_static_below > 0 and cfg.get("initial_state") is not None:
        raise ConfigError("loading.quasi_static_below", loading.quasi_static_below,
                          "0 with initial_state (a continued run starts from its stored state)")
    rod = cfg["rod"]
    if rod.radius >= 0.5 * rod.length:
        raise ConfigError("rod.radius", rod.radius, f"less than half of rod.length ({rod.length:g} m)")
    force = load_force(cfg)
    area = math.pi * rod.radius**2
    if force is not None and force >= cfg["material"].youngs_modulus * area:
        raise ConfigError("loading", force, f"a load below E*A0 = "
                          f"{cfg['material'].youngs_modulus * area:.4g} N (the rod would stretch without bound)")
    agent = cfg["agent"]
    if agent.first >= agent.last:
        raise ConfigError("agent.last", agent.last, f"greater than agent.first ({agent.first:g})")


# ---------------------------------------------------------------- unit mapping

def shear_modulus(cfg) -> float:
    g = cfg["material"].shear_modulus
    return units.paper_shear_modulus(cfg["material"].youngs_modulus) if g == "auto" else g


def buckling_force(cfg) -> float:
    """F_C = π² B / L0² of the scene's rod [N], B its material.bend_stiffness if given, else
    E·I0 (as Rod.buckling_force)."""
    rod, material = cfg["rod"], cfg["material"]
    if material.bend_stiffness is not None:
        return units.buckling_force(material.bend_stiffness, rod.length)
    return units.critical_force(material.youngs_modulus, rod.radius, rod.length)


def load_force(cfg) -> float | None:
    """The constant end load [N]: F = E·A0·(1 − 1/e) for an extension e of an incompressible rod
    (E·A0/3·(e − 1/e²) with material.law neo_hookean)."""
    loading, rod, E = cfg["loading"], cfg["rod"], cfg["material"].youngs_modulus
    if loading.force is not None:
        return loading.force
    if loading.force_multiple is not None:
        return loading.force_multiple * buckling_force(cfg)
    if loading.extension is not None:
        return units.load_for_extension(E, rod.radius, loading.extension, cfg["material"].law)
    return None


def twist_turns(cfg) -> float:
    """End rotation [turns] from twist_turns or the dimensionless twist density Φa."""
    loading, rod = cfg["loading"], cfg["rod"]
    if loading.twist_turns is not None:
        return loading.twist_turns
    if loading.twist_density is not None:
        return units.turns_for_twist_density(loading.twist_density, rod.radius, rod.length)
    if loading.twist_density_current is not None:
        return units.turns_for_current_twist_density(loading.twist_density_current, rod.radius,
                                                     rod.length, straight_extension(cfg))
    return 0.0


def refine_limit(cfg) -> int:
    """The most elements a run of `cfg` may be refined to: solver.refine_up_to, or
    rod.elements doubled solver.refinements times, whichever is larger (rod.elements alone:
    no refinement)."""
    doubled = cfg["rod"].elements * 2 ** cfg["solver"].refinements
    return max(cfg["solver"].refine_up_to, doubled)


def straight_extension(cfg) -> float:
    """L/L0 of the straight rod under the scene's constant load (1 without one)."""
    return units.extension_under_load(cfg["material"].youngs_modulus, cfg["rod"].radius,
                                      load_force(cfg) or 0.0, cfg["material"].law)


# ---------------------------------------------------------------- loading files

class _StrictLoader(yaml.SafeLoader):
    """Safe YAML that refuses what a config never needs and a typo or a crafted file uses:
    a key given twice in one mapping (PyYAML keeps the last one silently) and aliases (a
    nested alias "bomb" expands exponentially once the config is copied or hashed)."""

    def compose_node(self, parent, index):
        if self.check_event(yaml.AliasEvent):
            event = self.peek_event()
            raise yaml.constructor.ConstructorError(
                None, None, f"alias *{event.anchor} (anchors and aliases are not allowed in "
                "rodphase configs)", event.start_mark)
        return super().compose_node(parent, index)

    def construct_mapping(self, node, deep=False):
        seen = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=deep)
            if key in seen:
                raise yaml.constructor.ConstructorError(
                    None, None, f"key {key!r} given twice in one mapping", key_node.start_mark)
            seen.add(key)
        return super().construct_mapping(node, deep=deep)


def _no_octal(loader, node):
    if re.fullmatch(r"[-+]?0[0-9_]+", node.value):
        sign = node.value[0] if node.value[0] in "+-" else ""
        digits = node.value.lstrip("+-").lstrip("0_") or "0"
        raise yaml.constructor.ConstructorError(
            None, None, f"{node.value}: integers with leading zeros are octal in YAML 1.1 "
            f"(020 is 16); write {sign}{digits}", node.start_mark)
    return yaml.SafeLoader.construct_yaml_int(loader, node)


_StrictLoader.add_constructor("tag:yaml.org,2002:int", _no_octal)


def _yaml(text: str):
    return yaml.load(text, Loader=_StrictLoader)  # noqa: S506 (a SafeLoader subclass)


def make_output_folder(output) -> None:
    """`-o out/x.h5` on a fresh checkout: make `out/` rather than fail in h5py or matplotlib;
    a folder that cannot be made is refused as the option --output."""
    try:
        Path(output).parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError("--output", str(output), f"a path whose folder exists or can be made "
                          f"({exc.strerror}: {exc.filename})") from None


def stored_config(text: str) -> dict:
    """The resolved config a store carries (its config_yaml attribute), read with the same
    strict loader as config files (a file from elsewhere may hold an alias bomb); {} when it
    is not a YAML mapping."""
    if not isinstance(text, str):
        return {}  # an attribute of another type (a damaged file, another program's)
    try:
        data = _yaml(text or "")
    except yaml.YAMLError:
        return {}
    return data if isinstance(data, dict) else {}


def _short(text: str, limit: int = 60) -> str:
    text = " ".join(str(text).split())
    return text if len(text) <= limit else text[:limit] + "..."

def parse_override(item: str) -> tuple[str, Any]:
    if "=" not in item:
        raise ConfigError("--set", item, "key.path=value, e.g. rod.elements=60")
    key, value = item.split("=", 1)
    key = key.strip()
    if not key or any(not part for part in key.split(".")):
        raise ConfigError("--set", item, "key.path=value, e.g. rod.elements=60")
    try:
        parsed = _yaml(value)
    except yaml.YAMLError as exc:
        # a ReaderError (a control character) has no .problem and a two-line str: one line
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise ConfigError(key, value, f"a YAML value ({problem})") from None
    return key, parsed


def apply_overrides(data: dict, overrides: dict[str, Any] | list[tuple[str, Any]]) -> dict:
    data = copy.deepcopy(data)
    items = list(overrides.items() if isinstance(overrides, dict) else overrides)
    # setting rod.elements says how it is chosen: a count is given, auto is auto (a resolved
    # config carries rod.elements_from, which would otherwise keep the old choice)
    for key, value in list(items):
        if key in ("rod.elements", "scene.rod.elements"):
            items.append((key.rsplit(".", 1)[0] + ".elements_from",
                          "auto" if value in ("auto", None) else "given"))
    for key, value in items:
        node = data
        parts = key.split(".")
        for i, part in enumerate(parts[:-1]):
            nxt = node.get(part)
            if nxt is None:
                nxt = node[part] = {}
            if not isinstance(nxt, dict):
                raise ConfigError(".".join(parts[: i + 1]), nxt, "a mapping, to set a key inside it")
            node = nxt
        node[parts[-1]] = value
    return data


def read_yaml(path: str | Path) -> dict:
    path = Path(path)
    if not path.exists():
        raise ConfigError("config file", str(path), "an existing YAML file")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise ConfigError(str(path), "not UTF-8 text", "a YAML config file") from None
    try:
        data = _yaml(text)
    except yaml.YAMLError as exc:
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark is not None else ""
        raise ConfigError(str(path), "invalid YAML", f"{problem}{where}") from None
    if not isinstance(data, dict):
        raise ConfigError(str(path), _short(data), "a YAML mapping (a rodphase scene or sweep)")
    return data


def resolve_scene_path(name: str, base: Path | None = None) -> Path:
    """A scene file: a path (relative to `base`), or the name of a shipped scene."""
    candidates = []
    if base is not None:
        candidates.append(base / name)
    candidates += [Path(name), PACKAGE_CONFIGS / "scenes" / f"{name}.yaml",
                   PACKAGE_CONFIGS / name]
    for c in candidates:
        if c.is_file():
            return c
    shipped = sorted(p.stem for p in (PACKAGE_CONFIGS / "scenes").glob("*.yaml"))
    raise ConfigError("scene", name, "a YAML file path or a shipped scene: " + ", ".join(shipped)
                      + _did_you_mean(name, shipped))


def load_scene(path: str | Path, overrides=(), registered=None) -> Frozen:
    """A validated scene. Its initial_state (a stored run) is checked against the store by
    restart.checked_initial_state, which the CLI and the API call: config reads no store."""
    path = resolve_scene_path(str(path))
    return validate_scene(apply_overrides(read_yaml(path), list(overrides)), registered)


def resolve_sweep_path(name: str | Path) -> Path:
    """A sweep file: a path, or the name of a shipped sweep (`quick`, `fig3_paper`, ...; also
    `configs/quick.yaml` as the README writes it, when rodphase is installed elsewhere)."""
    path = Path(name)
    if path.is_file():
        return path
    stem = path.name[:-5] if path.name.endswith(".yaml") else path.name
    shipped = PACKAGE_CONFIGS / f"{stem}.yaml"
    if shipped.is_file() and path.parent in (Path("."), Path("configs")):
        return shipped
    names = sorted(p.stem for p in PACKAGE_CONFIGS.glob("*.yaml"))
    raise ConfigError("sweep file", str(name), "a YAML file path or a shipped sweep: "
                      + ", ".join(names) + _did_you_mean(stem, names))


def _did_you_mean(name: str, known) -> str:
    stem = Path(str(name)).name.removesuffix(".yaml")
    close = difflib.get_close_matches(stem, list(known), n=1)
    return f"; did you mean '{close[0]}'?" if close else ""


def load_sweep(path: str | Path, overrides=(), registered=None) -> tuple[Frozen, Frozen]:
    """(sweep, base scene) from a sweep file or a shipped sweep's name. Overrides under
    `sweep.` go to the sweep, all others to the scene (after the sweep's own `set`)."""
    path = resolve_sweep_path(path)
    data = read_yaml(path)
    sweep_over = [(k[len("sweep."):], v) for k, v in overrides if k.startswith("sweep.")]
    scene_over = [(k, v) for k, v in overrides if not k.startswith("sweep.")]
    if set(data) != {"sweep"}:
        extra = sorted(set(data) - {"sweep"})
        raise ConfigError(extra[0] if extra else "sweep", "unknown key" if extra else None,
                          "a single top-level 'sweep' mapping")
    raw = apply_overrides(data["sweep"] or {}, sweep_over)
    sweep = validate_sweep(raw)
    scene_raw = read_yaml(resolve_scene_path(sweep.scene, path.parent))
    # a value the user set for a control that an axis sets for every sample would be
    # replaced without a word: refuse it (the scene file's own value is the base the axis
    # replaces, as intended)
    for origin, items in (("sweep.set.", list(sweep["set"].items())), ("--set ", scene_over)):
        for key, value in items:
            axis = next((a for a in sweep.axes if key in _axis_controls(a)), None)
            if axis is not None:
                raise ConfigError(f"{origin}{key}", value,
                                  f"a key that no sweep axis sets: the axis '{axis}' gives "
                                  f"{AXES[axis][1]} its value in every sample")
    scene_raw = apply_overrides(scene_raw, list(sweep["set"].items()))
    scene_raw = apply_overrides(scene_raw, scene_over)
    for axis in sweep.axes:
        # the axis replaces whatever the scene said about the same control
        section = AXES[axis][1].split(".")[0]
        scene_raw.setdefault(section, {})
        if not isinstance(scene_raw[section], dict):
            continue  # --set loading=nan: validate_scene refuses it, naming the section
        for other in _axis_controls(axis):
            if other != AXES[axis][1]:
                scene_raw[section].pop(other.split(".")[1], None)
    scene = validate_scene(scene_raw, registered)
    check_onset_reach(sweep, scene)
    return sweep, scene


# Issue #47 item 4. The extension axis goes to L/L0 = 2 and the twist axis to |Φa| = 3, but
# the straight rod's buckling twist passes Φa = 3 near L/L0 = 1.48: above it a sweep finds
# only straight rods. Widening the twist range does not help: measured with Fig 3's settings
# (n = 80, refined to 160, quasi-static start at 0.8 of the onset, slow-down to 0.25 turns/s),
# a run just past the onset buckles into a solenoid at L/L0 = 1.3 (Φa = 2.5), but at
# L/L0 = 1.4, 1.45, 1.5, 1.7, 1.8, 1.9 and 2.0 (Φa = 2.9 ... 6.0, each 4-13 % past its onset)
# it stops unstable (an element sheared past 45°, or the end frame lagging its clamp), while
# the straight rod below the onset runs to equilibrium (L/L0 = 2, Φa = 4.9). So the twist
# range stays, and a twist-density sweep whose extension axis goes past what that range can
# buckle is refused, saying so.
def check_onset_reach(sweep: Frozen, scene: Frozen) -> None:
    """Refuse a sweep over twist_density and extension whose extension axis goes past the
    L/L0 at which the straight rod's buckling twist passes the largest twist density allowed
    (TWIST_DENSITY_RANGE): no sample there could buckle, whatever the twist axis. The
    buckling twist is the sheared clamped Greenhill twist of the scene's rod (the model's own
    onset for many elements; at n = 80 that is 1-5 % lower), checked for a rod clamped at
    both ends under an end load (other scenes are not)."""
    if "twist_density" not in sweep.axes or "extension" not in sweep.axes:
        return
    onset = _onset_twist_density(scene)
    top = TWIST_DENSITY_RANGE[1]
    low, high = sweep.axes["extension"]
    try:
        if onset is None or onset(high) <= top:
            return
        a, b = 1.0, high  # the onset grows with the extension: bisect for where it is `top`
        for _ in range(40):
            a, b = ((a + b) / 2, b) if onset((a + b) / 2) <= top else (a, (a + b) / 2)
        at_high = onset(high)
    except ValueError:  # no onset line for this rod (tension at its shear stiffness)
        return
    raise ConfigError("sweep.axes.extension", [low, high], (
        f"a high end of at most L/L0 = {a:.3g} with a twist_density axis: above it the "
        f"straight rod's buckling twist passes Phi*a = {top:g}, the largest twist density "
        f"allowed (it is {at_high:.3g} at L/L0 = {high:g}), so no sample there could buckle; "
        "the twist range is not wider because past the onset above L/L0 ~ 1.4 the model's "
        "rod stops unstable (sheared past its guards) instead of buckling"))


def _onset_twist_density(scene: Frozen):
    """e ↦ the sheared clamped Greenhill twist of the scene's straight rod stretched to e, as
    the rest Φa; None for a scene other than a rod clamped at both ends under an end load
    with the paper's incompressible law."""
    from .rod.model import Rod
    from .rod.onset import sheared_greenhill_turns

    ends, material, rod_cfg = scene["ends"], scene["material"], scene["rod"]
    if not (ends.start == "clamped" and ends.end_axial == "force" and ends.end_lateral == "held"
            and ends.end_rotation == "held" and material.incompressible
            and material.law == "paper"):
        return None
    rod = Rod(length=rod_cfg.length, radius=rod_cfg.radius, elements=rod_cfg.elements,
              youngs_modulus=material.youngs_modulus, shear_modulus=None
              if material.shear_modulus == "auto" else material.shear_modulus,
              bend_stiffness_given=material.bend_stiffness,
              twist_stiffness_given=material.twist_stiffness,
              shear_stiffness_given=material.shear_stiffness,
              axial_stiffness_given=material.axial_stiffness)
    to_phi = units.TURN * rod.radius / rod.length
    return lambda e: sheared_greenhill_turns(rod, e) * to_phi


def _axis_controls(axis: str) -> tuple[str, ...]:
    """The scene keys that set the same control as a sweep axis (its own key first)."""
    section = AXES[axis][1].split(".")[0]
    others = {"twist_density": ("twist_turns", "twist_density_current"),
              "twist_density_current": ("twist_turns", "twist_density"),
              "extension": ("force", "force_multiple"),
              "force_multiple": ("force", "extension")}[axis]
    return (AXES[axis][1],) + tuple(f"{section}.{k}" for k in others)


def validate_sweep(raw: Any) -> Frozen:
    if not isinstance(raw, dict):
        raise ConfigError("sweep", raw, "a mapping")
    for key in raw:
        if key not in SWEEP_SCHEMA:
            raise _unknown("sweep.", key, SWEEP_SCHEMA, raw[key])
    out = {}
    for key, (check, default) in SWEEP_SCHEMA.items():
        if key not in raw:
            if default is REQUIRED:
                raise ConfigError(f"sweep.{key}", None, "required")
            out[key] = copy.deepcopy(default)
        elif check is not None:
            out[key] = check(f"sweep.{key}", raw[key])
        else:
            out[key] = raw[key]
    if not isinstance(out["set"], dict):
        raise ConfigError("sweep.set", out["set"], "a mapping of key.path: value")
    axes = out["axes"]
    if not isinstance(axes, dict) or not axes:
        raise ConfigError("sweep.axes", axes, "a mapping of one or more of " + ", ".join(AXES))
    checked = {}
    for name, span in axes.items():
        if name not in AXES:
            raise _unknown("sweep.axes.", name, AXES, span)
        checked[name] = AXES[name][0](f"sweep.axes.{name}", span)
    if "twist_density" in checked and "twist_density_current" in checked:
        raise ConfigError("sweep.axes.twist_density_current", checked["twist_density_current"],
                          "not together with twist_density (both set the twist)")
    if "extension" in checked and "force_multiple" in checked:
        raise ConfigError("sweep.axes.force_multiple", checked["force_multiple"],
                          "not together with extension (both set the load)")
    if out.get("boundary") is None:
        out.pop("boundary", None)
    elif out["sampler"] != "boundaries":
        raise ConfigError("sweep.boundary", out["boundary"], "only with sweep.sampler: boundaries")
    if out["columns"] is None:
        del out["columns"]
    elif out["sampler"] != "paths":
        raise ConfigError("sweep.columns", out["columns"], "only with sweep.sampler: paths")
    else:
        out["columns"] = int(out["columns"])
    if out["sampler"] == "paths":
        twist = [name for name in checked if name.startswith("twist_density")]
        if len(checked) != 2 or len(twist) != 1:
            raise ConfigError("sweep.axes", {k: list(v) for k, v in checked.items()},
                              "with sweep.sampler: paths, two axes: a twist density and a "
                              "load (extension or force_multiple); each column is one load")
        if out.get("columns", 1) > out["samples"]:
            raise ConfigError("sweep.columns", out["columns"],
                              f"at most sweep.samples ({out['samples']})")
    out["axes"] = Frozen(checked)
    out["set"] = Frozen(out["set"])
    return Frozen(out)


# Keys added after stores were first written, each with the value that reproduces the
# behaviour from before it existed. config_hash leaves such a key out while it holds that
# value, so a store written before the key existed keeps its hash and still resumes; a new key
# registers here as (section, key) -> neutral value.
HASH_NEUTRAL: dict[tuple[str, str], Any] = {
    ("material", "law"): "paper",
    ("contact", "dashpot"): "explicit",  # issue #13: implicit contact dashpot
    ("solver", "strain_rate_damping"): 0.0,  # issue #13: axial Kelvin–Voigt damping
    ("loading", "quasi_static_below"): 0.0,  # issue #16: quasi-static straight start
    # fold contact (no self-passage inside the exclusion): on by default, so every config's
    # hash moved with it; a store written before it is not resumed by the new physics, and
    # contact.fold: false hashes (and runs) as before
    ("contact", "fold"): False,
    # contact asleep until the rod first touches itself (issue #16, lever 3): on by default,
    # so the hashes moved again; contact.sleep: false hashes (and runs) as before
    ("contact", "sleep"): False,
    # a refined run going on from a second before its trip (issue #16): on by default, so the
    # hashes moved again; solver.refine_from: start hashes (and runs) as before
    ("solver", "refine_from"): "start",
    # the static stability test of a hold's candidate (issue #32): on by default, so the
    # hashes moved again; solver.static_stability: false hashes (and runs) as before
    ("solver", "static_stability"): False,
    # a run stopped while an end turns, run again at half the twist rate (issue #29): off by
    # default, so no hash moved; the Fig 3 configs turn it on
    ("solver", "slow_down_to"): 0.0,
    # the contact thinning force made optional (issue #29): on by default, so no hash moved
    ("contact", "thinning_force"): True,
    # refinement as doublings (issue #46): off by default, so no hash moved
    ("solver", "refinements"): 0,
}

# keys that say how a value in force was chosen, not what runs (issue #46: rod.elements: auto
# resolves to a count, and the count is hashed): left out of every hash
HASH_OMITTED = {("rod", "element_length"), ("rod", "elements_from")}


def _hash_view(part: dict) -> dict:
    """A plain config without the keys that hold their HASH_NEUTRAL value."""
    out = {}
    for section, values in part.items():
        if isinstance(values, dict):
            values = {k: v for k, v in values.items()
                      if not ((section, k) in HASH_NEUTRAL and HASH_NEUTRAL[section, k] == v)
                      and (section, k) not in HASH_OMITTED}
        out[section] = values
    return out


# The engine's physics revision, raised by a change that moves results with no config key to
# say so (a law's bug fixed): a store is resumed only by the revision that wrote it, since its
# runs and the new ones would be of other physics. From 2 on the revision is part of the
# config hash; 1, the revision of every store written before it existed, leaves the hash as
# it was. ENGINE_REVISIONS says what each one changed (for the message that refuses a resume).
ENGINE_REVISION = 2
ENGINE_REVISIONS = {
    1: "before the engine revision was recorded",
    2: "the clamp spring's share of its κ × c term halved, as its energy gives (2026-12-06)",
}


def config_hash(*parts: Frozen, revision: int = ENGINE_REVISION) -> str:
    """The hash a store keeps of the config that made it, and of the engine's `revision`
    (ENGINE_REVISION): a store is resumed only by a config and an engine of the same hash."""
    views = [_hash_view(p.plain()) for p in parts]
    if revision != 1:
        views.append({"engine_revision": int(revision)})
    blob = json.dumps(views, sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def earlier_hashes(*parts: Frozen) -> dict[str, int]:
    """{hash: revision} of the same config under each earlier engine revision: what a store
    written by an older rodphase holds."""
    return {config_hash(*parts, revision=r): r for r in ENGINE_REVISIONS if r != ENGINE_REVISION}


def to_yaml(**parts: Frozen) -> str:
    return yaml.safe_dump({k: v.plain() for k, v in parts.items()}, sort_keys=False)


# ---------------------------------------------------------------- what each key means
# One line per key of SCENE_SCHEMA and SWEEP_SCHEMA, for `rodphase config --help`-like
# listings and the generated reference (docs/gen_reference.py renders it with each key's
# default and allowed values, read from the schema). tests/test_docs.py checks that every
# key has one.
MEANINGS: dict[str, str] = {
    "rod.length": "rest length L0",
    "rod.radius": "rest radius a0 (thins as a0/√e with the stretch e of an incompressible rod)",
    "rod.elements": "elements n of the discrete rod (n+1 nodes), or auto: from the rod's "
                    "slenderness over rod.element_length and its twist (90° an element at "
                    "most); a given count below L0/a0 (with contact) or 120° of twist an "
                    "element draws a warning",
    "rod.element_length": "the element length rod.elements: auto aims at, in rest radii "
                          "(contact needs elements no longer than about the radius)",
    "rod.elements_from": "how the count in force was chosen (auto or given); set by "
                         "validation and by --set rod.elements",
    "rod.density": "mass density",
    "rod.imperfection": "random rest curvature that breaks the straight rod's symmetry",
    "rod.seed": "seed of the imperfection",
    "material.youngs_modulus": "Young's modulus E",
    "material.shear_modulus": "shear modulus G; auto = the paper's 2E/3",
    "material.incompressible": "the section shrinks as the rod stretches (A·e constant)",
    "material.law": "paper: Gazzola 2018's law (the paper's figures); neo_hookean: forces and "
                    "couples from one strain energy (conserves energy)",
    "material.bend_stiffness": "B = EI given directly (null: from E and the radius)",
    "material.twist_stiffness": "C = GJ given directly (null: from G and the radius)",
    "material.shear_stiffness": "4GA/3 given directly (null: from G and the radius)",
    "material.axial_stiffness": "EA given directly (null: from E and the radius)",
    "ends.start": "the start (node 0): clamped or free",
    "ends.end_axial": "the end along the axis: a constant force, a prescribed displacement, "
                      "or free",
    "ends.end_lateral": "the end held on the axis or free to move sideways",
    "ends.end_rotation": "the end's frame held (turned by the twist protocol) or free",
    "ends.start_body": "a rigid cylinder beyond a clamped start that takes part in contact; "
                       "none lets a loop slip over the end (Fig S3)",
    "ends.end_body": "the same beyond a laterally held end",
    "ends.body_radius": "radius of the end bodies",
    "loading.force_multiple": "end load as a multiple of the Euler load F_C",
    "loading.force": "end load in newtons (instead of force_multiple or extension)",
    "loading.extension": "end load given as the extension L/L0 of the incompressible rod "
                         "under it: F = E·A0·(1 − 1/e)",
    "loading.force_ramp_time": "time over which the load ramps up",
    "loading.twist_turns": "end rotation in turns (instead of a twist density)",
    "loading.twist_density": "end rotation as the paper's Φa = θ·a0/L0",
    "loading.twist_density_current": "end rotation as Φa of the stretched straight rod "
                                     "(rest value / e^1.5)",
    "loading.twist_rate": "speed of the twist ramp",
    "loading.quasi_static_below": "start on the straight loaded rod at this fraction of its "
                                  "buckling twist instead of ramping from rest; 0 = the "
                                  "paper's whole protocol",
    "physics.self_contact": "self-contact (penalty spring–dashpot between capsules)",
    "physics.friction": "Coulomb friction coefficient of self-contact",
    "physics.gravity": "gravity vector",
    "contact.stiffness": "pair spring per unit element length, in units of E",
    "contact.damping_ratio": "damping ratio ζ of the pair dashpot",
    "contact.dashpot": "explicit: the dashpot is part of the force; implicit: backward Euler "
                       "per pair after the kick (no time-step limit)",
    "contact.exclusion": "elements closer than this arc length never touch",
    "contact.fold": "keep nodes inside the exclusion from folding tighter than the rod (no "
                    "self-passage, no link lost)",
    "contact.thinning_force": "the contact spring's pull along elements whose radius thins "
                              "with stretch (contact does no work on a stretching rod)",
    "contact.sleep": "take the larger step of a rod without contact until it first touches "
                     "itself or an end body",
    "contact.skin": "margin of the Verlet list of candidate pairs",
    "contact.near_skin": "smallest margin of the short list the force loop runs over",
    "contact.penetration_limit": "overlap beyond which the run stops as unstable",
    "solver.dt": "time step; auto = safety × the stable bound from the stiffest mode",
    "solver.safety": "fraction of the stable time step used when dt is auto",
    "solver.damping": "linear drag: velocities decay as exp(−damping·t) without forces",
    "solver.rotational_damping": "drag on the spins; auto = 40·√(G/ρ)/L0 (twist modes "
                                 "overdamped)",
    "solver.quadratic_drag": "drag that grows with speed; 0 = off",
    "solver.strain_rate_damping": "axial Kelvin–Voigt damping time η; damps the stiff "
                                  "axial and contact vibrations; 0 = off",
    "solver.hold_until": "a hold ends at equilibrium, or after hold_max_time",
    "solver.hold_tolerance": "equilibrium: residual force below this fraction of the force "
                             "scale",
    "solver.hold_max_time": "longest hold; a hold that has not settled then ends "
                            "not_converged",
    "solver.settle_window": "also end a hold once the window-mean shape moves less than "
                            "hold_tolerance × L0; 0 = residual test only",
    "solver.max_steps": "a hard cap on the steps of a run (null: none)",
    "solver.refine_up_to": "a run stopped as under-resolved is run again with twice the "
                           "elements, up to this many",
    "solver.refinements": "the same limit as doublings of rod.elements (1: up to twice the "
                          "scene's count), so that it follows the rod; the larger limit holds",
    "solver.refine_from": "a refined run goes on from a second before the trip, or starts over",
    "solver.slow_down_to": "a run still stopped while an end turns is run again at half the "
                           "twist rate, down to this rate",
    "solver.stability_probe": "a hold ends only at an equilibrium that survives a small "
                              "perturbation",
    "solver.probe_size": "size of the probe's perturbation",
    "solver.static_stability": "with the probe: a candidate not in contact must also be "
                               "stable by the model's own stiffness",
    "output.history_interval": "time between history rows",
    "output.topology": "compute link, twist and writhe for the history",
    "output.snapshots": "rod shapes kept besides the final one: auto (all for run, final for "
                        "sweeps), all, final, or every k-th history row",
    "pull.distance": "how far the end is pulled (solenoid_loss)",
    "pull.rate": "pulling speed",
    "pull.extra_turns": "turns put in during the pull (a diagonal path through the map)",
    "pull.release": "release instead of pull",
    "stiffen.factor": "final E / initial E (stiffening)",
    "stiffen.time": "duration of the stiffening ramp",
    "compress.slack": "distance the ends approach (helical_buckling)",
    "compress.time": "time over which slack and turns are put in",
    "muscle.helix_radius": "radius of the coiled fibre's helix",
    "muscle.pitch": "pitch of the helix",
    "muscle.loops": "loops of the helix",
    "muscle.inserted_twist": "twist inserted in the fibre",
    "muscle.chirality": "twist and coil of the same (homochiral) or opposite hand",
    "muscle.growth_factor": "final radius / a0 of the swelling fibre",
    "muscle.growth_time": "duration of the swelling",
    "muscle.load": "weight hung on the muscle",
    "agent.first": "start of the active segment",
    "agent.last": "end of the active segment",
    "agent.pull_multiple": "tension the agent relaxes, in F_C",
    "agent.extra_twist_density": "twist the agent adds over its segment",
    "agent.at_twist_density": "twist density at which the agent acts",
    "sweep.scene": "the scene swept: a shipped name or a YAML path (relative to the sweep's "
                   "file)",
    "sweep.set": "overrides applied to the scene, as --set would",
    "sweep.axes": "the axes and their [low, high] ranges (see AXES)",
    "sweep.sampler": "how points are drawn: random, lhs, sobol, grid, continuation, adaptive, "
                     "paths; boundaries: runs placed by bracketing (rodphase boundaries)",
    "sweep.samples": "how many points",
    "sweep.seed": "seed of the sampler (the same seed gives the same points and results)",
    "sweep.columns": "paths sampler: loads (columns of the map); null = √samples",
    "sweep.boundary": "boundaries sampler: tolerance (L/L0 width of a plectoneme-solenoid "
                      "bracket, 0.01), twist_tolerance (Phi*a width of the triple point's, "
                      "0.1), levels (twist levels of the first round, 6), hysteresis_loads "
                      "(loads of the return runs, 6) and hysteresis_step (their step down in "
                      "twist, 0.025 of the onset)",
}
