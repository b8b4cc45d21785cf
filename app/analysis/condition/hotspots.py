"""Hotspots: a line's segments ranked by where to act first.

Per segment of a run (usually the line's newest), four pieces of evidence,
each in units of its own threshold:

* **anomaly** — the segment's index (mean over wheels) against the segments of
  the same superstructure class in the run: robust z-score ``(x − median) /
  (1.4826 · MAD)`` of the class; stiffer (higher) or softer than its kind;
* **change** — the step test of the newest run against the segment's history
  (wheels combined, :func:`app.analysis.condition.change.combine_wheels`);
* **rate** — the trend test (per year, wheels combined; for 10 m segments that
  of the 100 m segment holding it);
* **wheels agreeing** — how many wheels show the strongest of them on their own.

``strength = max(|anomaly| / anomaly_z, |change| / step_z, |rate| / trend_z)``;
where it reaches 1 (a criterion beyond its threshold) ``priority = strength ·
(1 + 0.5 · agreeing / wheels)`` — the wheels agreeing weigh it up by half —
elsewhere ``priority = strength`` (below 1). ``reasons``
names the criteria beyond their thresholds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from app.analysis.condition.change import (
    DEFAULT_CHANGE_PARAMS,
    ChangeParams,
    combine_wheels,
    nan_median,
)

__all__ = ["HotspotTable", "rank_segments", "DEFAULT_ANOMALY_Z"]

#: Robust z of the anomaly against the class beyond which a segment stands out.
DEFAULT_ANOMALY_Z = 3.5
_MAD_TO_SD = 1.4826


@dataclass(frozen=True)
class HotspotTable:
    """Per-segment evidence and priority (arrays of the segments' length, in segment order).

    Attributes
    ----------
    seg : numpy.ndarray
        Segment numbers.
    index : numpy.ndarray
        Index, mean over the wheels.
    anomaly_z, change, change_z, rate_per_year, trend_z : numpy.ndarray
        The evidence (NaN: not available).
    agreeing, n_wheels : numpy.ndarray
        int64: wheels showing the strongest criterion on their own, wheels with data.
    priority : numpy.ndarray
        Ranking score (see the module docstring).
    direction : numpy.ndarray
        int64 +1 / -1 of the strongest criterion.
    reasons : list of tuple of str
        Criteria beyond their threshold: ``"anomaly"``, ``"change"``, ``"trend"``.
    """

    seg: np.ndarray
    index: np.ndarray
    anomaly_z: np.ndarray
    change: np.ndarray
    change_z: np.ndarray
    rate_per_year: np.ndarray
    trend_z: np.ndarray
    agreeing: np.ndarray
    n_wheels: np.ndarray
    priority: np.ndarray
    direction: np.ndarray
    reasons: list[tuple[str, ...]]


def _class_z(values: np.ndarray, classes: np.ndarray) -> np.ndarray:
    """Robust z of each value against the values of its class (NaN where MAD is 0 or unknown)."""
    z = np.full(values.shape, np.nan)
    for c in np.unique(classes):
        m = classes == c
        v = values[..., m]
        med = nan_median(v, axis=-1)[..., None]
        mad = _MAD_TO_SD * nan_median(np.abs(v - med), axis=-1)[..., None]
        with np.errstate(invalid="ignore", divide="ignore"):
            z[..., m] = np.where(mad > 0, (v - med) / mad, np.nan)
    return z


def _mean_over_wheels(a: np.ndarray) -> np.ndarray:
    """Mean over axis 0 of the finite values (NaN where there is none)."""
    ok = np.isfinite(a)
    n = ok.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, np.where(ok, a, 0.0).sum(axis=0) / n, np.nan)


def rank_segments(
    seg: np.ndarray,
    classes: np.ndarray,
    wheel_index: np.ndarray,
    wheel_change: np.ndarray,
    wheel_change_z: np.ndarray,
    wheel_trend_rate: np.ndarray,
    wheel_trend_z: np.ndarray,
    *,
    params: ChangeParams = DEFAULT_CHANGE_PARAMS,
    anomaly_z: float = DEFAULT_ANOMALY_Z,
) -> HotspotTable:
    """Evidence and priority of every segment of a run.

    Parameters
    ----------
    seg : numpy.ndarray
        (segments,) segment numbers.
    classes : numpy.ndarray
        (segments,) superstructure class of each segment (any labels; one group per label).
    wheel_index, wheel_change, wheel_change_z, wheel_trend_rate, wheel_trend_z : numpy.ndarray
        (wheels, segments) per wheel (NaN where a wheel has no value).
    params : ChangeParams
        Thresholds of the change tests (``step_z``, ``trend_z``, ``agree_z``).
    anomaly_z : float
        Threshold of the anomaly against the class (> 0).

    Returns
    -------
    HotspotTable
    """
    if not anomaly_z > 0:
        raise ValueError(f"anomaly_z: must be > 0, got {anomaly_z!r}")
    s = np.asarray(seg, dtype=np.int64)
    cls = np.asarray(classes, dtype=object)
    arrays = [np.asarray(a, dtype=np.float64) for a in
              (wheel_index, wheel_change, wheel_change_z, wheel_trend_rate, wheel_trend_z)]
    for name, a in zip(("wheel_index", "wheel_change", "wheel_change_z", "wheel_trend_rate", "wheel_trend_z"),
                       arrays, strict=True):
        if a.ndim != 2 or a.shape[1] != s.size or a.shape[0] != arrays[0].shape[0]:
            raise ValueError(f"{name}: must be (wheels, {s.size}), got shape {a.shape}")
    if cls.shape != s.shape:
        raise ValueError(f"classes: must have one label per segment ({s.size}), got shape {cls.shape}")
    idx, chg, cz, rate, tz = arrays
    n_wheels = np.isfinite(idx).sum(axis=0)
    index, change, rate_mean = _mean_over_wheels(idx), _mean_over_wheels(chg), _mean_over_wheels(rate)
    a_z = _class_z(index, cls)
    wheel_a_z = _class_z(idx, cls)
    c_z, c_agree = combine_wheels(cz, params.agree_z)
    t_z, t_agree = combine_wheels(tz, params.agree_z)
    a_agree = np.isfinite(wheel_a_z) & (np.sign(wheel_a_z) == np.sign(a_z)[None, :]) & (
        np.abs(np.nan_to_num(wheel_a_z)) >= params.agree_z)
    parts = np.stack([np.abs(np.nan_to_num(a_z)) / anomaly_z, np.abs(np.nan_to_num(c_z)) / params.step_z,
                      np.abs(np.nan_to_num(t_z)) / params.trend_z])
    best = np.argmax(parts, axis=0)
    strength = parts.max(axis=0)
    agree = np.choose(best, [a_agree.sum(axis=0), c_agree.sum(axis=0), t_agree.sum(axis=0)])
    signs = np.choose(best, [np.sign(np.nan_to_num(a_z)), np.sign(np.nan_to_num(c_z)), np.sign(np.nan_to_num(t_z))])
    with np.errstate(invalid="ignore", divide="ignore"):
        boost = 1.0 + 0.5 * np.where(n_wheels > 0, agree / n_wheels, 0.0)
    priority = np.where(strength >= 1.0, strength * boost, strength)
    names = ("anomaly", "change", "trend")
    reasons = [tuple(names[k] for k in range(3) if parts[k, j] >= 1.0) for j in range(s.size)]
    return HotspotTable(
        seg=s, index=index, anomaly_z=a_z, change=change, change_z=c_z, rate_per_year=rate_mean, trend_z=t_z,
        agreeing=agree.astype(np.int64), n_wheels=n_wheels.astype(np.int64), priority=priority,
        direction=np.where(signs < 0, -1, 1).astype(np.int64), reasons=reasons,
    )
