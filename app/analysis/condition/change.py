"""Change detection of segment condition: the newest run against the segment's history.

Two tests, vectorised over segments (rows of a history matrix; NaN = no
speed-matched value of that run):

**Step** (:func:`step_change`) — a sudden change (a new soft spot, a broken
support, a repair). The baseline is the median of the segment's history, the
repeatability its robust spread ``1.4826 · MAD`` (consistent with σ for normal
noise, with a small-sample correction, and never below ``min_spread``:
:func:`app.analysis.robust.robust_spread`). The
score

    z = (x − median) / (spread · √(1 + π / (2 n)))

counts the change in repeatability units, the second term being the
uncertainty of the median of ``n`` values. ``|z| ≥ step_z`` flags it.

**Stated uncertainty in the step test** (``sd_value``, ``sd_history``: the 1-σ of each run's
index that the profile states, :mod:`app.condition.index`; NaN where none is stated). The
stated 1-σ of one pass is mostly the response of the rail's roughness inside the sleeper
order's band (plus noise and too few sleeper bays). Rail roughness is fixed to the track: at
matched speed its response **repeats** from run to run, so the history's spread does not see it
and it does not move the newest value against the baseline either — it is an error against
the support's truth, not against the history. The denominator therefore changes only where
the physics says the errors no longer cancel:

* (a) **a newer run states more than the history did** (another vehicle, sensor or speed: more
  noise or floor than the typical run) — the repeatability already holds the typical run's
  noise, so only the excess counts. The floor is an absolute power (m/s²), not a share of the
  amplitude: a softer support lowers ``A`` and raises ``sd / A`` with the same floor, which is no
  new noise. The history's 1-σ are therefore brought to the new value's amplitude first
  (``sd_hist · e^(h − x)``, the ratio of the two amplitudes)::

      σ² = spread² (1 + π / (2 n)) + max(0, sd_new² − median(sd_hist² e^(2(h − x))))

* (b) **the rail surface changed** between the baseline's runs and the newest (a grinding or a
  rail renewal in the maintenance records over the segment, ``surface_days``): the old
  roughness response is in the baseline, the new one in the newest value, independent of each
  other. Both sides' whole stated 1-σ enter::

      σ² = spread² (1 + π / (2 n)) + sd_new² + median(sd_hist² of the runs before it)

  The whole 1-σ, not only its shared part (``sleeper_amp_sd_shared``): both the broadband part
  (roughness response in the order's band, correlated over ≈ 4 m) and the shared part (the
  floor bias not taken off, over ≈ 20 m) are made by the rail surface and change with it; on a
  10 m segment the broadband part is the larger. The noise share of the stated 1-σ, already in
  the spread, is counted a second time only across an intervention (a little conservative,
  there only). Where at least half of the baseline's runs predate the intervention the median
  is the old surface's; after that the new surface repeats in both and the test is as before.
  The trend test leaves out the runs before such an intervention (they measured another rail
  surface), and the run level (below) is taken from the segments it did not cover. The
  intervention's extent counts with a margin (:func:`~app.analysis.condition.interventions.intervention_margin_m`): a bin's estimate
  reaches half the floor window and the filter's correlation beyond itself. Tamping and other
  actions change the support, not the rail's surface: after them a segment's history starts anew (the
  caller leaves the runs before out, :func:`~app.analysis.condition.interventions.since_actions`), as a
  step or a trend read across the work measures the work. Measured (``bench/bench_uncertainty.py``, BENCHMARKS.md): a recorded grinding over 200 m of a
  rough line, 15–20 step flags over its extent before, none after; a −30 % support change beside it
  flagged either way.

**Wheels share the stated error.** The wheels of a run meet the same rails at the same speed: their
roughness responses are the same where they run on one rail, and the two-rail estimate gives both
wheels of an axle one value. The stated part is therefore taken as common to the ``w`` wheels whose
scores are combined (``stated_wheels``): each wheel's denominator carries ``w ×`` the stated variance,
so that the wheels' Stouffer sum ``Σ z / √w`` is the change over ``sqrt(spread²(…)/w + stated)`` —
the repeatability averages over the wheels, the roughness does not (full correlation: the upper
bound). Without it four wheels would turn one grinding's roughness into twice its score.

Where no 1-σ is stated (old rows, the synthetic fleet) the extra terms are 0: exactly the test
above.

**Trend** (:func:`trend_change`) — a gradual degradation. Over the last
``trend_window_days`` (history and the newest run), the index is winsorised at
``median ± 3 · spread`` and regressed on time; the score is the slope over its
standard error from the robust residual spread. A step inside the window tilts
that line too, so the score counts (else it is 0) only where the slope over the
recent half of the window's data has the same sign and reaches ``trend_recent_z``: the
change is still going on. ``|z| ≥ trend_z`` flags it, and
``rate_per_year`` (index units per year; ×100 ≈ % per year for a log index) says
how fast.

**Speed matching** (:func:`speed_matched`) comes first: history values count
only where the run passed within ``speed_tolerance`` of the newest run's
speed, and they are moved to that speed with the exponent of ``index`` on
``ln v`` estimated within segments over the whole history (a raw log amplitude
grows with speed; a speed-conditioned index does not, and its exponent comes
out near 0).

**The same vehicle** (``history_vehicle``, ``vehicle``; issue 33): a vehicle's response to the rails
(its unsprung mass, its wheels: the roughness it picks up, the contact filter) repeats from run to run
at matched speed, another vehicle's differs segment by segment (measured on a rough line: a second
vehicle with 25 % more unsprung mass read 0.23–0.34 ln units apart per 10 m on B91 sleepers without
pads at 40 m/s, 6 % of its segments flagged). A matched pass is therefore one at matched speed **by the
same vehicle**: where the segment's matched history holds ``min_history`` of them, only they count; where
it holds at least 2 and the other vehicles at least 2, the others count brought to this vehicle by the
segment's offset between the two (median of the same vehicle's values less that of the others'), whose
uncertainty (``spread² · π/2 · (1/n_same + 1/n_other)``) enters the step score's denominator; where it
holds fewer than 2, the run is not step-tested there (its vehicle's response is not known yet). Without
vehicles (None) all runs count as one vehicle's, as before.

**Run level** (:func:`level_offsets`): every run (history and newest) is
brought to the history's level block by block (``level_block_m``, and at least
``level_block_segments`` segments; the median deviation of the block's
segments from their baselines), so that what moves a
whole kilometre at once — a sensor's calibration, rail temperature, a speed
law the exponent does not catch — is not taken for a change of the segments.
A change that covers a whole block in one run is therefore not seen by these
tests: they look for places that depart from their surroundings.

**Wheels** (:func:`combine_wheels`): the wheels see the same place; their
scores combine as ``Σ z / √n`` (Stouffer), wheels that give one value (the
two-rail estimate: both wheels of an axle) counted as one witness, and the wheels
*agreeing* are those whose own score has the combined sign and at least ``agree_z``. A change of the
support is one change under every axle (each passes the same support under the same rails at the same
speed): the step's combined score is divided by the axles' disagreement beyond their 1-σ, the Birge ratio
``√max(1, χ² / (n_axles − 1))`` of their changes about the weighted mean (:func:`axle_consistency`; the
places' steps and the store's step flags alike). On issue 33's line a step that one axle read
(−0.28 ± 0.04) and the other did not (−0.05 ± 0.06) was listed from a combined score of −5.3; with the
ratio (3.1) it is −1.7.

The direction is the sign: ``+1`` the index rose (stiffer / higher amplitude),
``-1`` it fell. Both tests need ``min_history`` matched runs; otherwise their
score is NaN (no test). :func:`detect_changes` runs it all for one wheel.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np

from app.analysis.robust import nan_median, robust_spread
from app.analysis.speed_match import DEFAULT_SPEED_TOLERANCE, speeds_matched
from app.analysis.units import DAYS_PER_YEAR

__all__ = [
    "ChangeParams",
    "DEFAULT_CHANGE_PARAMS",
    "StepResult",
    "TrendResult",
    "SpeedMatch",
    "speed_matched",
    "vehicle_matched",
    "MatchedPasses",
    "matched_passes",
    "step_change",
    "stated_variance",
    "trend_change",
    "pooled_spread",
    "level_offsets",
    "WheelChange",
    "detect_changes",
    "combine_wheels",
    "axle_labels",
    "axle_consistency",
    "series_labels",
    "series_counts",
]



@dataclass(frozen=True)
class ChangeParams:
    """Thresholds and windows of the change detection.

    Attributes
    ----------
    step_z : float
        Step score beyond which a change is flagged (repeatability units).
    trend_z : float
        Trend score beyond which a degradation is flagged.
    trend_recent_z : float
        The slope over the recent half of the trend window must reach this
        score (same sign) for a trend to count: a step inside the window is
        not a trend.
    min_history : int
        Fewest speed-matched history runs a test needs.
    history_runs : int
        Most recent speed-matched runs the step test compares each segment with.
    history_scan_runs : int
        Most recent runs of the line looked at to find them.
    trend_window_days : float
        Days of history the trend test regresses over.
    min_spread : float
        Floor of the repeatability (log units): a perfectly repeatable
        history does not turn every rounding difference into a flag.
    agree_z : float
        A wheel agrees with a combined change when its own score reaches this.
    speed_tolerance : float
        History values count only where the run passed at matched speed,
        ``|ln(v / v_new)| ≤ ln(1 + speed_tolerance)`` (:mod:`app.analysis.speed_match`).
    level_block_m : float
        Length of the blocks whose median deviation is taken as a run's level, m.
    level_block_segments : int
        Blocks hold at least this many segments (longer blocks for long
        segments), so that a local change of a few segments does not move
        their median.
    min_level_segments : int
        Fewest segments with a value a block needs for a level correction.
    spread_prior_runs : float
        Weight, in runs, of the block's typical spread in each segment's
        repeatability (:func:`pooled_spread`).
    """

    step_z: float = 4.5
    trend_z: float = 4.5
    trend_recent_z: float = 1.0
    agree_z: float = 2.0
    min_history: int = 8
    history_runs: int = 30
    history_scan_runs: int = 60
    trend_window_days: float = 180.0
    min_spread: float = 0.005
    speed_tolerance: float = DEFAULT_SPEED_TOLERANCE
    level_block_m: float = 1000.0
    level_block_segments: int = 50
    min_level_segments: int = 5
    spread_prior_runs: float = 10.0

    def block_m(self, segment_m: float) -> float:
        """Block length for segments of ``segment_m``, m."""
        return max(self.level_block_m, self.level_block_segments * segment_m)

    def __post_init__(self) -> None:
        for name in ("step_z", "trend_z", "trend_recent_z", "agree_z", "trend_window_days", "min_spread", "speed_tolerance",
                     "level_block_m"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name}: must be a finite number > 0, got {value!r}")
        if not (np.isfinite(self.spread_prior_runs) and self.spread_prior_runs >= 0):
            raise ValueError(f"spread_prior_runs: must be >= 0, got {self.spread_prior_runs!r}")
        if self.level_block_segments < 1:
            raise ValueError(f"level_block_segments: must be >= 1, got {self.level_block_segments!r}")
        if self.min_level_segments < 1:
            raise ValueError(f"min_level_segments: must be >= 1, got {self.min_level_segments!r}")
        if self.min_history < 2:
            raise ValueError(f"min_history: must be >= 2, got {self.min_history!r}")
        if self.history_runs < self.min_history:
            raise ValueError(f"history_runs: must be >= min_history ({self.min_history}), got {self.history_runs!r}")
        if self.history_scan_runs < self.history_runs:
            raise ValueError(f"history_scan_runs: must be >= history_runs ({self.history_runs}), "
                             f"got {self.history_scan_runs!r}")


#: The default thresholds and windows.
DEFAULT_CHANGE_PARAMS = ChangeParams()


@dataclass(frozen=True)
class StepResult:
    """Step test per segment (arrays of the segments' length).

    Attributes
    ----------
    baseline : numpy.ndarray
        Median of the history (log units).
    spread : numpy.ndarray
        Robust repeatability (log units).
    change : numpy.ndarray
        Newest value minus baseline.
    z : numpy.ndarray
        Score (NaN: fewer than ``min_history`` runs).
    n_history : numpy.ndarray
        int64 number of history values used.
    sd : numpy.ndarray
        The score's denominator σ: the 1-σ of ``change`` (log units; module docstring).
    """

    baseline: np.ndarray
    spread: np.ndarray
    change: np.ndarray
    z: np.ndarray
    n_history: np.ndarray
    sd: np.ndarray | None = None


@dataclass(frozen=True)
class TrendResult:
    """Trend test per segment.

    Attributes
    ----------
    rate_per_year : numpy.ndarray
        Slope of the index, log units per year (NaN: no test, or the recent half
        of the data does not go on in the same direction).
    z : numpy.ndarray
        Slope over its standard error (NaN: no test).
    n_runs : numpy.ndarray
        int64 number of values regressed (history in the window + newest).
    """

    rate_per_year: np.ndarray
    z: np.ndarray
    n_runs: np.ndarray


def _matrix(history: object, n_segments: int | None = None) -> np.ndarray:
    h = np.asarray(history, dtype=np.float64)
    if h.ndim != 2:
        raise ValueError(f"history: must be 2-D (segments × runs), got shape {h.shape}")
    if n_segments is not None and h.shape[0] != n_segments:
        raise ValueError(f"history: must have one row per segment ({n_segments}), got {h.shape[0]}")
    return h


@dataclass(frozen=True)
class SpeedMatch:
    """History moved to the newest run's speed.

    Attributes
    ----------
    history : numpy.ndarray
        (segments, runs) adjusted index; NaN where missing or not speed-matched.
    exponent : float
        Slope of the index on ``ln v`` within segments (0 when the speeds do not vary).
    n_matched : numpy.ndarray
        int64 matched history values per segment.
    """

    history: np.ndarray
    exponent: float
    n_matched: np.ndarray


def speed_matched(
    history: np.ndarray, history_speed: np.ndarray, speed: np.ndarray, tolerance: float
) -> SpeedMatch:
    """Keep the history values passed at a speed close to the newest run's, moved to that speed.

    Parameters
    ----------
    history, history_speed : numpy.ndarray
        (segments, runs) index and speed (m/s) of earlier runs (NaN = none).
    speed : numpy.ndarray
        (segments,) speed of the newest run, m/s.
    tolerance : float
        Matched-speed tolerance (> 0): kept where ``|ln(v / v_new)| <= ln(1 + tolerance)``
        (:func:`app.analysis.speed_match.speeds_matched`).

    Returns
    -------
    SpeedMatch
    """
    v = np.asarray(speed, dtype=np.float64)
    h = _matrix(history, v.size)
    hv = _matrix(history_speed, v.size)
    if hv.shape != h.shape:
        raise ValueError(f"history_speed: must have the shape of history {h.shape}, got {hv.shape}")
    if not (np.isfinite(tolerance) and tolerance > 0):
        raise ValueError(f"tolerance: must be a finite number > 0, got {tolerance!r}")
    with np.errstate(invalid="ignore", divide="ignore"):
        lv = np.log(np.where(hv > 0, hv, np.nan))
        ok = np.isfinite(h) & np.isfinite(lv)
        n = ok.sum(axis=1)
        mean_h = np.where(ok, h, 0.0).sum(axis=1) / n
        mean_v = np.where(ok, lv, 0.0).sum(axis=1) / n
        dx = np.where(ok, lv - mean_v[:, None], 0.0)
        dy = np.where(ok, h - mean_h[:, None], 0.0)
        sxx = float((dx * dx).sum())
        exponent = float((dx * dy).sum() / sxx) if sxx > 1e-6 * max(int(ok.sum()), 1) else 0.0
        lv_new = np.log(np.where(v > 0, v, np.nan))[:, None]
        matched = ok & speeds_matched(hv, v[:, None], tolerance)
        adjusted = np.where(matched, h + exponent * (lv_new - lv), np.nan)
    return SpeedMatch(history=adjusted, exponent=exponent, n_matched=matched.sum(axis=1).astype(np.int64))


def vehicle_matched(history: np.ndarray, history_vehicle: np.ndarray, vehicle: object, *, min_history: int,
                    min_spread: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The history as passes of the newest run's vehicle (module docstring, "The same vehicle").

    Parameters
    ----------
    history : numpy.ndarray
        (segments, runs) speed-matched index (NaN = none).
    history_vehicle : numpy.ndarray
        (runs,) vehicle of each history run (object labels; None: unknown, counted as the newest's).
    vehicle : object
        The newest run's vehicle (None: every run counts as its own).
    min_history, min_spread : int and float
        Of :class:`ChangeParams`.

    Returns
    -------
    history : numpy.ndarray
        (segments, runs) the values that count, the other vehicles' brought to this one (NaN elsewhere).
    extra_var : numpy.ndarray
        (segments,) variance of the offset applied (0 where none), log units².
    testable : numpy.ndarray
        (segments,) bool: the segment's history holds enough passes of this vehicle to test.
    """
    h = np.asarray(history, dtype=np.float64)
    labels = np.asarray(history_vehicle, dtype=object)
    if labels.shape != (h.shape[1],):
        raise ValueError(f"history_vehicle: must have one label per history run ({h.shape[1]}), got {labels.shape}")
    zero = np.zeros(h.shape[0])
    mine = np.array([v is None or v == vehicle for v in labels.tolist()], dtype=bool)
    if vehicle is None or mine.all():
        # every run one vehicle's: the history as it is (as without vehicles — a segment with few passes still
        # counts in its block's run level and spread)
        return h, zero, np.ones(h.shape[0], dtype=bool)
    ok = np.isfinite(h)
    same, other = ok & mine[None, :], ok & ~mine[None, :]
    n_same, n_other = same.sum(axis=1), other.sum(axis=1)
    own = n_same >= min_history
    shift = (~own) & (n_same >= 2) & (n_other >= 2)
    med_same = nan_median(np.where(same, h, np.nan), axis=1)
    med_other = nan_median(np.where(other, h, np.nan), axis=1)
    offset = np.where(shift, med_same - med_other, 0.0)
    out = np.where(own[:, None], np.where(same, h, np.nan),
                   np.where(shift[:, None], np.where(other, h + offset[:, None], h), np.nan))
    _, spread = robust_spread(np.where(same, h, np.nan), min_spread=min_spread)
    with np.errstate(invalid="ignore", divide="ignore"):
        var = spread**2 * (np.pi / 2.0) * (1.0 / np.maximum(n_same, 1) + 1.0 / np.maximum(n_other, 1))
    return out, np.where(shift, np.nan_to_num(var), 0.0), own | shift


class MatchedPasses(NamedTuple):
    """The history as matched passes of the newest run (:func:`matched_passes`).

    Attributes
    ----------
    history : numpy.ndarray
        (segments, runs) the matched values (NaN elsewhere).
    extra_var : numpy.ndarray or None
        (segments,) variance of a vehicle offset applied, log units² (None: no vehicles given).
    testable : numpy.ndarray
        (segments,) bool: enough passes of the newest run's vehicle to compare with.
    exponent : float
        The speed exponent the values were moved with (:class:`SpeedMatch`).
    """

    history: np.ndarray
    extra_var: np.ndarray | None
    testable: np.ndarray
    exponent: float


def matched_passes(history: np.ndarray, history_speed: np.ndarray, speed: np.ndarray, params: ChangeParams, *,
                   history_vehicle: np.ndarray | None = None, vehicle: object = None) -> MatchedPasses:
    """The history as matched passes of the newest run: the values passed at a matched speed
    (:func:`speed_matched`), of the same vehicle (:func:`vehicle_matched`, the other vehicles' brought to it
    where it has too few of its own). The one rule the step and trend tests compare a run with — the condition
    store's flags and the places' tests and baselines alike.

    Parameters
    ----------
    history, history_speed : numpy.ndarray
        (segments, runs) index and speed (m/s) of earlier runs (NaN = none).
    speed : numpy.ndarray
        (segments,) speed of the newest run, m/s.
    params : ChangeParams
        ``speed_tolerance``, ``min_history`` and ``min_spread``.
    history_vehicle, vehicle : numpy.ndarray and object, optional
        (runs,) vehicle of each history run and the newest run's (None: all runs one vehicle's).

    Returns
    -------
    MatchedPasses
    """
    sm = speed_matched(history, history_speed, speed, params.speed_tolerance)
    if history_vehicle is None or vehicle is None:
        return MatchedPasses(sm.history, None, np.ones(sm.history.shape[0], dtype=bool), sm.exponent)
    h, extra, testable = vehicle_matched(sm.history, history_vehicle, vehicle, min_history=params.min_history,
                                         min_spread=params.min_spread)
    return MatchedPasses(h, extra, testable, sm.exponent)


def _blocks(seg: np.ndarray, segment_m: float, block_m: float) -> tuple[np.ndarray, list[np.ndarray]]:
    """Rows of each block of ``block_m`` (as index arrays), in block order."""
    block = np.floor(np.asarray(seg, dtype=np.int64) * (segment_m / block_m)).astype(np.int64)
    order = np.argsort(block, kind="stable")
    _, start = np.unique(block[order], return_index=True)
    bounds = np.r_[start, order.size]
    return block, [order[bounds[k]: bounds[k + 1]] for k in range(start.size)]


def pooled_spread(spread: np.ndarray, n: np.ndarray, seg: np.ndarray, *, segment_m: float, block_m: float,
                  prior_runs: float) -> np.ndarray:
    """Each segment's spread shrunk towards its block's typical spread.

    A spread from a few runs is itself uncertain (from 8 runs, ±45 %), which
    would make the scores heavy-tailed. The repeatability is mostly a property
    of the line, the vehicle and the run, so each segment's spread is combined
    with the median spread of the segments of its block as if that were
    ``prior_runs`` more runs: ``√((n s² + k s_block²) / (n + k))``.

    Parameters
    ----------
    spread : numpy.ndarray
        (segments,) own spread (NaN where unknown).
    n : numpy.ndarray
        (segments,) runs it comes from.
    seg : numpy.ndarray
        (segments,) segment numbers.
    segment_m, block_m : float
        Segment and block length, m.
    prior_runs : float
        Weight of the block's spread, runs (0: own spread only).
    """
    s = np.asarray(spread, dtype=np.float64)
    if prior_runs <= 0 or s.size == 0:
        return s
    block_spread = np.full_like(s, np.nan)
    for rows in _blocks(seg, segment_m, block_m)[1]:
        block_spread[rows] = nan_median(s[rows][None, :], axis=1)[0]
    nn = np.asarray(n, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        pooled = np.sqrt((nn * s**2 + prior_runs * block_spread**2) / (nn + prior_runs))
    return np.where(np.isfinite(pooled), pooled, s)


def step_change(
    history: np.ndarray,
    value: np.ndarray,
    params: ChangeParams = DEFAULT_CHANGE_PARAMS,
    *,
    seg: np.ndarray | None = None,
    segment_m: float | None = None,
    sd_value: np.ndarray | None = None,
    sd_history: np.ndarray | None = None,
    crossed: np.ndarray | None = None,
    stated_wheels: int = 1,
    extra_var: np.ndarray | None = None,
) -> StepResult:
    """Step test of the newest value of each segment against its history.

    Parameters
    ----------
    history : numpy.ndarray
        (segments, runs) index of earlier speed-matched runs (NaN = none); at
        most ``params.history_runs`` columns are expected (the most recent).
    value : numpy.ndarray
        (segments,) index of the newest run.
    params : ChangeParams
    seg, segment_m : numpy.ndarray and float, optional
        Segment numbers and length (m): with them, the spreads are pooled
        within blocks (:func:`pooled_spread`).
    sd_value : numpy.ndarray, optional
        (segments,) stated 1-σ of the newest value (log units; NaN: none).
    sd_history : numpy.ndarray, optional
        (segments, runs) stated 1-σ of the history values (NaN: none).
    crossed : numpy.ndarray, optional
        (segments, runs) bool: the rail surface was changed between that history run and the newest.
    stated_wheels : int, optional
        Wheels whose scores will be combined and share the stated error (module docstring; default 1).
    extra_var : numpy.ndarray, optional
        (segments,) further variance of the change (log units²; e.g. a vehicle offset's, :func:`vehicle_matched`).

    Returns
    -------
    StepResult
        With the denominator of the module docstring (the stated terms 0 where no 1-σ is stated).
    """
    x = np.asarray(value, dtype=np.float64)
    if x.ndim != 1:
        raise ValueError("value: must be 1-D")
    h = _matrix(history, x.size)
    n = np.isfinite(h).sum(axis=1)
    med, spread = robust_spread(h, min_spread=params.min_spread)
    if seg is not None and segment_m is not None:
        spread = pooled_spread(spread, n, seg, segment_m=segment_m, block_m=params.block_m(segment_m),
                               prior_runs=params.spread_prior_runs)
    change = x - med
    se = spread * np.sqrt(1.0 + np.pi / (2.0 * np.maximum(n, 1)))
    if not (isinstance(stated_wheels, (int, np.integer)) and stated_wheels >= 1):
        raise ValueError(f"stated_wheels: must be an int >= 1, got {stated_wheels!r}")
    se = np.sqrt(se**2 + stated_wheels * stated_variance(h, sd_value, sd_history, crossed, value=x)
                 + (0.0 if extra_var is None else np.nan_to_num(np.asarray(extra_var, dtype=np.float64))))
    with np.errstate(invalid="ignore", divide="ignore"):
        z = np.where((n >= params.min_history) & np.isfinite(x), change / se, np.nan)
    return StepResult(baseline=med, spread=spread, change=change, z=z, n_history=n.astype(np.int64), sd=se)


def stated_variance(history: np.ndarray, sd_value: np.ndarray | None, sd_history: np.ndarray | None,
                    crossed: np.ndarray | None = None, *, value: np.ndarray | None = None) -> np.ndarray:
    """The stated uncertainty's share of the step test's variance (module docstring), log units².

    Parameters
    ----------
    history : numpy.ndarray
        (segments, runs) the history values the baseline is the median of (NaN: not used).
    sd_value : numpy.ndarray or None
        (segments,) stated 1-σ of the newest value (NaN or None: none).
    sd_history : numpy.ndarray or None
        (segments, runs) stated 1-σ of the history values (NaN or None: none).
    crossed : numpy.ndarray or None
        (segments, runs) bool: a rail-surface intervention lies between that run and the newest.
    value : numpy.ndarray, optional
        (segments,) the newest value (log units): the history's 1-σ are brought to its amplitude for
        the excess (a), ``sd · e^(h − x)``; without it they are taken as they are.

    Returns
    -------
    numpy.ndarray
        (segments,) ≥ 0; 0 where nothing is stated.
    """
    h = np.asarray(history, dtype=np.float64)
    used = np.isfinite(h)
    n_seg = h.shape[0]
    sv = np.full(n_seg, np.nan) if sd_value is None else np.asarray(sd_value, dtype=np.float64)
    if sv.shape != (n_seg,):
        raise ValueError(f"sd_value: must have one value per segment ({n_seg}), got shape {sv.shape}")
    sh = np.full(h.shape, np.nan) if sd_history is None else np.asarray(sd_history, dtype=np.float64)
    if sh.shape != h.shape:
        raise ValueError(f"sd_history: must have the shape of history {h.shape}, got {sh.shape}")
    cr = np.zeros(h.shape, bool) if crossed is None else np.asarray(crossed, dtype=bool)
    if cr.shape != h.shape:
        raise ValueError(f"crossed: must have the shape of history {h.shape}, got {cr.shape}")
    new_var = np.where(np.isfinite(sv), sv**2, np.nan)
    scale = np.ones(h.shape)
    if value is not None:
        xv = np.asarray(value, dtype=np.float64)
        if xv.shape != (n_seg,):
            raise ValueError(f"value: must have one value per segment ({n_seg}), got shape {xv.shape}")
        with np.errstate(invalid="ignore", over="ignore"):
            scale = np.where(np.isfinite(h) & np.isfinite(xv)[:, None], np.exp(2.0 * (h - xv[:, None])), 1.0)
    hist_var = nan_median(np.where(used & np.isfinite(sh), sh**2 * scale, np.nan), axis=1)
    # (a) what the newest run states beyond the history's typical run (where both are stated)
    excess = np.where(np.isfinite(new_var) & np.isfinite(hist_var), np.maximum(new_var - hist_var, 0.0), 0.0)
    # (b) across a rail-surface intervention the old and the new roughness response, whole
    n = used.sum(axis=1)
    c = (used & cr).sum(axis=1)
    across = (c > 0) & (2 * c >= n)
    old_var = nan_median(np.where(used & cr & np.isfinite(sh), sh**2, np.nan), axis=1)
    rough = np.nan_to_num(new_var) + np.nan_to_num(old_var)
    return np.where(across, rough, excess)


def trend_change(
    times_days: np.ndarray,
    history: np.ndarray,
    value: np.ndarray,
    now_days: float,
    params: ChangeParams = DEFAULT_CHANGE_PARAMS,
    *,
    seg: np.ndarray | None = None,
    segment_m: float | None = None,
) -> TrendResult:
    """Trend test over the last ``params.trend_window_days`` of each segment's history and its newest value.

    Parameters
    ----------
    times_days : numpy.ndarray
        (runs,) time of each history column, days (any origin, the same as ``now_days``).
    history : numpy.ndarray
        (segments, runs) index of earlier speed-matched runs (NaN = none).
    value : numpy.ndarray
        (segments,) index of the newest run.
    now_days : float
        Time of the newest run, days.
    params : ChangeParams
    seg, segment_m : numpy.ndarray and float, optional
        Segment numbers and length (m): with them, the residual spreads are
        pooled within blocks (:func:`pooled_spread`).

    Returns
    -------
    TrendResult
    """
    x = np.asarray(value, dtype=np.float64)
    if x.ndim != 1:
        raise ValueError("value: must be 1-D")
    h = _matrix(history, x.size)
    t = np.asarray(times_days, dtype=np.float64)
    if t.shape != (h.shape[1],):
        raise ValueError(f"times_days: must have one time per history column ({h.shape[1]}), got shape {t.shape}")
    if not np.isfinite(now_days):
        raise ValueError(f"now_days: must be finite, got {now_days!r}")
    inside = (t >= now_days - params.trend_window_days) & (t < now_days) & np.isfinite(t)
    y = np.concatenate([h[:, inside], x[:, None]], axis=1)
    tt = np.concatenate([t[inside], [now_days]]) - now_days
    ok = np.isfinite(y)
    n = ok.sum(axis=1)
    med, spread = robust_spread(y, min_spread=params.min_spread)
    lo, hi = (med - 3 * spread)[:, None], (med + 3 * spread)[:, None]
    yw = np.where(ok, np.clip(y, lo, hi), np.nan)

    def fit(keep: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Slope, score and count of the least-squares line over the columns ``keep``."""
        yy, tk = yw[:, keep], tt[keep]
        okk = np.isfinite(yy)
        nk = okk.sum(axis=1)
        w = okk.astype(np.float64)
        with np.errstate(invalid="ignore", divide="ignore"):
            t_mean = (tk[None, :] * w).sum(axis=1) / nk
            y_mean = np.where(okk, yy, 0.0).sum(axis=1) / nk
            dt = (tk[None, :] - t_mean[:, None]) * w
            sxx = (dt * dt).sum(axis=1)
            slope = (dt * np.where(okk, yy - y_mean[:, None], 0.0)).sum(axis=1) / sxx
            resid = np.where(okk, yy - y_mean[:, None] - slope[:, None] * dt, np.nan)
            _, r_spread = robust_spread(resid, min_spread=params.min_spread)
            if seg is not None and segment_m is not None:
                r_spread = pooled_spread(r_spread, nk, seg, segment_m=segment_m, block_m=params.block_m(segment_m),
                                         prior_runs=params.spread_prior_runs)
            z_k = np.where(sxx > 0, slope / (r_spread / np.sqrt(sxx)), np.nan)
        return slope, z_k, nk

    slope, z, _ = fit(np.ones(tt.size, dtype=bool))
    # a step inside the window also tilts the line: a trend must go on in the recent half of the data
    recent_slope, recent_z, n_recent = fit(tt >= tt.min() / 2)
    consistent = (np.sign(recent_slope) == np.sign(slope)) & (np.abs(recent_z) >= params.trend_recent_z)
    z = np.where(consistent, z, 0.0)
    # the newest value and at least min_history earlier ones, spread over some time
    testable = (n >= params.min_history + 1) & (n_recent >= params.min_history // 2 + 1) & np.isfinite(x) & np.isfinite(slope)
    return TrendResult(
        rate_per_year=np.where(testable & consistent, slope * DAYS_PER_YEAR, np.nan),
        z=np.where(testable, z, np.nan),
        n_runs=n.astype(np.int64),
    )


def level_offsets(
    deviation: np.ndarray, seg: np.ndarray, *, segment_m: float, block_m: float, min_segments: int = 5
) -> np.ndarray:
    """Level of each run column: the median deviation of the segments of each block.

    Parameters
    ----------
    deviation : numpy.ndarray
        (segments, runs) index minus the segment's baseline (NaN = none).
    seg : numpy.ndarray
        (segments,) segment numbers (position ``seg · segment_m``, m).
    segment_m, block_m : float
        Segment and block length, m.
    min_segments : int
        Blocks with fewer values in a column get offset 0 there.

    Returns
    -------
    numpy.ndarray
        (segments, runs) offset to subtract (0 where unknown).
    """
    d = _matrix(deviation)
    s = np.asarray(seg, dtype=np.int64)
    if s.shape != (d.shape[0],):
        raise ValueError(f"seg: must have one number per row of deviation ({d.shape[0]}), got shape {s.shape}")
    out = np.zeros_like(d)
    if d.size == 0:
        return out
    with np.errstate(invalid="ignore"):
        for rows in _blocks(s, segment_m, block_m)[1]:
            part = d[rows]
            med = nan_median(part, axis=0)
            enough = np.isfinite(part).sum(axis=0) >= min_segments
            out[rows] = np.where(enough & np.isfinite(med), med, 0.0)[None, :]
    return out


@dataclass(frozen=True)
class WheelChange:
    """Change tests of one wheel's segments (arrays of the segments' length).

    Attributes
    ----------
    n_history : numpy.ndarray
        int64 speed-matched history runs.
    baseline : numpy.ndarray
        Median of the matched, levelled history (log units).
    change, change_z : numpy.ndarray
        Newest value minus baseline, and its step score.
    trend_rate, trend_z : numpy.ndarray
        Trend per year and its score (NaN when no trend test was asked or possible).
    exponent : float
        Speed exponent used to move the history to the newest run's speed.
    change_sd : numpy.ndarray
        The step score's denominator (log units): the 1-σ of ``change`` with the stated part counted
        ``stated_wheels`` times; the 1-σ of the mean change over those wheels is its mean over them
        divided by ``sqrt(stated_wheels)``.
    """

    n_history: np.ndarray
    baseline: np.ndarray
    change: np.ndarray
    change_z: np.ndarray
    trend_rate: np.ndarray
    trend_z: np.ndarray
    exponent: float
    change_sd: np.ndarray | None = None


def detect_changes(
    history: np.ndarray,
    history_speed: np.ndarray,
    history_days: np.ndarray,
    value: np.ndarray,
    speed: np.ndarray,
    now_days: float,
    seg: np.ndarray,
    *,
    segment_m: float,
    params: ChangeParams = DEFAULT_CHANGE_PARAMS,
    trend: bool = True,
    sd_value: np.ndarray | None = None,
    sd_history: np.ndarray | None = None,
    surface_days: np.ndarray | None = None,
    stated_wheels: int = 1,
    history_vehicle: np.ndarray | None = None,
    vehicle: object = None,
) -> WheelChange:
    """The newest run of one wheel against its history: speed matching, run level, step and trend.

    Parameters
    ----------
    history, history_speed : numpy.ndarray
        (segments, runs) index and speed (m/s) of earlier runs, oldest column first (NaN = none);
        the step test takes each segment's ``params.history_runs`` most recent speed-matched values.
    history_days : numpy.ndarray
        (runs,) time of each history run, days.
    value, speed : numpy.ndarray
        (segments,) index and speed of the newest run.
    now_days : float
        Time of the newest run, days.
    seg : numpy.ndarray
        (segments,) segment numbers.
    segment_m : float
        Segment length, m.
    params : ChangeParams
    trend : bool
        Also run the trend test.
    sd_value, sd_history : numpy.ndarray, optional
        (segments,) and (segments, runs) stated 1-σ of the newest and the history's index (NaN: none).
    surface_days : numpy.ndarray, optional
        (segments,) day of the latest rail-surface intervention on the segment up to the newest run
        (:func:`~app.analysis.condition.interventions.latest_action_days`; NaN: none).
    stated_wheels : int, optional
        Wheels whose scores will be combined (:func:`step_change`; default 1).
    history_vehicle, vehicle : numpy.ndarray and object, optional
        (runs,) vehicle of each history run and the newest run's: the step test's passes are the same
        vehicle's (:func:`vehicle_matched`; None: all runs one vehicle's).

    Returns
    -------
    WheelChange
    """
    x = np.asarray(value, dtype=np.float64)
    matched = matched_passes(history, history_speed, speed, params, history_vehicle=history_vehicle, vehicle=vehicle)
    h, extra, testable = matched.history, matched.extra_var, matched.testable
    times = np.asarray(history_days, dtype=np.float64)
    finite = np.isfinite(h)
    # per segment the history_runs most recent matched values (columns are oldest first)
    recent = finite & (np.cumsum(finite[:, ::-1], axis=1)[:, ::-1] <= params.history_runs)
    base = nan_median(np.where(recent, h, np.nan), axis=1)
    y = np.concatenate([h, x[:, None]], axis=1)
    dev = y - base[:, None]
    crossed = None
    if surface_days is not None:
        sdays = np.asarray(surface_days, dtype=np.float64)
        if sdays.shape != (x.size,):
            raise ValueError(f"surface_days: must have one day per segment ({x.size}), got shape {sdays.shape}")
        with np.errstate(invalid="ignore"):
            crossed = times[None, :] < sdays[:, None]  # NaN: False
        # a new rail surface moves its segments: the run's level comes from the others
        dev = np.where(crossed.any(axis=1)[:, None], np.nan, dev)
    y = y - level_offsets(dev, seg, segment_m=segment_m, block_m=params.block_m(segment_m),
                          min_segments=params.min_level_segments)
    h_lev, x_lev = y[:, :-1], y[:, -1]
    step = step_change(np.where(recent, h_lev, np.nan), x_lev, params, seg=seg, segment_m=segment_m,
                       sd_value=sd_value, sd_history=sd_history, crossed=crossed, stated_wheels=stated_wheels,
                       extra_var=extra)
    if not testable.all():
        step = replace(step, z=np.where(testable, step.z, np.nan))
    if trend and h.shape[1]:
        # the runs before a rail-surface intervention measured another rail: not in the trend
        h_tr = h_lev if crossed is None else np.where(crossed, np.nan, h_lev)
        tr = trend_change(times, h_tr, x_lev, now_days, params, seg=seg, segment_m=segment_m)
        rate, tz = tr.rate_per_year, tr.z
    else:
        rate = tz = np.full(x.size, np.nan)
    return WheelChange(
        n_history=step.n_history, baseline=step.baseline, change=step.change, change_z=step.z,
        trend_rate=rate, trend_z=tz, exponent=matched.exponent, change_sd=step.sd,
    )


def series_labels(index: Sequence[np.ndarray] | np.ndarray) -> np.ndarray:
    """Which wheels give one index: wheels whose index is the same at every segment (to rounding) share a
    label — the two-rail estimate gives both wheels of an axle one value.

    Parameters
    ----------
    index : sequence of numpy.ndarray
        Each wheel's index over the same segments (NaN: none).

    Returns
    -------
    numpy.ndarray
        (wheels,) int64 label of each wheel: the position of the first wheel of its series.
    """
    rows = [np.asarray(r, dtype=np.float64) for r in index]
    labels = np.arange(len(rows), dtype=np.int64)
    for w, r in enumerate(rows):
        for v in range(w):
            o = rows[v]
            if labels[v] == v and o.shape == r.shape and np.allclose(r, o, rtol=1e-9, atol=1e-12, equal_nan=True):
                labels[w] = v
                break
    return labels


def series_counts(ok: np.ndarray, series: np.ndarray | None = None) -> np.ndarray:
    """How many wheels of each series (:func:`series_labels`) have a value, per segment.

    Parameters
    ----------
    ok : numpy.ndarray
        (wheels, segments) bool: the wheel has a value there.
    series : numpy.ndarray, optional
        (wheels,) label of each wheel's series (default: every wheel its own).

    Returns
    -------
    numpy.ndarray
        (series, segments) int64 counts, series in the order of their sorted labels.
    """
    okk = np.asarray(ok, dtype=bool)
    lab = np.arange(okk.shape[0]) if series is None else np.asarray(series)
    if lab.shape != (okk.shape[0],):
        raise ValueError(f"series: must have one label per wheel ({okk.shape[0]}), got shape {lab.shape}")
    groups = np.unique(lab)
    out = np.zeros((groups.size, okk.shape[1]), dtype=np.int64)
    for k, g in enumerate(groups):
        out[k] = okk[lab == g].sum(axis=0)
    return out


def axle_labels(wheels: Sequence[str]) -> np.ndarray:
    """The axle of each wheel from its name: the digits less the last (``"11"``, ``"Z12"`` → ``"1"``; the side
    is the last digit). A name without two digits is its own axle.

    Parameters
    ----------
    wheels : sequence of str
        Wheel names.

    Returns
    -------
    numpy.ndarray
        (wheels,) object labels.
    """
    out = []
    for w in wheels:
        digits = "".join(ch for ch in str(w) if ch.isdigit())
        out.append(digits[:-1] if len(digits) >= 2 else str(w))
    return np.array(out, dtype=object)


def axle_consistency(change: np.ndarray, sd: np.ndarray, axles: np.ndarray) -> np.ndarray:
    """How far the axles' changes disagree beyond their 1-σ: the Birge ratio ``S`` (≥ 1) per segment.

    Every axle of a run passes the same support under the same rails at the same speed, so a change of the
    support is one change under all of them. Per axle the mean change ``c_a`` of its wheels with a value and
    their mean 1-σ ``s_a`` (the wheels of an axle taken as fully correlated: the upper bound) give
    ``χ² = Σ (c_a − ĉ)² / s_a²`` about the weighted mean ``ĉ``; ``S = √max(1, χ² / (n_axles − 1))`` scales the
    combined score down where they disagree more than their errors allow (the scale factor of a weighted
    mean of inconsistent measurements). The 1-σ hold the stated part too, counted as the wheels share it
    (:func:`step_change`): the difference of two axles sees less of it, so ``S`` is the smaller, lower bound.

    Parameters
    ----------
    change, sd : numpy.ndarray
        (wheels, segments) change and its 1-σ, log units (NaN: none).
    axles : numpy.ndarray
        (wheels,) axle of each wheel (:func:`axle_labels`).

    Returns
    -------
    numpy.ndarray
        (segments,) ``S ≥ 1``; 1 where fewer than two axles have a value.
    """
    c = np.asarray(change, dtype=np.float64)
    s = np.asarray(sd, dtype=np.float64)
    if c.ndim != 2 or s.shape != c.shape:
        raise ValueError(f"change, sd: must be 2-D of one shape (wheels × segments), got {c.shape} and {s.shape}")
    lab = np.asarray(axles, dtype=object)
    if lab.shape != (c.shape[0],):
        raise ValueError(f"axles: must have one label per wheel ({c.shape[0]}), got shape {lab.shape}")
    ok = np.isfinite(c) & np.isfinite(s) & (s > 0)
    groups = list(dict.fromkeys(lab.tolist()))
    ca = np.full((len(groups), c.shape[1]), np.nan)
    sa = np.full_like(ca, np.nan)
    with np.errstate(invalid="ignore", divide="ignore"):
        for k, g in enumerate(groups):
            rows = lab == g
            n = ok[rows].sum(axis=0)
            ca[k] = np.where(n > 0, np.where(ok[rows], c[rows], 0.0).sum(axis=0) / n, np.nan)
            sa[k] = np.where(n > 0, np.where(ok[rows], s[rows], 0.0).sum(axis=0) / n, np.nan)
        has = np.isfinite(ca)
        n_axles = has.sum(axis=0)
        w = np.where(has, 1.0 / sa**2, 0.0)
        mean = (w * np.where(has, ca, 0.0)).sum(axis=0) / w.sum(axis=0)
        chi2 = (w * np.where(has, ca - mean[None, :], 0.0) ** 2).sum(axis=0)
        ratio = np.where(n_axles >= 2, chi2 / np.maximum(n_axles - 1, 1), 1.0)
    return np.sqrt(np.fmax(np.nan_to_num(ratio, nan=1.0), 1.0))


def combine_wheels(z: np.ndarray, agree_z: float, series: np.ndarray | None = None, *,
                   change: np.ndarray | None = None, sd: np.ndarray | None = None,
                   axles: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Combined score over wheels (Stouffer over the wheels with a score) and who agrees.

    Wheels of one series (``series``: the two-rail estimate gives both wheels of an axle one index,
    :func:`series_labels`) are one witness counted as often as it appears: the sum is over the wheels, its
    variance ``Σ n_g²`` over the series ``g`` with ``n_g`` wheels scored — ``Σ z / √n`` where every wheel has
    its own, ``(z₁ + z₄) / √2`` for two axles of two wheels each (``Σ z / √n`` counted such an axle's score
    twice: ``z₁ + z₄``, √2 too high).

    With the wheels' ``change`` and its 1-σ ``sd`` and their ``axles``, the combined score is divided by the
    axles' disagreement (:func:`axle_consistency`): one axle reading a change that the other, over the same
    support and rails, does not read is not a change of the support (issue 33's line: a false step read
    −0.28 ± 0.04 on axle 1 and −0.05 ± 0.06 on axle 4, combined z −5.3).

    Parameters
    ----------
    z : numpy.ndarray
        (wheels, segments) scores (NaN = no test).
    agree_z : float
        A wheel agrees when its score has the combined sign and ``|z| ≥ agree_z``.
    series : numpy.ndarray, optional
        (wheels,) label of each wheel's series (:func:`series_labels`; default: every wheel its own).
    change, sd : numpy.ndarray, optional
        (wheels, segments) each wheel's change and the 1-σ its score divides it by, log units.
    axles : numpy.ndarray, optional
        (wheels,) axle of each wheel (:func:`axle_labels`); default: the series.

    Returns
    -------
    combined : numpy.ndarray
        (segments,) combined score (NaN where no wheel has one).
    agree : numpy.ndarray
        (wheels, segments) bool: the wheel agrees.
    """
    zz = np.asarray(z, dtype=np.float64)
    if zz.ndim != 2:
        raise ValueError(f"z: must be 2-D (wheels × segments), got shape {zz.shape}")
    if (change is None) != (sd is None):
        raise ValueError("change, sd: give both or neither")
    ok = np.isfinite(zz)
    n = ok.sum(axis=0)
    # a series scored by n_g wheels is one witness counted n_g times: the sum's variance is Σ n_g²
    pairs = (series_counts(ok, series) ** 2).sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        combined = np.where(n > 0, np.where(ok, zz, 0.0).sum(axis=0) / np.sqrt(np.maximum(pairs, 1)), np.nan)
    if change is not None and sd is not None:
        c = np.asarray(change, dtype=np.float64)
        if c.shape != zz.shape:
            raise ValueError(f"change: must have the shape of z {zz.shape}, got {c.shape}")
        labels = axles if axles is not None else (np.arange(zz.shape[0]) if series is None else series)
        combined = combined / axle_consistency(np.where(ok, c, np.nan), np.asarray(sd, dtype=np.float64),
                                               np.asarray(labels, dtype=object))
    agree = ok & (np.sign(zz) == np.sign(combined)[None, :]) & (np.abs(np.where(ok, zz, 0.0)) >= agree_z)
    return combined, agree
