"""railway_residual against a direct evaluation of y − Σ Re(a_n e^{iφ_n})."""

from __future__ import annotations

import numpy as np
import pytest

from app.analysis.order_residual import railway_residual
from app.analysis.orders import railway_multipliers


def _direct(y, psi, env, step, mult):
    """Slow reference: interpolate every order linearly, sum the waveforms."""
    k = np.arange(y.size)
    grid = np.arange(env.shape[1]) * step
    x = np.zeros(y.size)
    for n, m in enumerate(mult):
        a = np.interp(k, grid, env[n].real) + 1j * np.interp(k, grid, env[n].imag)
        x += (a * np.exp(1j * m * psi)).real
    return y - x


@pytest.mark.parametrize("step, n, extra", [(1, 50, 0), (7, 1000, 1), (21, 5000, 3), (16, 160, 0)])
def test_matches_direct_evaluation(step, n, extra):
    rng = np.random.default_rng(step)
    mult = railway_multipliers(0.92, 0.6, 11)
    psi = np.cumsum(rng.uniform(0.001, 0.01, n))
    m = -(-n // step) + extra
    env = rng.normal(size=(mult.size, m)) + 1j * rng.normal(size=(mult.size, m))
    y = rng.normal(size=n)
    got = railway_residual(y, psi, env, step, mult)
    np.testing.assert_allclose(got, _direct(y, psi, env, step, mult), rtol=0, atol=1e-11)


def test_pure_orders_leave_nothing():
    """A signal made of the orders themselves has a zero residual."""
    mult = railway_multipliers(0.912, 0.6, 3)
    psi = np.linspace(0.0, 40.0, 999)
    amp = np.array([0.5, 1.0 + 0.5j, 0.2, -0.3j])
    y = sum((a * np.exp(1j * m * psi)).real for a, m in zip(amp, mult, strict=True))
    env = np.repeat(amp[:, None], 100, axis=1)
    np.testing.assert_allclose(railway_residual(y, psi, env, 10, mult), 0.0, atol=1e-12)


def test_bad_arguments_name_the_problem():
    mult = railway_multipliers(0.92, 0.6, 2)
    y, psi, env = np.zeros(10), np.zeros(10), np.zeros((3, 10), complex)
    with pytest.raises(ValueError, match="psi"):
        railway_residual(y, psi[:5], env, 1, mult)
    with pytest.raises(ValueError, match="envelope"):
        railway_residual(y, psi, env[:2], 1, mult)
    with pytest.raises(ValueError, match="step"):
        railway_residual(y, psi, env, 0, mult)
    with pytest.raises(ValueError, match="does not cover"):
        railway_residual(y, psi, env[:, :3], 2, mult)
    with pytest.raises(ValueError, match="railway orders"):
        railway_residual(y, psi, env, 1, np.array([1.0, 2.0, 5.0]))
