"""The wheel on a discretely supported rail: limits and the independent physics model's numbers."""

from __future__ import annotations

import numpy as np
import pytest

from app.analysis.stiffness.track_dynamics import (
    TrackParameters,
    excitation_roughness,
    point_receptance,
    resonance_frequency,
    sleeper_passage_amplitude,
    wheel_accelerance,
)

#: (ballast stiffness MN/m, speed m/s, sleeper-passage amplitude m/s²) from the physics
#: reference runs (../shared/physics/cases.csv, A_lockin): an independent FE model.
PHYSICS_CASES = [(20, 20, 0.5037), (40, 27.5, 1.6944), (80, 15, 0.2555), (80, 30, 2.2188),
                 (80, 35, 5.6871), (80, 45, 2.3427), (110, 50, 2.9967), (160, 27.5, 1.3274),
                 (320, 35, 2.8904), (320, 50, 53.8229)]
#: Coupled wheel–track resonance of the physics model (README: 39 Hz at 20 MN/m … 85 Hz at 320 MN/m).
PHYSICS_RESONANCE_HZ = {20: 39.0, 80: 62.0, 160: 75.0, 320: 85.0}


def _p(k_mnm: float) -> TrackParameters:
    return TrackParameters(ballast_stiffness=k_mnm * 1e6)


def test_static_receptance_is_softer_between_sleepers_and_on_soft_ballast() -> None:
    a = point_receptance(_p(80), np.zeros(1), np.array([0.0, 0.3]))[0]
    assert np.all(np.abs(a.imag) < 1e-6 * np.abs(a.real))  # no damping force at 0 Hz
    assert a[1].real > a[0].real > 0
    soft = point_receptance(_p(20), np.zeros(1), np.array([0.0]))[0, 0].real
    assert soft > 1.5 * a[0].real
    # a Winkler beam with the supports smeared out bounds the deflection from below
    p = _p(80)
    ks = 1 / (1 / p.pad_stiffness + 1 / p.ballast_stiffness) / p.sleeper_spacing
    beta = (ks / (4 * p.rail_bending_stiffness)) ** 0.25
    winkler = beta / (2 * ks)
    assert winkler < a[0].real < 1.6 * winkler
    r = excitation_roughness(p, 3)
    assert r[0] > r[1] > 0 and r[0] == pytest.approx(p.static_load * (a[1].real - a[0].real) / 2, rel=0.35)


def test_wheel_follows_roughness_at_low_frequency() -> None:
    f = np.array([2.0, 4.0])
    h = wheel_accelerance(_p(80), f)
    np.testing.assert_allclose(h, (2 * np.pi * f) ** 2, rtol=0.02)


@pytest.mark.parametrize("k, f_phys", sorted(PHYSICS_RESONANCE_HZ.items()))
def test_resonance_within_2_hz_of_the_physics_model(k, f_phys) -> None:
    assert abs(resonance_frequency(_p(k)) - f_phys) <= 2.0


def test_amplitudes_close_to_the_physics_model() -> None:
    ratio = np.array([sleeper_passage_amplitude(_p(k), np.array([float(v)]))[0] / a for k, v, a in PHYSICS_CASES])
    assert np.all((ratio > 0.8) & (ratio < 1.25)), ratio.round(3)
    assert abs(np.median(ratio) - 1) < 0.1


def test_argument_checks() -> None:
    with pytest.raises(ValueError, match="positions_m"):
        point_receptance(_p(80), np.zeros(1), np.array([0.01]))
    with pytest.raises(ValueError, match="speed_mps"):
        sleeper_passage_amplitude(_p(80), np.array([0.0]))
    with pytest.raises(ValueError, match="harmonic"):
        sleeper_passage_amplitude(_p(80), np.array([10.0]), harmonic=4)
    with pytest.raises(ValueError, match="ballast_stiffness"):
        TrackParameters(ballast_stiffness=-1.0)


#: Physics sweep at 80 MN/m (cases.csv): speed m/s, lock-in amplitude m/s².
PHYSICS_K80 = [(15, 0.2555), (20, 0.5247), (25, 1.0334), (27.5, 1.4389), (30, 2.2188), (35, 5.6871),
               (40, 4.4730), (42.5, 3.1204), (45, 2.3427), (50, 1.5111), (55, 1.2530), (60, 1.5394)]


def test_support_stiffness_from_passes_at_several_speeds() -> None:
    from app.analysis.stiffness.support_stiffness import (
        estimate_support_stiffness,
        model_log_amplitudes,
    )

    v = np.array([s for s, _ in PHYSICS_K80])
    a = np.array([x for _, x in PHYSICS_K80])
    est = estimate_support_stiffness(v, a)  # the shape against speed only
    assert 70 < est.k_mnm < 90 and est.k_interval_mnm[0] <= est.k_mnm <= est.k_interval_mnm[1]
    assert not est.at_grid_edge and est.rms_log_residual < 0.15
    # own model, 5 % noise, three passes: the right stiffness within its interval
    rng = np.random.default_rng(1)
    p = _p(150)
    speeds = np.array([22.0, 33.0, 45.0])
    amp = sleeper_passage_amplitude(p, speeds) * 2.0 * np.exp(0.05 * rng.standard_normal(3))
    k_grid = np.geomspace(20, 600, 61)
    est = estimate_support_stiffness(speeds, amp, k_grid_mnm=k_grid,
                                     model=model_log_amplitudes(TrackParameters(), speeds, k_grid))
    assert est.k_interval_mnm[0] <= 150 <= est.k_interval_mnm[1] and abs(est.log_scale - np.log(2)) < 0.2
    with pytest.raises(ValueError, match="at least 3"):
        estimate_support_stiffness(speeds[:2], amp[:2])
