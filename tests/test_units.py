"""rodphase.units: the paper's controls and SI, each mapping against its inverse and a hand value."""

import math

import numpy as np
import pytest

from rodphase import units as U

E, A0, L0 = 1.0e6, 0.025, 1.0  # the paper's rod: Pa, m, m


def test_critical_force_is_eulers():
    # π² E I / L², I = π a⁴/4: 1e6 × π × 0.025⁴/4 = 0.306796 N m², × π² = 3.02796 N
    assert U.critical_force(E, A0, L0) == pytest.approx(3.02796, rel=1e-5)
    assert U.critical_force(E, A0, L0) == pytest.approx(
        math.pi**2 * E * U.second_moment_of_area(A0) / L0**2, rel=1e-15)


@pytest.mark.parametrize("extension", [1.0, 1.05, 1.3, 2.0])
def test_load_and_extension_are_inverse(extension):
    force = U.load_for_extension(E, A0, extension)
    # incompressible, the paper's law: F = E A0 (1 − 1/e), so e = 1.3 takes 0.2308 E A0
    assert force == pytest.approx(E * math.pi * A0**2 * (1 - 1 / extension), rel=1e-15)
    assert U.extension_under_load(E, A0, force) == pytest.approx(extension, rel=1e-14)


@pytest.mark.parametrize("phi_a", [0.0, 0.8, 2.6, -1.2])
def test_twist_density_and_turns_are_inverse_in_both_readings(phi_a):
    turns = U.turns_for_twist_density(phi_a, A0, L0)
    assert turns == pytest.approx(phi_a * 40 / (2 * math.pi), rel=1e-15)  # L0/a0 = 40
    assert U.twist_density_for_rotation(turns * U.TURN, A0, L0) == pytest.approx(phi_a, abs=1e-15)
    e = 1.16
    current_turns = U.turns_for_current_twist_density(phi_a, A0, L0, e)
    rest = U.twist_density_for_rotation(current_turns * U.TURN, A0, L0)
    # the stretched straight rod: radius a0/√e, length e L0, so Φa_current = θ (a0/√e)/(e L0)
    assert current_turns * U.TURN * (A0 / math.sqrt(e)) / (e * L0) == pytest.approx(phi_a, abs=1e-14)
    assert U.current_twist_density(rest, e) == pytest.approx(phi_a, abs=1e-14)
    assert U.rest_twist_density(U.current_twist_density(rest, e), e) == pytest.approx(rest, abs=1e-14)


def test_arrays_go_through_the_twist_conversions():
    rotation = np.linspace(0, 10 * U.TURN, 5)
    np.testing.assert_allclose(U.twist_density_for_rotation(rotation, A0, L0),
                               rotation * A0 / L0, rtol=1e-15)
    np.testing.assert_allclose(U.current_twist_density(np.ones(3), np.array([1.0, 4.0, 9.0])),
                               [1.0, 1 / 8, 1 / 27], rtol=1e-15)
