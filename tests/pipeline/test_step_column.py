"""The step estimate column of a wheel's profile rows (app.pipeline.assemble.sleeper_step): missing bins and
NaN split the profile, the resolution in bins from the run's own track resolution."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from app.analysis.steps import step_levels
from app.pipeline.assemble import sleeper_step


def _rows(bins: np.ndarray, amp: np.ndarray, sd: float = 0.05) -> pd.DataFrame:
    return pd.DataFrame({"bin": bins, "sleeper_amp": amp, "sleeper_amp_sd": np.full(bins.size, sd)})


def test_missing_bins_split_the_profile_like_a_nan():
    rng = np.random.default_rng(4)
    amp = np.where(np.arange(400) < 200, 1.5, 1.0) + 0.02 * rng.standard_normal(400)
    bins = np.r_[np.arange(100, 300), np.arange(350, 550)]  # 50 bins without samples between the halves
    got = sleeper_step(_rows(bins, amp), 3.0, 0.25)
    want = step_levels(np.r_[amp[:200], np.nan, amp[200:]], np.full(401, 0.05), 12.0)
    np.testing.assert_array_equal(got, np.delete(want, 200))
    assert np.ptp(got[:200]) == 0.0 and got[0] == pytest.approx(amp[:200].mean())  # each half its own level
    assert np.ptp(got[200:]) == 0.0 and got[-1] == pytest.approx(amp[200:].mean())


def test_nan_where_the_amplitude_or_its_sd_is_nan_and_the_resolution_in_bins():
    rng = np.random.default_rng(5)
    amp = 1.0 + 0.02 * rng.standard_normal(300)
    amp[[3, 150]] = np.nan
    rows = _rows(np.arange(300), amp)
    rows.loc[200, "sleeper_amp_sd"] = np.nan  # an amplitude without a stated 1-σ has no step estimate
    got = sleeper_step(rows, 21.0, 0.25)
    assert np.isnan(got[[3, 150, 200]]).all() and np.isfinite(np.delete(got, [3, 150, 200])).all()
    np.testing.assert_array_equal(got, step_levels(amp, rows["sleeper_amp_sd"].to_numpy(), 84.0))
    # a resolution under one bin segments bin by bin
    np.testing.assert_array_equal(sleeper_step(rows, 0.1, 0.25),
                                  step_levels(amp, rows["sleeper_amp_sd"].to_numpy(), 1.0))
    assert sleeper_step(rows.iloc[:0], 3.0, 0.25).size == 0
    # a stretch shorter than two resolutions holds no change point: one level, its mean
    short = _rows(np.r_[np.arange(0, 100), np.arange(110, 130), np.arange(140, 240)], 1.0 + 0.3 * rng.random(220))
    got = sleeper_step(short, 3.0, 0.25)
    assert np.ptp(got[100:120]) == 0.0 and got[100] == pytest.approx(short["sleeper_amp"][100:120].mean())
    with pytest.raises(ValueError, match="increasing"):
        sleeper_step(rows.iloc[::-1], 3.0, 0.25)


def test_every_wheel_of_a_run_in_bin_order_whatever_the_rows_order():
    """The run's rows (two wheels, shuffled) get each wheel's step estimate at the wheel's own resolution."""
    from app.pipeline.assemble import _with_steps

    rng = np.random.default_rng(6)
    frames = []
    for wheel, level in (("11", 1.5), ("41", 0.9)):
        amp = np.where(np.arange(300) < 150, level, 0.7 * level) + 0.02 * rng.standard_normal(300)
        frames.append(_rows(np.arange(1000, 1300), amp).assign(wheel=wheel))
    run = pd.concat(frames, ignore_index=True)
    shuffled = run.iloc[rng.permutation(len(run))]
    got = _with_steps(shuffled, {"11": 3.0, "41": 6.0}, 0.25).sort_index()
    for wheel, res_m in (("11", 3.0), ("41", 6.0)):
        p = run[run.wheel == wheel]
        np.testing.assert_array_equal(got.loc[p.index, "sleeper_step"], sleeper_step(p, res_m, 0.25))
    assert _with_steps(run, {"11": 3.0}, 0.25).loc[run.wheel == "41", "sleeper_step"].isna().all()
