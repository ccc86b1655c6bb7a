"""Closed-form references that figures compare against (no simulation here).

The tests check these against the literature's numbers; the kernel never uses them (the
quasi-static start of the twist_under_load scene uses the straight rod's buckling twist).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import brentq

from . import units


def greenhill_clamped_moment(tension: float, length: float, bending: float) -> float:
    """Smallest axial moment M [N m] at which a straight rod clamped at both ends, under
    tension T [N], buckles (the clamped Greenhill problem): the first root of
    u1·u2·sin(u1 − u2) = (u1 − u2)·sin u1·sin u2 with u = L·(M ± √(M² − 4BT))/(4B).
    M_c·L/B = 8.9868 at T = 0 and 20.9835 at T·L²/B = 100; M_c → 2√(BT) for long rods.
    """

    # the equation is 0/0 at T = 0 itself; T·L²/B = 1e-9 moves M_c by ~1e-10 relative
    tension = max(tension, 1e-9 * bending / length**2)

    def f(m):
        d = np.sqrt(np.maximum(m * m - 4 * bending * tension, 0.0))
        u1, u2 = length * (m + d) / (4 * bending), length * (m - d) / (4 * bending)
        # both sides vanish like u2² as T → 0; dividing by it keeps the root well conditioned
        return (u1 * u2 * np.sin(u1 - u2) - (u1 - u2) * np.sin(u1) * np.sin(u2)) / u2**2

    lo = 2 * math.sqrt(bending * tension) * (1 + 1e-9) + 1e-9
    grid = np.linspace(lo, lo + 40 * bending / length, 4000)
    values = f(grid)  # the first sign change brackets the smallest root
    change = np.flatnonzero((values[:-1] == 0) | (np.sign(values[:-1]) != np.sign(values[1:])))
    if not len(change):
        raise ValueError(f"no clamped Greenhill root for T = {tension:g} N, L = {length:g} m")
    i = change[0]
    return brentq(lambda m: float(f(m)), grid[i], grid[i + 1])


def stretched_rod_buckling_moments(force: float, youngs_modulus: float, radius: float,
                                   length: float) -> tuple[float, float, float]:
    """(e, clamped Greenhill M_c, 2√(B·F)) for the incompressible rod of rest radius `radius`
    and rest length `length` stretched by an axial force: e = 1/(1 − F/(E·A0)), and the
    straight stretched rod has length e·L0 and bending stiffness B/e² (I = I0/e²)."""
    bending = youngs_modulus * units.second_moment_of_area(radius)
    e = units.extension_under_load(youngs_modulus, radius, force)
    return (e, greenhill_clamped_moment(force, e * length, bending / e**2),
            long_rod_buckling_moment(force, bending / e**2))


def long_rod_buckling_moment(tension: float, bending: float) -> float:
    """M_c = 2√(B·T) [N m], the buckling moment of a long rod under tension."""
    return 2.0 * math.sqrt(bending * tension)


def straight_rod_buckling_turns(force: float, youngs_modulus: float, shear_modulus: float,
                                radius: float, length: float) -> float:
    """Turns of end rotation at which the straight incompressible rod of rest radius `radius`
    and rest length `length`, stretched by `force` [N] and clamped at both ends, buckles by
    the clamped Greenhill criterion (the paper's law: B = E·I0/e², G·J = G·J0/e² at
    L = e·L0): θ_c = M_c·e·L0/(G·J0/e²) = M_c·e³·L0/(G·J0), in turns θ_c/2π."""
    e = units.extension_under_load(youngs_modulus, radius, force)
    second = units.second_moment_of_area(radius)
    return stretched_greenhill_turns(force, e, length, youngs_modulus * second,
                                     shear_modulus * 2.0 * second)


def stretched_greenhill_turns(tension: float, extension: float, length: float, bending: float,
                              twist: float) -> float:
    """The clamped Greenhill twist [turns] of a rod of rest length `length`, rest bending and
    twist stiffnesses `bending`, `twist` [N m²], stretched to `extension` e by `tension` [N]
    with the paper's incompressible thinning (B/e², C/e² at length e·L0), unshearable:
    θ_c = M_c(T, e·L0, B/e²)·e·L0/(C/e²)."""
    e = extension
    moment = greenhill_clamped_moment(tension, e * length, bending / e**2)
    return moment * e * length / (twist / e**2) / units.TURN
