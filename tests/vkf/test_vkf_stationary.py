"""Stationary orders (issue 26): an order that is a function of its own frequency does not take a wide
order's changes at its line, and is itself recovered, also when its response changes with frequency."""

from __future__ import annotations

import numpy as np
import pytest

from app.analysis.vkf import CLOSE_ORDERS_MESSAGE, VKFWarning, vkf
from app.analysis.vkf._stationary import fit_over_log_frequency

FS = 2000.0


def test_fit_is_the_mean_at_one_frequency_and_exact_for_a_line_in_log_frequency():
    rng = np.random.default_rng(0)
    n = 4000
    values = (2.0 + 0.5j) + 0.1 * (rng.standard_normal(n) + 1j * rng.standard_normal(n))
    fit = fit_over_log_frequency(values[None], np.full(n, 58.0), np.ones(n, bool))
    assert fit(np.array([58.0]))[0, 0] == pytest.approx(values.mean(), abs=1e-12)
    f = np.linspace(50.0, 70.0, n)  # a run-up
    line = (1.0 - 2.0j) + (0.3 + 0.4j) * np.log(f / 50.0)
    fit = fit_over_log_frequency(np.vstack([line, 2 * line]), f, np.ones(n, bool))
    np.testing.assert_allclose(fit(f), np.vstack([line, 2 * line]), rtol=0, atol=1e-7)
    # a response like a wheel polygon's (∝ f², phase turning) over ±15 %: followed locally
    resp = 1e-3 * f**2 * np.exp(0.02j * (f - 50.0))
    err = np.abs(fit_over_log_frequency(resp[None], f, np.ones(n, bool))(f)[0] - resp) / np.abs(resp)
    assert err.max() < 1e-3


def test_fit_arguments():
    assert fit_over_log_frequency(np.ones((1, 3)), np.full(3, 50.0), np.zeros(3, bool)) is None
    with pytest.raises(ValueError, match="rel_width"):
        fit_over_log_frequency(np.ones((1, 3)), np.full(3, 50.0), np.ones(3, bool), rel_width=0.0)


def _step_and_line(freq_scale: np.ndarray | float = 1.0, line_power: float = 0.0):
    """A wide order at 58 Hz whose envelope steps 1 → 3 (and turns 1 rad) at 10 s, and a narrow line at
    60.2 Hz (0.18 of 12 Hz apart: wheel order 5 beside f_s) of amplitude 2·(f/60.2)^line_power."""
    n = int(20 * FS)
    t = np.arange(n) / FS
    scale = np.broadcast_to(np.asarray(freq_scale, dtype=float), (n,))
    f = np.vstack([58.0 * scale, 60.2 * scale])
    phi = 2 * np.pi * np.cumsum(f, axis=1) / FS
    wide = np.where(t < 10.0, 1.0, 3.0 * np.exp(1j))
    line = 2.0 * (f[1] / 60.2) ** line_power * np.exp(0.7j)
    y = (wide * np.exp(1j * phi[0])).real + (line * np.exp(1j * phi[1])).real
    return y, f, t, wide, line


@pytest.mark.parametrize("stationary", [None, [False, True]])
def test_a_stationary_line_does_not_take_the_wide_orders_step(stationary):
    y, f, t, wide, line = _step_and_line()
    with pytest.warns(VKFWarning, match=CLOSE_ORDERS_MESSAGE):  # 58 and 60.2 Hz: closer than the 10 Hz band
        res = vkf(y, FS, f, np.array([10.0, 1.2]), 2, stationary=stationary)
    env = res.envelope
    after = (t > 10.4) & (t < 12.0)  # 0.4–2 s after the step: the wide filter has settled
    dev = np.max(np.abs(np.abs(env[0, after]) - 3.0)) / 2.0  # share of the step
    if stationary is None:
        assert dev > 0.03  # the joint solve rings: the line took part of the step
    else:
        assert dev < 0.005
        inner = (t > 1.0) & (t < 19.0)
        assert np.max(np.abs(env[1, inner] - line[inner])) < 0.01 * 2.0
        assert res.info["chunks"][0]["stationary_orders"] == [1]


def test_a_stationary_line_follows_its_response_over_a_speed_ramp():
    """30 % faster over 20 s (0.45 m/s² at 30 m/s), the line's amplitude ∝ ω² like a wheel polygon's: the
    fit follows it; near the step the kernel (±1 % of the frequency: ±0.7 s here) is about as local as
    the narrow filter, so the gain over the joint solve shrinks there (measured 4.2 % → 3.6 % of the step)."""
    n = int(20 * FS)
    scale = np.linspace(1.0, 1.3, n)
    y, f, t, wide, line = _step_and_line(scale, line_power=2.0)
    bw = np.vstack([10.0 * scale, 1.2 * scale])
    with pytest.warns(VKFWarning, match=CLOSE_ORDERS_MESSAGE):
        res = vkf(y, FS, f, bw, 2, stationary=np.array([False, True]))
    with pytest.warns(VKFWarning, match=CLOSE_ORDERS_MESSAGE):
        joint = vkf(y, FS, f, bw, 2)
    inner = (t > 1.0) & (t < 19.0)
    far = inner & (np.abs(t - 10.0) > 2.0)
    err_line = np.abs(res.envelope[1] - line) / np.abs(line)
    assert err_line[far].max() < 0.005
    err_wide, err_joint = (np.abs(r.envelope[0] - wide) / 2.0 for r in (res, joint))
    assert err_wide[far].max() < 0.005
    near = inner & (np.abs(t - 10.0) > 0.4) & ~far
    assert err_wide[near].max() < err_joint[near].max()


def test_stationary_argument_is_checked():
    y, f, *_ = _step_and_line()
    with pytest.raises(ValueError, match="stationary"):
        vkf(y, FS, f, 2.0, stationary=[True])
    with pytest.raises(ValueError, match="stationary"):
        vkf(y, FS, f, 2.0, stationary=np.array([1, 0]))
    with pytest.raises(ValueError, match="stationary"):
        vkf(y, FS, f, 2.0, stationary=[True, True])
    with pytest.warns(VKFWarning, match=CLOSE_ORDERS_MESSAGE):
        plain = vkf(y, FS, f, np.array([10.0, 1.2]))
    with pytest.warns(VKFWarning, match=CLOSE_ORDERS_MESSAGE):
        none = vkf(y, FS, f, np.array([10.0, 1.2]), stationary=[False, False])
    np.testing.assert_array_equal(plain.envelope, none.envelope)
