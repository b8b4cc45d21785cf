"""OOR acceleration: the second time derivative of the contact radius."""

from __future__ import annotations

import numpy as np
import pytest

from app.simulate.speed import SpeedProfile
from app.simulate.wheels import WheelOOR, oor_acceleration, random_wheel_oor


def test_acceleration_is_second_derivative_of_contact_radius() -> None:
    oor = random_wheel_oor(np.random.default_rng(0), "11", 0.9)
    profile = SpeedProfile.from_segments(15.0, [(2.0, 25.0)])  # accelerating, |a| up to 7.9 m/s²
    fs = 200_000.0
    t = np.arange(int(2.0 * fs)) / fs
    v, a, s = profile.evaluate(t)
    r = oor.radius(2.0 * s / oor.diameter_m)
    numeric = (r[2:] - 2 * r[1:-1] + r[:-2]) * fs**2
    model = oor_acceleration(oor, s, v, a)[1:-1]
    scale = np.abs(model).max()
    assert np.abs(numeric - model).max() < 2e-4 * scale


def test_constant_speed_phase_convention() -> None:
    rho = np.zeros(11)
    psi = np.zeros(11)
    rho[4], psi[4] = 20.0, 0.7  # order 5: 20 µm at phase 0.7 rad
    oor = WheelOOR("42", 0.92, rho, psi)
    v = 40.0
    s = np.linspace(0.0, 10.0, 5001)
    acc = oor_acceleration(oor, s, np.full_like(s, v), np.zeros_like(s))
    theta = 2 * s / 0.92
    omega5 = 2 * 5 * v / 0.92
    expected = 20e-6 * omega5**2 * np.cos(5 * theta + 0.7 + np.pi)
    np.testing.assert_allclose(acc, expected, atol=1e-9 * omega5**2)
    assert oor.acceleration_amplitude(v)[4] == pytest.approx(20e-6 * omega5**2)


def test_random_oor_range() -> None:
    rng = np.random.default_rng(1)
    for _ in range(20):
        o = random_wheel_oor(rng, "41", 0.92)
        assert o.rho_um.shape == (11,) and 1.0 <= o.rho_um.min() and o.rho_um.max() <= 400.0
        assert o.rho_um[0] > o.rho_um[-1]
        assert np.all((0 <= o.psi_rad) & (o.psi_rad < 2 * np.pi))
