"""The paper's dimensionless controls and SI, in both directions, in one place.

Charles, Gazzola & Mahadevan describe a twisted, stretched filament by two numbers:
- the extension e = L/L0 of an incompressible rod under a constant end load F. With A·e
  constant (a = a0/√e), the paper's law gives F = E·A0·(1 − 1/e), and back e = 1/(1 − F/(E·A0));
  loads are also quoted as multiples of the Euler force F_C = π²·E·I0/L0² (I0 = π·a0⁴/4);
- the twist density Φa = θ·a0/L0 of an end rotation θ, with the rest radius a0 and rest length
  L0 (the paper's definition, "rest" reading). The straight stretched rod has radius a0/√e and
  length e·L0, so its own twist density ("current" reading) is θ·(a0/√e)/(e·L0) = Φa/e^1.5.

Everything else in rodphase converts through these functions (SI in, SI out; rotations in
radians unless the name says turns). The operation order inside each is the one the scenes
were built with, so refactoring onto them changed no result.
"""

from __future__ import annotations

import math

TURN = 2.0 * math.pi  # rad


def cross_section_area(radius: float) -> float:
    """A = π a² [m²]."""
    return math.pi * radius**2


def second_moment_of_area(radius: float) -> float:
    """I = π a⁴/4 [m⁴], about a diameter."""
    return math.pi * radius**4 / 4.0


def buckling_force(bending_stiffness: float, length: float) -> float:
    """F_C = π² B / L0² [N], the unit of the paper's loads (the Euler load of a pinned rod),
    for a bending stiffness B [N m²]: the one definition (Rod.buckling_force and the config's
    force_multiple both use it)."""
    return math.pi**2 * bending_stiffness / length**2


def critical_force(youngs_modulus: float, radius: float, length: float) -> float:
    """F_C = π² E I0 / L0² [N] of a solid circular rod (buckling_force with B = E·π·a0⁴/4,
    its product kept in this order: the shipped loads are bit-identical to before)."""
    return math.pi**2 * youngs_modulus * math.pi * radius**4 / 4.0 / length**2


def paper_shear_modulus(youngs_modulus: float) -> float:
    """G = 2E/3 [Pa], as the paper states it: E/(1 + ν) with ν = ½, twice the textbook
    E/(2(1 + ν)) of an incompressible solid. The one place it is written."""
    return 2.0 * youngs_modulus / 3.0


def load_for_extension(youngs_modulus: float, radius: float, extension: float,
                       law: str = "paper") -> float:
    """F = E·A0·(1 − 1/e) [N]: the constant load that stretches the straight rod to L/L0 = e;
    with law="neo_hookean", F = E·A0/3·(e − 1/e²) (rod/neo_hookean.py)."""
    if law == "neo_hookean":
        return youngs_modulus * cross_section_area(radius) / 3.0 * (extension - extension**-2)
    return youngs_modulus * math.pi * radius**2 * (1.0 - 1.0 / extension)


def extension_under_load(youngs_modulus: float, radius: float, force: float,
                         law: str = "paper") -> float:
    """e = 1/(1 − F/(E·A0)): L/L0 of the straight rod under the load F (inverse of the above).
    With law="neo_hookean" the root of e³ − 3f·e² − 1 = 0, f = F/(E·A0), by Newton (the
    tension rises monotonically with e, so the root is unique)."""
    if law == "neo_hookean":
        f = force / (youngs_modulus * cross_section_area(radius))
        e = 1.0 + f
        for _ in range(50):
            step = (e**3 - 3.0 * f * e**2 - 1.0) / (3.0 * e**2 - 6.0 * f * e)
            e -= step
            if abs(step) < 1e-15 * e:
                break
        return e
    return 1.0 / (1.0 - force / (youngs_modulus * cross_section_area(radius)))


def turns_for_twist_density(twist_density: float, radius: float, length: float) -> float:
    """End rotation [turns] that gives the paper's Φa = θ·a0/L0 (rest radius and length)."""
    return twist_density * length / radius / TURN


def twist_density_for_rotation(rotation: float, radius: float, length: float):
    """Φa = θ·a0/L0 of an end rotation θ [rad] (works on arrays as well)."""
    return rotation * radius / length


def turns_for_current_twist_density(twist_density: float, radius: float, length: float,
                                    extension: float) -> float:
    """End rotation [turns] that gives the straight stretched rod the twist density Φa, in the
    current reading θ·(a0/√e)/(e·L0)."""
    return twist_density * length * extension**1.5 / radius / TURN


def current_twist_density(rest_twist_density, extension):
    """Φa of the straight stretched rod (current reading) from the paper's rest Φa."""
    return rest_twist_density / extension**1.5


def rest_twist_density(current, extension):
    """The paper's rest Φa from the current reading (inverse of current_twist_density)."""
    return current * extension**1.5
