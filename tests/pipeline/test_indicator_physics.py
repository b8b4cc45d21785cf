"""The indicator against the independent physics runs (../shared/physics), through the real pipeline.

Uniform track: the steady bays of every physics run, tiled (bench/physics_runs.py), written as Z11 of a
canonical run and processed with the default settings: the sleeper amplitude equals the lock-in
amplitude of cases.csv within 0.05 % (measured ≤ 0.034 %), its harmonics within 1 %. Resolution: a
stiffness step and a 6 m soft spot spliced at a sleeper meet issue 15's targets, also with a 90 µm
order-5 wheel polygon added. Transitions as physics makes them (issue 26, bench/physics_transitions.py):
the transition runs, as they are and inside 1000 m of their own track, and transitions constructed from
the uniform runs at 35 and 50 m/s, against the per-bay truth.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))

from physics_runs import D_S, PHYSICS, cases, polygon, steady_unit, write_run  # noqa: E402
from physics_transitions import (  # noqa: E402
    TARGETS,
    blended_run,
    embedded_run,
    evaluate,
    meets_targets,
    physics_run,
    pipeline_profile,
    soft_level_cause,
    wheel5_projection,
)

from app.analysis.settings import ProcessingSettings  # noqa: E402
from app.pipeline import run_pipeline  # noqa: E402

pytestmark = pytest.mark.skipif(not (PHYSICS / "cases.csv").is_file(), reason="no ../shared/physics")


def _profile(tmp_path: Path, name: str, z: np.ndarray, fs: float, v: float):
    res = run_pipeline(write_run(tmp_path / f"{name}.h5", z, fs, v), ProcessingSettings(), tmp_path / f"w-{name}")
    p = res.profiles[res.profiles["wheel"] == "11"].sort_values("bin")
    return (p["bin"].to_numpy() + 0.5) * 0.25, p, res


@pytest.mark.parametrize("name", sorted(cases()) if (PHYSICS / "cases.csv").is_file() else [])
def test_uniform_amplitudes_equal_the_lock_in(tmp_path, name):
    c = cases()[name]
    unit, v, fs, nb = steady_unit(name)
    z = np.tile(unit, -(-100 // int(nb * D_S)))
    x, p, res = _profile(tmp_path, "u", z, fs, v)
    inner = p[(x > 15) & (x < x[-1] - 15)]
    for col, key in (("sleeper_amp", "A_lockin"), ("sleeper_2_amp", "A2"), ("sleeper_3_amp", "A3")):
        err = inner[col].mean() - c[key]
        # the fundamental within 0.05 % (measured ≤ 0.034 %; 0.071 % before issue 26); a harmonic within 1 %,
        # under a tenth of the fundamental within 0.1 % of the fundamental (measured worst: 2·f_s of k320
        # at 50 m/s, 0.85 beside 53.8 m/s², +3 % = 0.05 % of f_s)
        tol = 0.0005 * c[key] if key == "A_lockin" else max(0.01 * c[key], 0.001 * c["A_lockin"])
        assert abs(err) <= tol, f"{name} {col}: {err:+.4f} m/s² vs {key}"
    expect_rms = np.sqrt((c["A_lockin"] ** 2 + c["A2"] ** 2 + c["A3"] ** 2) / 2)
    assert inner["sleeper_rms"].mean() == pytest.approx(expect_rms, rel=0.01)
    assert res.meta["warnings"] == []


def _splice(v: int, k_a: int, k_b: int, bays_b: int | None, with_polygon: bool):
    ua, va, fs, na = steady_unit(f"grid_k{k_a}_v{v}.npz")
    ub, _, _, nb = steady_unit(f"grid_k{k_b}_v{v}.npz")
    lead = 100

    def bays(u, n, count):
        return np.tile(u, -(-count // n))[: count * (u.size // n)]

    parts = [bays(ua, na, lead), bays(ub, nb, lead if bays_b is None else bays_b)]
    if bays_b is not None:
        parts.append(bays(ua, na, lead))
    z = np.concatenate(parts)
    if with_polygon:
        z = z + polygon(z.size, fs, va)
    return z, fs, va, lead * D_S


@pytest.mark.parametrize("with_polygon", [False, True])
@pytest.mark.parametrize("k_a, k_b", [(40, 160), (80, 20)])
def test_step_and_soft_spot_resolution(tmp_path, k_a, k_b, with_polygon):
    """At 35 m/s (f_s 58 Hz): 40 → 160 MN/m (1.12 → 3.34 m/s²) and 80 → 20 MN/m (5.69 → 0.56 m/s²)."""
    c = cases()
    a1, a2 = c[f"grid_k{k_a}_v35.npz"]["A_lockin"], c[f"grid_k{k_b}_v35.npz"]["A_lockin"]
    z, fs, v, x0 = _splice(35, k_a, k_b, None, with_polygon)
    x, p, _ = _profile(tmp_path, "step", z, fs, v)
    sel = (x > x0 - 30) & (x < x0 + 30)
    xs, s = x[sel], (p["sleeper_amp"].to_numpy()[sel] - a1) / (a2 - a1)
    i90 = int(np.argmax(s >= 0.9))
    i10 = int(np.flatnonzero(s[:i90] < 0.1)[-1])
    x10 = np.interp(0.1, s[i10 : i10 + 2], xs[i10 : i10 + 2])
    x90 = np.interp(0.9, s[i90 - 1 : i90 + 1], xs[i90 - 1 : i90 + 1])
    i50 = i10 + int(np.argmax(s[i10 : i90 + 1] >= 0.5))
    x50 = np.interp(0.5, s[i50 - 1 : i50 + 1], xs[i50 - 1 : i50 + 1])
    assert x90 - x10 <= 6.0
    assert abs(x50 - x0) <= 2.0
    assert max(s.max() - 1.0, -s.min()) <= 0.10
    far = (x > 20) & (x < x0 - 20)
    assert abs(p["sleeper_amp"].to_numpy()[far].mean() / a1 - 1) <= 0.05  # polygon or not
    z, fs, v, x0 = _splice(35, k_a, k_b, 10, with_polygon)  # a 6 m spot of k_b in k_a
    x, p, _ = _profile(tmp_path, "spot", z, fs, v)
    centre = (x > x0 + 2.5) & (x < x0 + 3.5)
    kept = (p["sleeper_amp"].to_numpy()[centre].mean() - a1) / (a2 - a1)
    assert kept >= 0.86  # issue 15's 70 %; 86 % before issue 26, 96 % since


@pytest.mark.parametrize("name", ["trans2_v30.npz", "trans2_v42.npz"])
def test_transitions_inside_a_long_run_meet_the_targets(tmp_path, name):
    """The physics transition run inside 1000 m of its own first and last segment (the service's chunks
    are 1.5–3 km): 10–90 % width ≤ 6 m (or the physics' own + 1 m), 50 % point within 2 m, ringing ≤ 10 %
    of the step, levels 10–20 m from the edges within 3 % (before issue 26: ringing 10.5–13.5 %, widths
    17–33 m on trans2_v30; the 30 MN/m level of trans2_v42 +38.7 %)."""
    run = embedded_run(name)
    res = evaluate(*pipeline_profile(run, tmp_path), run)
    assert meets_targets(res) == {"width": True, "offset": True, "ringing": True, "levels": True}, res


@pytest.mark.parametrize("name", ["trans2_v30.npz", "trans2_v42.npz"])
def test_transition_runs_as_they_are(tmp_path, name):
    """The 160 m runs alone: the step widths and 50 % points meet the targets. What is left is the track's
    own content at the wheel-order-5 line over the record (0.088 m/s² on trans2_v30 = 10.6 % of its step,
    0.56 m/s² on trans2_v42 = 75 % of its 30 MN/m level: a 0.8 µm / 2.6 µm order-5 polygon), which a
    wheel order estimated from this record alone takes: the ripple it leaves is bounded by it."""
    run = physics_run(name)
    x, a = pipeline_profile(run, tmp_path)
    res = evaluate(x, a, run)
    line = wheel5_projection(run)
    for e, l1, l2 in zip(res["edges"], run.levels[:-1], run.levels[1:], strict=True):
        p = e["product"]
        assert p["rise"] <= TARGETS["width_m"] and abs(p["offset"]) <= TARGETS["offset_m"]
        # the ringing beyond the filter's own (≤ 5 %, q = 2 and the phase turning) is the line content
        assert p["ringing"] <= 0.05 + line / abs(l2 - l1)
    for err, level in zip(res["levels"], run.levels, strict=True):
        assert abs(err) * level <= line
    met = meets_targets(res)
    if name == "trans2_v30.npz":  # the line is 10.6 % of the step: levels met, ringing at the edge of 10 %
        assert met["levels"] and max(e["product"]["ringing"] for e in res["edges"]) < 0.11
    else:  # the steps are 12–16x the weak levels: widths and ringing met, the 30 MN/m level carries the line
        assert met["width"] and met["ringing"]


def test_the_30_mn_level_of_trans2_v42_is_the_wheel_order_5_line(tmp_path):
    """Issue 26 (b): the 30 MN/m level of trans2_v42 as it is reads −16 % / +24 % 10–20 m from its edges
    (+4 % over both windows): the product's sleeper extraction there is the physics' own per-bay lock-in of
    the signal less the stationary wheel order 5 the record holds (0.43 m/s² on a smooth wheel: the track's
    content at that line over 160 m, 0.56 m/s²), within 2 % of the level; that line beats with f_s over
    15.8 m. Nothing else of the VKF enters: a 160 m record at one speed cannot tell the track's content at
    the line from an order-5 polygon (inside 1000 m the level is within 2 %: the test above)."""
    cause = soft_level_cause(tmp_path)
    assert cause["line"] > 0.4 and cause["record_content"] > cause["line"]
    for row in cause["rows"]:
        assert abs(row["product"] - row["lockin_less_line"]) <= 0.02 * cause["level"], row
    by_window = {r["window"]: r for r in cause["rows"]}
    # the two 10 m windows sample the beat; over both (20 m, 1.3 beats) the level is within 5 %
    assert by_window[(60.0, 70.0)]["product"] / by_window[(60.0, 70.0)]["a_bay"] - 1 > 0.15
    assert abs(by_window[(50.0, 70.0)]["product"] / by_window[(50.0, 70.0)]["a_bay"] - 1) <= 0.05


@pytest.mark.parametrize("speed, k_a, k_b", [(35, 40, 160), (35, 80, 20), (50, 40, 160), (50, 20, 80)])
def test_constructed_transitions_from_the_uniform_runs(tmp_path, speed, k_a, k_b):
    """Constructed (labelled so): steady bays of two uniform runs of one speed cross-faded over 3 m at each
    edge (the phase turns over metres), segments 37.2 / 24.6 / 60 m inside 500 m. At 50 m/s, 20 ↔ 80 MN/m,
    the two responses are far apart in phase: the per-bay truth itself dips by half the step inside
    the 3 m transition and the product follows it; elsewhere every target is met."""
    run = blended_run(speed, k_a, k_b, [37.2, 24.6, 60.0])
    res = evaluate(*pipeline_profile(run, tmp_path), run)
    met = meets_targets(res)
    assert met["offset"] and met["levels"], res
    if (speed, k_a, k_b) == (50, 20, 80):
        for e in res["edges"]:
            assert e["product"]["rise"] <= 3.0
            assert abs(e["product"]["ringing"] - e["physics"]["ringing"]) <= 0.05
    else:
        assert met["width"] and met["ringing"], res


def test_a_wheel_polygon_is_kept_beside_a_real_transition(tmp_path):
    """trans2_v42 inside 1000 m of its own track with a 90 µm order-5 polygon (25 m/s², 2–30x the sleeper
    amplitudes): the transition still meets the targets and the polygon's amplitude is recovered."""
    run = embedded_run("trans2_v42.npz")
    poly = polygon(run.z.size, run.fs, run.speed)
    run.z = run.z + poly
    res = run_pipeline(write_run(tmp_path / "p.h5", run.z, run.fs, run.speed), ProcessingSettings(), tmp_path / "w")
    p = res.profiles[res.profiles["wheel"] == "11"].sort_values("bin")
    x = (p["bin"].to_numpy() + 0.5) * 0.25
    out = evaluate(x, p["sleeper_amp"].to_numpy(), run)
    assert meets_targets(out) == {"width": True, "offset": True, "ringing": True, "levels": True}, out
    inner = (x > 50) & (x < x[-1] - 50)
    amp = np.abs(poly).max()
    assert np.abs(p["order_amp_05"].to_numpy()[inner] / amp - 1).max() < 0.01


def test_a_small_step_under_noise_meets_the_targets_as_steps(tmp_path):
    """Issue 33 item 7, from the uniform runs: 80 ↔ 40 MN/m at 50 m/s (1.51 ↔ 0.98 m/s², the levels of the FE
    step 80 → 52 MN/m) cross-faded over 3 m, with 1 m/s² of the simulator's band-limited noise. The stored
    profile reads every edge wider than 6 m or ringing by more than 10 % (the noise in the 3 m band is
    11–13 % of the step per bin); the stored step estimate (``sleeper_step``: the piecewise-constant levels
    of the stored amplitude at the run's 3 m resolution) meets the issue-26 targets."""
    from app.analysis.steps import step_levels
    from app.simulate.noise import BandLimitedNoise

    run = blended_run(50, 80, 40, [37.2, 24.6, 60.0])
    z = run.z + BandLimitedNoise(np.random.default_rng(5), run.fs, 1.0, (2.0, 0.4 * run.fs)).next(run.z.size)
    x, p, _ = _profile(tmp_path, "weak", z, run.fs, run.speed)
    a, sd, step = p["sleeper_amp"].to_numpy(), p["sleeper_amp_sd"].to_numpy(), p["sleeper_step"].to_numpy()
    np.testing.assert_array_equal(step, step_levels(a, sd, 3.0 / 0.25))
    stored = evaluate(x, a, run)
    assert all(e["product"]["width"] > 6.0 or e["product"]["ringing"] > 0.10 for e in stored["edges"]), stored
    steps = evaluate(x, step, run)
    for e in steps["edges"]:
        m = e["product"]
        assert m["width"] <= 6.0 and m["ringing"] <= 0.10 and abs(m["offset"]) <= 2.0, steps
    assert all(abs(v) <= 0.03 for v in steps["levels"] if np.isfinite(v)), steps
