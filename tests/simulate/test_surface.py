"""The simulator's running surfaces: roughness fixed to the track, grinding, welds, wheel flats, the contact filter.

Roughness follows Sato's spectrum (closed-form RMS per band), is the same wherever and however often a stretch is
made, changes only where and from when a grinding action applies; its response goes through the wheel–track
dynamics of app.analysis.stiffness.track_dynamics (the FIR against the model's own transfer function), and
the runs of one line carry the same surface.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.signal import welch

from app.analysis.stiffness.track_dynamics import TrackParameters, wheel_rail_transfer
from app.io import open_run
from app.simulate.contact import ContactFilter
from app.simulate.run import Confounders, SimulationConfig, plan_run, simulate_run
from app.simulate.speed import SpeedProfile
from app.simulate.surface import (
    ROUGHNESS_STEP_M,
    RailGrinding,
    RailSurface,
    RoughnessSpectrum,
    TrackImpact,
    generate_surface,
)
from app.simulate.track import TrackSection, generate_line
from app.simulate.truth import load_truth
from app.simulate.wheels import WheelFlat, WheelOOR


def test_roughness_follows_the_sato_spectrum():
    surface = RailSurface(11)
    x, h = surface.roughness(1, 5000.0, 9000.0)
    assert np.allclose(np.diff(x), ROUGHNESS_STEP_M)
    spec = surface.spectrum
    assert spec.rms() == pytest.approx(68.8e-6, rel=0.01)  # the physics README: 69 µm over 0.05–3 m
    assert spec.rms((0.3, 1.2)) == pytest.approx(26.6e-6, rel=0.01)
    k, p = welch(h, fs=1 / ROUGHNESS_STEP_M, nperseg=2**16)
    for band in ((0.05, 0.3), (0.3, 1.2), (1.2, 2.5)):
        m = (k >= 1 / band[1]) & (k <= 1 / band[0])
        assert math.sqrt(np.trapezoid(p[m], k[m])) == pytest.approx(spec.rms(band), rel=0.12), band


def test_roughness_is_fixed_to_the_track():
    surface = RailSurface(5)
    x, h = surface.roughness(2, 1000.0, 1400.0)
    x2, h2 = surface.roughness(2, 1200.0, 1250.0)
    i = int(np.argmin(np.abs(x - x2[0])))
    np.testing.assert_allclose(h[i : i + x2.size], h2, rtol=0, atol=1e-15)  # any stretch alone agrees with a longer one
    _, other_rail = surface.roughness(1, 1000.0, 1400.0)
    assert abs(np.corrcoef(h, other_rail)[0, 1]) < 0.1  # the rails are independent
    _, fine = surface.roughness(2, 1000.0, 1400.0, min_wavelength_m=0.2)
    assert np.corrcoef(h, fine)[0, 1] > 0.99  # coarse sampling leaves the long waves as they were
    with pytest.raises(ValueError, match="side"):
        surface.roughness(3, 0.0, 1.0)


def test_grinding_changes_the_roughness_from_its_date_on_where_it_applies():
    plain = RailSurface(8)
    ground = plain.with_grindings([RailGrinding(1100.0, 1300.0, "2024-06-01", roughness_scale=0.3)])
    x, before = plain.roughness(1, 1000.0, 1400.0, on="2025-01-01")
    _, same = ground.roughness(1, 1000.0, 1400.0, on="2024-05-31")
    _, after = ground.roughness(1, 1000.0, 1400.0, on="2024-06-01")
    np.testing.assert_allclose(before, same, rtol=0, atol=1e-15)  # before the action: the rail as it was
    outside = (x < 1099.0) | (x > 1301.0)
    np.testing.assert_allclose(after[outside], before[outside], rtol=0, atol=1e-15)
    inside = (x > 1101.0) & (x < 1299.0)
    assert after[inside].std() == pytest.approx(0.3 * before[inside].std(), rel=0.25)
    assert abs(np.corrcoef(after[inside], before[inside])[0, 1]) < 0.2  # a new surface, not the old one scaled


def test_welds_are_cosine_dips_on_both_rails():
    s = generate_surface(0.0, 2000.0, 4)
    welds = [w for w in s.impacts if w.kind == "weld"]
    pos = sorted({w.track_m for w in welds})
    assert 9 <= len(pos) <= 20 and np.all(np.diff(pos) >= 100.0) and np.all(np.diff(pos) <= 200.0)
    assert all(sum(1 for w in welds if w.track_m == p) == 2 for p in pos)  # both rails
    assert all(0.2e-3 <= w.depth_m <= 0.4e-3 and 0.8 <= w.length_m <= 1.2 for w in welds)
    w = TrackImpact(100.0, 1.0, 0.3e-3, 1)
    assert w.height(np.array([100.0]))[0] == pytest.approx(-0.3e-3)
    assert w.height(np.array([99.4, 100.6])).tolist() == [0.0, 0.0]
    x, h = RailSurface(1, None, (w,)).profile(1, 90.0, 110.0)
    assert h.min() == pytest.approx(-0.3e-3, rel=1e-3) and h[np.abs(x - 100) > 0.5].max() == 0.0
    with pytest.raises(ValueError, match="depth_m"):
        TrackImpact(0.0, 1.0, -1e-3, 1)


def test_wheel_flat_is_met_once_per_revolution():
    flat = WheelFlat(0.04, 0.2e-3, angle_rad=1.0)
    d = 0.92
    s = np.arange(0.0, 3 * math.pi * d, 1e-4)
    h = flat.height(s, d)
    centre = 1.0 * d / 2
    assert h.min() == pytest.approx(-0.2e-3, rel=1e-3)
    assert s[np.argmin(h)] == pytest.approx(centre, abs=2e-4)
    assert (h < 0).sum() * 1e-4 == pytest.approx(3 * 0.04, rel=0.01)  # 40 mm per revolution
    assert flat.height(np.array([centre + math.pi * d]), d)[0] == pytest.approx(-0.2e-3)
    with pytest.raises(ValueError, match="length_m"):
        WheelFlat(length_m=1.0)


@pytest.mark.parametrize("f0", [15.0, 58.0, 200.0, 900.0])
def test_contact_filter_is_the_wheel_track_transfer_function(f0):
    p = TrackParameters()
    filt = ContactFilter(p, 10_000.0)
    t = np.arange(filt.history + 40_000 + filt.lookahead) / 1e4
    y = filt.apply(1e-5 * np.cos(2 * np.pi * f0 * t))
    tt = t[filt.history : filt.history + y.size]
    got = 2 * np.mean(y * np.exp(-2j * np.pi * f0 * tt)) / 1e-5
    want = wheel_rail_transfer(p, np.array([f0]))[0]
    assert abs(got) == pytest.approx(abs(want), rel=0.01)
    assert np.angle(got / want) == pytest.approx(0.0, abs=0.01)


def _line(surface, typ="b91_no_pads"):
    return generate_line(11_900.0, 12_500.0, 1, sections=[TrackSection(11_900.0, 12_500.0, typ)], anomalies=[],
                         variation_std=0.0, surface=surface)


def test_runs_of_a_line_meet_the_same_surface(tmp_path: Path):
    line = _line(RailSurface(2, impacts=(TrackImpact(12_200.0, 1.0, 0.3e-3, 1),)))
    kw = {"length_km": 0.3, "fs": 5000.0, "line": line}
    a = plan_run(SimulationConfig(seed=1, speed_profile=SpeedProfile.constant(30.0), **kw))
    b = plan_run(SimulationConfig(seed=2, speed_profile=SpeedProfile.constant(45.0), **kw))
    for side in (1, 2):
        xa, _, ha = a.surface[side]
        xb, _, hb = b.surface[side]
        i = int(round((xb - xa) / ROUGHNESS_STEP_M))
        n = min(ha.size - i, hb.size)
        np.testing.assert_allclose(ha[i : i + n], hb[:n], atol=1e-12)
    later = plan_run(SimulationConfig(seed=1, speed_profile=SpeedProfile.constant(30.0),
                                      start_time="2025-03-01T08:00:00+01:00",
                                      **{**kw, "line": _line(line.surface.with_grindings(
                                          [RailGrinding(12_000.0, 12_400.0, "2025-01-10")]))}))
    assert not np.allclose(later.surface[1][2], a.surface[1][2])  # ground since the first run


def test_confounders_on_and_off(tmp_path: Path):
    line = _line(RailSurface(2, impacts=(TrackImpact(12_100.0, 1.0, 0.3e-3, 1), TrackImpact(12_100.0, 1.0, 0.3e-3, 2))))
    wheels = {w: WheelOOR(w, 0.92, np.zeros(11), np.zeros(11)) for w in ("11", "12", "41", "42")}
    kw = {"length_km": 0.2, "fs": 5000.0, "seed": 3, "speed_profile": SpeedProfile.constant(35.0), "line": line,
          "wheels": wheels, "noise_std": 0.0, "with_forces": False}
    off = simulate_run(tmp_path / "off.h5", confounders=Confounders(False, False, False), **kw)
    on = simulate_run(tmp_path / "on.h5", wheel_flats={"11": WheelFlat()}, **kw)
    plain = simulate_run(tmp_path / "plain.h5", **{**kw, "line": _line(None)})
    with open_run(off.run_path) as r0, open_run(on.run_path) as r1, open_run(plain.run_path) as r2:
        np.testing.assert_array_equal(r0.read("Z11"), r2.read("Z11"))  # switched off = smooth rails
        z0, z1 = r0.read("Z11"), r1.read("Z11")
        assert np.std(z1 - z0) > 5 * np.std(z0) / 10  # roughness, the weld and the flat add a lot
    truth = load_truth(on.truth_path)
    assert truth.wheels["11"].flat == WheelFlat() and truth.wheels["12"].flat is None
    assert truth.line.surface == line.surface
    assert [w.track_m for w in truth.track_impacts("11")] == [12_100.0]
    assert truth.switch("roughness") and truth.run_date == "2024-05-01"
    assert not load_truth(off.truth_path).track_impacts("11")


def test_roughness_raises_the_sleeper_order_like_the_physics(tmp_path: Path):
    """Qualitatively as ../shared/physics/rough_k80_v35 against its smooth twin (+40 % in the product's
    10 m means there): the roughness answers near f_s and the indicator reads tens of per cent high."""
    from app.analysis.settings import ProcessingSettings
    from app.pipeline import run_pipeline

    line = _line(RailSurface(1))
    kw = {"length_km": 0.4, "fs": 10_000.0, "seed": 1, "speed_profile": SpeedProfile.constant(35.0), "line": line,
          "noise_std": 0.5, "with_forces": False}
    out = {}
    for name, sw in (("smooth", Confounders(False, False, False)), ("rough", Confounders())):
        truth = simulate_run(tmp_path / f"{name}.h5", confounders=sw, **kw)
        p = run_pipeline(truth.run_path, ProcessingSettings(), tmp_path / f"w-{name}").profiles
        p = p[p["wheel"] == "11"].sort_values("bin")
        out[name] = ((p["bin"].to_numpy() + 0.5) * 0.25, p["sleeper_amp"].to_numpy())
    x, smooth = out["smooth"]
    rough = out["rough"][1]
    edges = np.arange(12_020.0, 12_380.0, 10.0)
    ratio = np.array([rough[(x >= a) & (x < a + 10)].mean() / smooth[(x >= a) & (x < a + 10)].mean() for a in edges])
    assert 1.1 < np.median(ratio) < 2.5
    assert np.sqrt(np.mean((ratio - 1) ** 2)) > 0.2  # and it scatters from one 10 m to the next


def test_config_object_and_keywords_make_the_same_run(tmp_path: Path):
    kw = {"length_km": 0.1, "fs": 2000.0, "seed": 6, "rail_surface": True}
    a = simulate_run(tmp_path / "a.h5", **kw)
    b = simulate_run(tmp_path / "b.h5", SimulationConfig(**kw))
    c = simulate_run(tmp_path / "c.h5", SimulationConfig(seed=99, length_km=0.1, fs=2000.0, rail_surface=True), seed=6)
    with open_run(a.run_path) as ra, open_run(b.run_path) as rb, open_run(c.run_path) as rc:
        for ch in ra.channels:
            np.testing.assert_array_equal(ra.read(ch), rb.read(ch))
            np.testing.assert_array_equal(ra.read(ch), rc.read(ch))
    assert a.line.surface is not None and a.line.surface == b.line.surface
    with pytest.raises(ValueError, match="wheel_flats"):
        SimulationConfig(wheel_flats={"13": WheelFlat()})
    with pytest.raises(ValueError, match="confounders"):
        SimulationConfig(confounders=True)  # type: ignore[arg-type]
    assert RoughnessSpectrum().wavelength_m == (0.05, 3.0)
