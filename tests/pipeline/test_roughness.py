"""Roughness out of the sleeper amplitude, through the real pipeline, on synthetic runs with a known truth.

A sleeper-passage component of known amplitude plus broadband noise of known in-band power (white
noise: its density is flat, so the band beside the order holds exactly the density inside it):

* the floor from the side bands equals the in-band noise power (the gain of
  :func:`app.analysis.roughness.floor_gain`, checked against direct integration);
* a single wheel's ``sleeper_amp`` loses the floor's bias, ``sleeper_amp_raw`` keeps it;
* two wheels of an axle with independent noise give one unbiased two-rail estimate;
* the stated 1-σ of 10 m means covers the truth about two times in three;
* without noise (a wheel polygon beside the order) nothing changes: the floor holds no wheel order.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import quad

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))

from physics_runs import polygon, write_run  # noqa: E402

from app.analysis.binning import BinSums  # noqa: E402
from app.analysis.roughness import floor_gain, inband_floor, smooth_along  # noqa: E402
from app.analysis.settings import ProcessingSettings  # noqa: E402
from app.analysis.uncertainty import segment_sd  # noqa: E402
from app.pipeline import assemble, run_pipeline  # noqa: E402
from app.pipeline.chunkfile import read_wheel  # noqa: E402

FS, V, D_S = 2000.0, 35.0, 0.6
#: the sleeper order's full -3 dB bandwidth at 35 m/s (3 m, q = 2), Hz, and its noise bandwidth ∫H²
B_HZ = 0.7205 / 3.0 * V
ENBW_HZ = 1.0384 * B_HZ


def _sleeper(x: np.ndarray, amp: np.ndarray | float, phase: float = 0.4) -> np.ndarray:
    return amp * np.cos(2 * np.pi * (x - 0.3) / D_S + phase)


def _noise_sigma(floor: float) -> float:
    """σ of white noise (sample variance) whose power in the sleeper order's band is ``floor`` (m/s²)²:
    one-sided density 2σ²/fs, peak envelope ``E|R|² = 2 · density · ENBW``."""
    return float(np.sqrt(floor * FS / (4.0 * ENBW_HZ)))


def _run(tmp_path: Path, name: str, z11: np.ndarray, z12: np.ndarray | None = None,
         settings: ProcessingSettings | None = None):
    run = write_run(tmp_path / f"{name}.h5", z11, FS, V, z12=z12)
    work = tmp_path / f"w-{name}"
    res = run_pipeline(run, settings or ProcessingSettings(), work)
    return res, sorted(work.glob("*.npz"))


def _wheel(res, wheel: str = "11"):
    p = res.profiles[res.profiles["wheel"] == wheel].sort_values("bin").reset_index(drop=True)
    return (p["bin"].to_numpy() + 0.5) * 0.25, p


def _segments(x: np.ndarray, p, truth: np.ndarray, level: float = 10.0, skip: float = 20.0):
    """(10 m means of sleeper_amp / truth − 1, covered by the stated 1-σ) over the inner segments."""
    segs, sd = segment_sd(p["bin"].to_numpy(), p["sleeper_amp_sd"].to_numpy(), level,
                          shared=p["sleeper_amp_sd_shared"].to_numpy())
    ratio, covered = [], []
    for g, s in zip(segs, sd, strict=True):
        sel = (x >= g * level) & (x < (g + 1) * level)
        if g * level < skip or (g + 1) * level > x.max() - skip:
            continue
        est, tru = p["sleeper_amp"].to_numpy()[sel].mean(), truth[sel].mean()
        ratio.append(est / tru - 1)
        covered.append(abs(est - tru) <= s)
    return np.array(ratio), np.array(covered)


def test_floor_gain_against_direct_integration():
    def h(f):
        return 1.0 / (1.0 + (np.sqrt(2.0) - 1.0) * (2.0 * f) ** 4)

    inside = quad(lambda f: h(f) ** 2, -np.inf, np.inf)[0]
    side = quad(lambda f: (1 - h(f)) ** 2 * h(f - 1.5) ** 2, -30, 30, points=[0, 1.5], limit=400)[0]
    assert floor_gain(2) == pytest.approx(inside / side, rel=1e-4)
    assert floor_gain(2) == pytest.approx(1.108, abs=1e-3)


def test_single_wheel_floor_removed(tmp_path):
    rng = np.random.default_rng(11)
    n = int(FS * 3000 / V)
    x = np.arange(n) * V / FS
    floor = 0.5  # in-band noise power against a sleeper power of 1
    z = _sleeper(x, 1.0) + _noise_sigma(floor) * rng.standard_normal(n)
    res, chunks = _run(tmp_path, "single", z)
    xb, p = _wheel(res)
    inner = (xb > 20) & (xb < xb.max() - 20)
    # the noise level is what it was built to be: |E|² = S² + F
    raw_pow = float(np.mean(p["sleeper_amp_raw"].to_numpy()[inner] ** 2))
    rough = BinSums.merge_all([read_wheel(c, "11").groups["rough"] for c in chunks]).finalize(0.25)
    sel = ((rough["bin"].to_numpy() + 0.5) * 0.25 > 20) & ((rough["bin"].to_numpy() + 0.5) * 0.25 < xb.max() - 20)
    inband = rough["pow"].to_numpy()[sel].mean() - 1.0
    # as built, less the slice the wheel orders inside the band take (≈ 10 %), ± the noise's own scatter
    assert 0.8 * floor <= inband <= 1.05 * floor
    # the side bands measure the floor inside the band (flat density), and so does the envelope's fluctuation
    for side in ("floor_lo", "floor_hi"):
        assert rough[side].to_numpy()[sel].mean() == pytest.approx(inband, rel=0.15)
    env = rough["re"].to_numpy() + 1j * rough["im"].to_numpy()
    assert np.median(inband_floor(rough["bin"].to_numpy(), env)[sel]) == pytest.approx(inband, rel=0.15)
    # the amplitude: the raw one reads sqrt(1.45) in power, the corrected one about 1 in amplitude
    assert raw_pow == pytest.approx(1.0 + floor, rel=0.08)
    assert np.mean(p["sleeper_amp_raw"].to_numpy()[inner]) > 1.1
    # (the lesser of the two side bands' 20 m floors is biased low by their scatter: ≈ +5 % remains)
    assert np.mean(p["sleeper_amp"].to_numpy()[inner]) == pytest.approx(1.0, abs=0.07)
    ratio, covered = _segments(xb, p, np.ones(xb.size))
    assert abs(np.median(ratio)) <= 0.08
    assert 0.55 <= covered.mean() <= 0.85, covered.mean()


def test_two_rail_estimate_unbiased_and_shared(tmp_path):
    rng = np.random.default_rng(5)
    n = int(FS * 1200 / V)
    x = np.arange(n) * V / FS
    truth_of = np.where(x < 600, 1.0, 2.0)  # a stiffer half
    floor = 1.0  # the soft half at a signal-to-roughness power of 1, the stiff one at 4
    sig = _noise_sigma(floor)
    z11 = _sleeper(x, truth_of) + sig * rng.standard_normal(n)
    z12 = _sleeper(x, truth_of) + sig * rng.standard_normal(n)
    res, _ = _run(tmp_path, "pair", z11, z12)
    xb, p11 = _wheel(res, "11")
    _, p12 = _wheel(res, "12")
    np.testing.assert_allclose(p11["sleeper_amp"], p12["sleeper_amp"], rtol=1e-9)
    np.testing.assert_allclose(p11["sleeper_amp_sd"], p12["sleeper_amp_sd"], rtol=1e-9)
    assert (p11["sleeper_amp_sd_shared"] == 0).all()  # the cross product is unbiased: no floor error shared
    truth = np.where(xb < 600, 1.0, 2.0)
    ratio, covered = _segments(xb, p11, truth)
    raw = p11.assign(sleeper_amp=p11["sleeper_amp_raw"])
    raw_ratio, _ = _segments(xb, raw, truth)
    assert np.median(raw_ratio) > 0.1  # the single wheel reads high
    assert abs(np.median(ratio)) <= 0.08
    assert np.sqrt(np.mean(ratio**2)) < np.sqrt(np.mean(raw_ratio**2))
    assert 0.55 <= covered.mean() <= 0.85, covered.mean()
    # the step stays a step: the halves' means within 10 % of 1 and 2
    amp = p11["sleeper_amp"].to_numpy()
    assert amp[(xb > 30) & (xb < 570)].mean() == pytest.approx(1.0, rel=0.1)
    assert amp[(xb > 630) & (xb < 1170)].mean() == pytest.approx(2.0, rel=0.1)


def test_clean_signal_unchanged_and_wheel_orders_not_in_the_floor(tmp_path):
    """No broadband content: a 90 µm order-5 polygon beside the order is no floor."""
    n = int(FS * 300 / V)
    x = np.arange(n) * V / FS
    z = _sleeper(x, 2.0) + polygon(n, FS, V)
    res, _ = _run(tmp_path, "clean", z)
    xb, p = _wheel(res)
    inner = (xb > 20) & (xb < xb.max() - 20)
    amp, raw = p["sleeper_amp"].to_numpy()[inner], p["sleeper_amp_raw"].to_numpy()[inner]
    np.testing.assert_allclose(amp, raw, rtol=1e-4)
    assert np.mean(amp) == pytest.approx(2.0, rel=2e-4)
    assert np.max(p["sleeper_amp_sd"].to_numpy()[inner]) < 0.01 * 2.0


def test_chunked_like_one_solve(tmp_path):
    rng = np.random.default_rng(8)
    n = int(FS * 900 / V)
    x = np.arange(n) * V / FS
    z11 = _sleeper(x, 1.0) + _noise_sigma(0.5) * rng.standard_normal(n)
    z12 = _sleeper(x, 1.0) + _noise_sigma(0.5) * rng.standard_normal(n)
    one, _ = _run(tmp_path, "one", z11, z12)
    many, chunks = _run(tmp_path, "many", z11, z12, ProcessingSettings(chunk_seconds=8.0))
    assert len(chunks) >= 3
    for w in ("11", "12"):
        xa, a = _wheel(one, w)
        _, b = _wheel(many, w)
        inner = (xa > 20) & (xa < xa.max() - 20)
        # bin by bin as close as the single-wheel amplitude itself is across seams (broadband noise ≫ signal)
        raw_diff = np.abs(b["sleeper_amp_raw"] - a["sleeper_amp_raw"]).to_numpy()[inner]
        diff = np.abs(b["sleeper_amp"] - a["sleeper_amp"]).to_numpy()[inner]
        assert np.median(diff) <= 2 * np.median(raw_diff) + 1e-6
        # 10 m means: as close as the single wheel's own (the stationary wheel orders are fitted per
        # stretch, so seams move the envelope a little); their 1-σ alike
        g = a["bin"].to_numpy()[inner] // 40
        groups = np.unique(g)

        def means(df, col, g=g, groups=groups, inner=inner):
            return np.bincount(g, df[col].to_numpy()[inner])[groups] / np.bincount(g)[groups]

        raw_dev = np.abs(means(b, "sleeper_amp_raw") / means(a, "sleeper_amp_raw") - 1)
        dev = np.abs(means(b, "sleeper_amp") / means(a, "sleeper_amp") - 1)
        assert np.median(dev) <= 2 * np.median(raw_dev) + 0.002
        assert dev.max() <= 2 * raw_dev.max() + 0.01
        np.testing.assert_allclose(means(b, "sleeper_amp_sd"), means(a, "sleeper_amp_sd"), rtol=0.05)


def test_chunk_files_before_issue_26_still_assemble(tmp_path):
    n = int(FS * 200 / V)
    x = np.arange(n) * V / FS
    z = _sleeper(x, 1.5) + 0.3 * np.random.default_rng(1).standard_normal(n)
    res, chunks = _run(tmp_path, "old", z)
    for c in chunks:  # drop the rough group, as in files written before it existed
        with np.load(c) as npz:
            kept = {k: npz[k] for k in npz.files if not k.startswith("rough_")}
        np.savez(c, **kept)
    old = assemble(tmp_path / "old.h5", ProcessingSettings(), chunks)
    _, p_old = _wheel(old)
    _, p_new = _wheel(res)
    np.testing.assert_allclose(p_old["sleeper_amp"], p_new["sleeper_amp_raw"])
    np.testing.assert_allclose(p_old["sleeper_amp_raw"], p_new["sleeper_amp_raw"])
    assert p_old["sleeper_amp_sd"].isna().all()


def test_smooth_along_ignores_gaps_and_nan():
    bins = np.array([0, 1, 2, 10, 11, 12])
    v = np.array([1.0, np.nan, 3.0, 10.0, 20.0, 30.0])
    out = smooth_along(bins, v, 0.5)  # ±1 bin
    np.testing.assert_allclose(out, [1.0, 2.0, 3.0, 15.0, 20.0, 25.0])
    with pytest.raises(ValueError, match="one length"):
        smooth_along(bins, v[:3], 1.0)
