"""simulate_run: the written signals are exactly the documented model of the truth."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from app.io import WHEELS, open_run
from app.simulate.run import simulate_run
from app.simulate.speed import SpeedProfile
from app.simulate.track import SUPERSTRUCTURE_TYPES, generate_line
from app.simulate.truth import load_truth

FS = 4000.0
V = 30.0


def _expected_z(truth, wheel: str, s: np.ndarray, v: float) -> np.ndarray:
    """Independent reconstruction at constant speed from the truth tables."""
    bins = truth.bins[wheel]
    x = truth.track_m(s, wheel[0])
    order = np.argsort(bins.track_m)
    amp = np.interp(x, bins.track_m[order], bins.amplitude_mps2[order])
    sleeper = amp * np.cos(2 * np.pi * x / truth.sleeper_spacing_m)
    oor = truth.wheels[wheel]
    d = oor.diameter_m
    theta = 2 * s / d
    wheel_part = np.zeros_like(s)
    for ll, rho, psi in zip(oor.orders, oor.rho_um, oor.psi_rad, strict=True):
        wheel_part += rho * 1e-6 * (2 * ll * v / d) ** 2 * np.cos(ll * theta + psi + np.pi)
    return sleeper + wheel_part


@pytest.mark.parametrize("km_increasing", [True, False])
def test_clean_signal_equals_truth_components(tmp_path: Path, km_increasing: bool) -> None:
    truth = simulate_run(
        tmp_path / "run.h5",
        duration_s=2.0,
        fs=FS,
        seed=11,
        noise_std=0.0,
        force_noise_std=0.0,
        speed_profile=SpeedProfile.constant(V),
        km_increasing=km_increasing,
    )
    assert truth.n_samples == 8000
    with open_run(truth.run_path) as run:
        s = run.position()
        np.testing.assert_allclose(s, V * np.arange(8000) / FS, atol=1e-9)
        np.testing.assert_allclose(run.speed(), V)
        for w in WHEELS:
            bins = truth.bins[w]
            x = truth.track_m(s, w[0])
            inside = (x >= bins.track_m.min()) & (x <= bins.track_m.max())
            z = run.read(f"Z{w}")
            expected = _expected_z(truth, w, s, V)
            scale = np.abs(expected).max()
            assert scale > 1.0
            np.testing.assert_allclose(z[inside], expected[inside], atol=2e-6 * scale, err_msg=w)
            q = run.read(f"Q{w}")
            np.testing.assert_allclose(
                q, truth.static_load_kn + truth.unsprung_mass_kg * z / 1000.0, atol=1e-4
            )


def test_noise_and_forces(tmp_path: Path) -> None:
    kw = {"duration_s": 8.0, "fs": FS, "seed": 5, "speed_profile": SpeedProfile.constant(V)}
    clean = simulate_run(tmp_path / "clean.h5", noise_std=0.0, force_noise_std=0.0, **kw)
    noisy = simulate_run(tmp_path / "noisy.h5", noise_std=2.0, force_noise_std=0.2, **kw)
    assert noisy.noise_band_hz == (2.0, 1600.0)
    with open_run(clean.run_path) as c, open_run(noisy.run_path) as n:
        for w in WHEELS:
            noise = n.read(f"Z{w}") - c.read(f"Z{w}")  # the deterministic part is identical
            assert noise.std() == pytest.approx(2.0, rel=0.05)
            spec = np.abs(np.fft.rfft(noise)) ** 2
            f = np.fft.rfftfreq(noise.size, 1 / FS)
            assert spec[f > 1800].sum() < 0.01 * spec.sum()  # band-limited
            z, q = n.read(f"Z{w}"), n.read(f"Q{w}")
            design = np.column_stack([np.ones_like(z), z])
            (q0, slope), *_ = np.linalg.lstsq(design, q, rcond=None)
            assert slope * 1000.0 == pytest.approx(300.0, rel=0.01)  # m_u in kg
            assert q0 == pytest.approx(80.0, abs=0.02)
            assert (q - q0 - slope * z).std() == pytest.approx(0.2, rel=0.05)
    # independent noise per wheel
    with open_run(noisy.run_path) as n, open_run(clean.run_path) as c:
        n11 = n.read("Z11") - c.read("Z11")
        n12 = n.read("Z12") - c.read("Z12")
        assert abs(np.corrcoef(n11, n12)[0, 1]) < 0.05


@pytest.fixture(scope="module")
def realistic(tmp_path_factory: pytest.TempPathFactory):
    d = tmp_path_factory.mktemp("sim")
    return simulate_run(d / "run.h5", length_km=1.5, fs=2000.0, seed=2)


def test_truth_is_self_consistent(realistic) -> None:
    t = realistic
    p = t.speed_profile
    assert t.distance_m == pytest.approx(1500.0, abs=0.05)
    assert len(t.line.anomalies) >= 1 and t.line.anomalies[0].kind == "soft spot"
    for w in WHEELS:
        b = t.bins[w]
        np.testing.assert_allclose(
            b.amplitude_mps2, b.amplitude_vref_mps2 * t.speed_response.factor(b.section, b.speed_mps)
        )
        np.testing.assert_allclose(b.speed_mps, p.speed(b.t_s))
        np.testing.assert_allclose(p.distance(b.t_s), b.s_m, atol=1e-6)
        np.testing.assert_allclose(b.track_m, t.track_m(b.s_m, w[0]), atol=1e-6)
        np.testing.assert_array_equal(b.bin, np.floor(b.track_m / 0.25).astype(np.int64))
        assert np.all(np.diff(b.track_m) == 0.25)  # one row per bin, along the run
        assert abs(len(b) - 1500.0 / 0.25) <= 1
        for sec in t.line.sections:
            m = (b.track_m > sec.track_from_m) & (b.track_m < sec.track_to_m)
            assert np.all(b.section[m] == SUPERSTRUCTURE_TYPES.index(sec.type))
    # axle 4 runs 17.5 m behind on the same rail: same stiffness at the same bin
    b11, b41, b12 = t.bins["11"], t.bins["41"], t.bins["12"]
    assert b41.track_m[0] == pytest.approx(b11.track_m[0] - 17.5, abs=0.25)
    common, i11, i41 = np.intersect1d(b11.bin, b41.bin, return_indices=True)
    assert common.size > 5000
    np.testing.assert_array_equal(b11.stiffness_factor[i11], b41.stiffness_factor[i41])
    assert not np.array_equal(
        b11.stiffness_factor[: common.size], b12.stiffness_factor[: common.size]
    )
    # every anomaly is passed by both axles
    for an in t.line.anomalies:
        for b in (b11, b41):
            assert b.track_m.min() < an.track_from_m and an.track_to_m < b.track_m.max()


def test_run_file_matches_truth(realistic) -> None:
    t = realistic
    with open_run(t.run_path) as run:
        assert run.metadata.wheel_diameters == t.reported_diameters == t.wheel_diameters
        assert run.metadata.axle_positions == t.axle_positions
        assert run.n_samples == t.n_samples and run.fs == t.fs
        time = run.time()
        v, _, s = t.speed_profile.evaluate(time)
        np.testing.assert_allclose(run.speed(), v)
        np.testing.assert_allclose(run.position(), s)
        kmh = run.speed() * 3.6
        assert 40.0 <= kmh.min() and kmh.max() <= 200.0


def test_truth_file_round_trip(realistic) -> None:
    t = realistic
    again = load_truth(t.truth_path)
    assert again.run_path == t.run_path and again.seed == t.seed and again.n_samples == t.n_samples
    assert again.line.sections == t.line.sections and again.line.anomalies == t.line.anomalies
    np.testing.assert_array_equal(again.line.factor, t.line.factor)
    for w in WHEELS:
        np.testing.assert_array_equal(again.wheels[w].rho_um, t.wheels[w].rho_um)
        np.testing.assert_array_equal(again.wheels[w].psi_rad, t.wheels[w].psi_rad)
        for field in ("bin", "track_m", "speed_mps", "section", "amplitude_mps2"):
            np.testing.assert_array_equal(getattr(again.bins[w], field), getattr(t.bins[w], field))
    np.testing.assert_array_equal(again.speed_profile.v1, t.speed_profile.v1)
    assert again.section_table() == t.section_table()


def test_blocks_do_not_change_the_signal(tmp_path: Path) -> None:
    kw = {"length_km": 0.2, "fs": 2000.0, "seed": 8}
    a = simulate_run(tmp_path / "a.h5", block_samples=1000, **kw)
    b = simulate_run(tmp_path / "b.h5", block_samples=4096, **kw)
    with open_run(a.run_path) as ra, open_run(b.run_path) as rb:
        for c in ra.channels:
            np.testing.assert_array_equal(ra.read(c), rb.read(c), err_msg=c)


def test_same_line_for_other_runs_and_calibration(tmp_path: Path) -> None:
    line = generate_line(11_900.0, 12_400.0, seed=3)
    kw = {"duration_s": 1.0, "fs": 2000.0, "speed_profile": SpeedProfile.constant(V), "line": line}
    plain = simulate_run(tmp_path / "a.h5", seed=1, **kw)
    cal = simulate_run(
        tmp_path / "b.h5", seed=1, calibration={"Z11": {"gain": 0.01, "offset": 2.0}}, **kw
    )
    assert plain.line is line and cal.line is line
    with open_run(plain.run_path) as a, open_run(cal.run_path) as b:
        np.testing.assert_allclose(b.read("Z11"), a.read("Z11"), atol=1e-4)
        assert b.calibration("Z11") == (0.01, 2.0)
    other = simulate_run(tmp_path / "c.h5", seed=2, **kw)
    assert not np.array_equal(other.wheels["11"].rho_um, plain.wheels["11"].rho_um)


def test_argument_validation(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="at most one"):
        simulate_run(tmp_path / "x.h5", length_km=1.0, duration_s=10.0)
    with pytest.raises(ValueError, match="fs"):
        simulate_run(tmp_path / "x.h5", duration_s=1.0, fs=500.0)
    with pytest.raises(ValueError, match="line covers"):
        simulate_run(tmp_path / "x.h5", duration_s=1.0, fs=2000.0, line=generate_line(0.0, 100.0))
    with pytest.raises(ValueError, match="noise_std"):
        simulate_run(tmp_path / "x.h5", duration_s=1.0, fs=2000.0, noise_std=-1.0)
    assert list(tmp_path.iterdir()) == []


def test_an_uncalibrated_sensor_gain_scales_the_accelerations_only(tmp_path: Path) -> None:
    kw = {"duration_s": 0.5, "fs": 2000.0, "seed": 4, "speed_profile": SpeedProfile.constant(V)}
    plain = simulate_run(tmp_path / "a.h5", **kw)
    high = simulate_run(tmp_path / "b.h5", sensor_gain=1.15, **kw)
    with open_run(plain.run_path) as a, open_run(high.run_path) as b:
        np.testing.assert_allclose(b.read("Z11"), 1.15 * a.read("Z11"), rtol=1e-6, atol=1e-6)
        np.testing.assert_array_equal(b.read("Q11"), a.read("Q11"))
        assert b.calibration("Z11") == a.calibration("Z11") == (1.0, 0.0)  # nothing in the file says so
    with pytest.raises(ValueError, match="sensor_gain"):
        simulate_run(tmp_path / "c.h5", sensor_gain=0.0, **kw)
