"""Rail roughness against the independent physics runs (../shared/physics, "Added 2026-11-26"), through
the real pipeline (:func:`app.pipeline.run_pipeline` on canonical files built by bench/physics_runs.py).

Truth: ``A_bay_smooth``, the per-bay lock-in of the same track without roughness. Issue 26's targets:

* two rails of one axle (rail 1 as Z11, rail 2 as Z12): median bias of 10 m means within ±15 % on the
  uniform 400 m run and ±20 % on the transition run, the sections' order kept (120 > 60 > 30 MN/m), RMS no
  worse than the single wheel's of today (``sleeper_amp_raw``), the stated 1-σ of 10 m means covering the
  smooth truth in 60–75 % of the segments (asserted per run: 68 % within twice the binomial scatter of the
  number of segments, the share pooled over shifted segment grids; see _calibrated);
* one rail: the floor correction takes out part of the bias (the side bands see less roughness response
  than the band holds where the wheel–track resonance sits at f_s: docs/indicator.md), the 1-σ is stated;
* smooth uniform runs (tiled steady bays): the floor does not bias the amplitude (0.02 %) and the 1-σ is small.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))

from physics_runs import (  # noqa: E402
    D_S,
    ONE_SIGMA,
    PHYSICS,
    START_M,
    cases,
    coverage,
    rough_run,
    segment_scores,
    steady_unit,
    write_run,
)

from app.analysis.settings import ProcessingSettings  # noqa: E402
from app.analysis.uncertainty import segment_sd  # noqa: E402
from app.pipeline import run_pipeline  # noqa: E402

pytestmark = pytest.mark.skipif(not (PHYSICS / "rail2_k80_v35_r1.npz").is_file(), reason="no ../shared/physics")

#: the first bays are the physics run's start-up transient (README: 7 bays)


def _process(tmp_path: Path, name: str, two_rails: bool):
    r = rough_run(name)
    z12 = r["z12"] if two_rails else None
    run = write_run(tmp_path / f"{name}.h5", r["z11"], r["fs"], r["speed"], z12=z12)
    res = run_pipeline(run, ProcessingSettings(), tmp_path / f"w-{name}")
    p = res.profiles[res.profiles["wheel"] == "11"].sort_values("bin").reset_index(drop=True)
    return r, p


def _rms(a: np.ndarray) -> float:
    return float(np.sqrt(np.mean(a**2)))


def _calibrated(r: dict, p) -> bool:
    """The stated 1-σ of 10 m means covers the smooth truth in 68.27 % of the segments, within twice the
    binomial scatter of the number of segments of one grid.

    The share is pooled over the grids shifted by 2.5, 5, 7.5 m (bench/physics_runs.coverage): one grid of
    14 segments scatters ±12 points around 68 %. Measured (BENCHMARKS.md, issue 26 (c)): 58 / 64 % (two
    rails, uniform / transition), 59–76 % one rail; pooled over every run 66 %."""
    c = coverage(r, p, 10.0)
    return abs(c["share_offsets"] - ONE_SIGMA) <= 2.0 * c["sigma"]


def test_two_rails_uniform(tmp_path):
    r, p = _process(tmp_path, "rail2_k80_v35", two_rails=True)
    ratio, _ = segment_scores(r, p, "sleeper_amp", 10.0)
    raw, _ = segment_scores(r, p, "sleeper_amp_raw", 10.0)
    assert np.median(raw) > 0.25  # the single wheel: +37 %
    assert abs(np.median(ratio)) <= 0.15, np.median(ratio)
    assert _rms(ratio) <= _rms(raw)
    assert _calibrated(r, p), coverage(r, p, 10.0)


def test_two_rails_transition(tmp_path):
    r, p = _process(tmp_path, "rail2_trans_v42", two_rails=True)
    ratio, _ = segment_scores(r, p, "sleeper_amp", 10.0)
    raw, _ = segment_scores(r, p, "sleeper_amp_raw", 10.0)
    assert np.median(raw) > 0.5  # the single wheel: +68 %
    assert abs(np.median(ratio)) <= 0.20, np.median(ratio)
    assert _rms(ratio) <= _rms(raw)
    assert _calibrated(r, p), coverage(r, p, 10.0)
    # the sections' order: 120 / 30 / 120 / 60 MN/m between the edges 40 / 80 / 120 m, 5 m off each edge
    x = (p["bin"].to_numpy() + 0.5) * 0.25
    amp = p["sleeper_amp"].to_numpy()
    edges = [START_M, *np.asarray(r["edges"]).tolist(), 160.0]
    level = [amp[(x > a + 5) & (x < b - 5)].mean() for a, b in zip(edges[:-1], edges[1:], strict=True)]
    k120, k30, k120b, k60 = level
    assert min(k120, k120b) > k60 > k30, level


@pytest.mark.parametrize("name", ["rough_k80_v35", "rough_k80_v35_severe"])
def test_one_rail(tmp_path, name):
    r, p = _process(tmp_path, name, two_rails=False)
    ratio, _ = segment_scores(r, p, "sleeper_amp", 10.0)
    raw, _ = segment_scores(r, p, "sleeper_amp_raw", 10.0)
    # part of the bias out, not all of it: a single wheel cannot see the floor the resonance puts under f_s
    assert 0 < np.median(ratio) < np.median(raw)
    assert _rms(ratio) <= _rms(raw)
    # the stated 1-σ is of the size of the error (measured over the shifted grids: 59 % / 62 %, on the grid from
    # 0 m 57 % / 71 % of 14 segments; what the side bands miss is a bias shared along the floor window,
    # sleeper_amp_sd_shared)
    assert _calibrated(r, p), coverage(r, p, 10.0)
    after = (p["bin"].to_numpy() + 0.5) * 0.25 > START_M
    shared, sd = p["sleeper_amp_sd_shared"].to_numpy()[after], p["sleeper_amp_sd"].to_numpy()[after]
    assert np.all((shared >= 0) & (shared <= sd))
    assert np.median(shared / sd) > 0.2  # the floor not taken off is a good part of the error
    assert np.median(p["sleeper_amp_sd"].to_numpy()[after]) > 0.3 * np.median(p["sleeper_amp"].to_numpy()[after])


@pytest.mark.parametrize("name", ["grid_k80_v35.npz", "grid_k320_v50.npz", "sweep_k40_v60.npz",
                                  "grid_k20_v20.npz", "sweep_k160_v15.npz"])
def test_smooth_uniform_runs_not_biased(tmp_path, name):
    """Tiled steady bays (no roughness): the floor leaves the amplitude within 0.02 %, the 1-σ is small.

    The tiles' own ripple (the physics runs' start transient, repeating every tile) is all there is
    beside the order: up to 1.2 m/s² beside 53.8 m/s² at 320 MN/m, 50 m/s.
    """
    c = cases()[name]
    unit, v, fs, nb = steady_unit(name)
    z = np.tile(unit, -(-100 // int(nb * D_S)))
    res = run_pipeline(write_run(tmp_path / "u.h5", z, fs, v), ProcessingSettings(), tmp_path / "w")
    p = res.profiles
    x = (p["bin"].to_numpy() + 0.5) * 0.25
    inner = p[(x > 15) & (x < x.max() - 15)]
    # (sleeper_amp_raw against the lock-in: tests/pipeline/test_indicator_physics.py)
    assert abs(inner["sleeper_amp"].mean() / inner["sleeper_amp_raw"].mean() - 1) <= 2e-4
    segs, sd = segment_sd(p["bin"].to_numpy(), p["sleeper_amp_sd"].to_numpy(), 10.0,
                          shared=p["sleeper_amp_sd_shared"].to_numpy())
    assert np.median(sd) <= 0.06 * c["A_lockin"]
