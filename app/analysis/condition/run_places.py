"""A run's places: where the speed-conditioned index stands out or changed, merged and graded.

Per 10 m segment of a run (wheels × segments), with the **speed-conditioned
stiffness index** ``ln(A / A_ref(class, v))`` of the run and of its history
(the earlier runs of the line, the same reference curves: :func:`segment_index`):

* **anomaly** — the index (mean over the wheels) reaches the alert limit of
  its superstructure class (:class:`~app.analysis.condition.tiers.TierTable`
  ``levels``): the place departs from the typical track of its kind *at the
  speed it was passed*, so speed ramps at stations do not read as track;
* **step** — the index against the segment's own history of **matched passes**
  (given the speeds and vehicles: the earlier runs passed at a matched speed by
  the same vehicle, the flags' rule,
  :func:`~app.analysis.condition.change.matched_passes`; on rough rails the
  index is the rails' response as much as the support's, and that response
  changes with the speed and the vehicle): median baseline,
  robust repeatability, run level per kilometre block taken out, wheels
  combined (:func:`~app.analysis.condition.change.detect_changes`,
  :func:`~app.analysis.condition.change.combine_wheels`: a change of the support is one change under
  every axle, and the axles' disagreement beyond their 1-σ divides the combined score); a step counts where
  ``|z| ≥ step_z`` **and** the change reaches the alert limit of ``changes``
  (a significant change too small to act on is not a place). A step back towards the typical
  track on a segment that was an anomaly before (a hard place softening, a repair) is that anomaly
  shrinking, not a new place the other way: no step, unless the segment overshoots into an anomaly
  of the other side (without this rule a shrinking hard place was listed as a new soft place at its
  km, "growing");
* **trend** — the index's slope over the last ``trend_window_days`` of the
  segment's history (:func:`~app.analysis.condition.change.trend_change`, the
  same levelled history), wheels combined: ``|z| ≥ trend_z`` and a rate of at
  least ``min_rate_per_year`` away from the class's typical track, reaching the class's alert
  limit within ``watch_days`` at that rate where it is the only evidence. A place
  growing steadily has a history too spread for the step test and may not
  have reached a limit yet: the trend finds it (tier *watch* until it does). Not on a segment whose
  rail surface was changed (``surface_days``) within the trend window: a new surface runs in.

**After maintenance on the support** (``support_days``: a tamping, ballast cleaning — every action that is
not on the rails' surface) a segment's history starts anew: the step and the trend tests see only the runs
after the latest such action on it (:func:`~app.analysis.condition.interventions.since_actions`). The work
changed the support by intent; read across it, a step or a trend measures the work (the demo's tamped place
was listed a month later as a new soft place "growing" at −174 % a year).

Exceeding segments merge into places (:func:`~app.analysis.condition.places.merge_places`;
a step segment's direction is that of its change, a trend's that of its rate,
an anomaly's that of its index). A place's **level** is the index at its peak segment, its **change**
the change there; its tier is the higher of the level's tier (limits of its
class) and the change's (``changes``), and its severity in tier units
(``magnitude / alert limit`` of whichever is higher) orders places of one tier.

**Uncertainty.** With the stated 1-σ of the runs' index (the store's ``index_sd``) the step test
widens as :mod:`app.analysis.condition.change` says (the newest run's excess over the history's, and
across a rail-surface intervention — ``surface_days`` — both sides' roughness response: a grinding
is not a stiffness change). A place's size carries its 1-σ: the level's is the wheels' mean stated
1-σ at the peak segment (the wheels of a run meet the same rails at the same speed: their errors are
taken as fully correlated, the upper bound), the change's that of the wheels' mean change (the step
test's denominators, the stated part shared by the wheels). **Grading rests on the size and its
1-σ**: a level is graded in units of the healthy scatter at its pass (:func:`graded_level`: the limits
stand for the class's healthy scatter σ0, a pass uncertain by sd has √(σ0² + sd²); on rough rail one
pass's 10 m level is uncertain by tens of per cent — the rails' response at the sleeper spacing, which a
typical support under them gives too — and a level graded on its lower 1-σ bound reached the alert limit
at 1.8 σ of that scatter: the rails' roughness, not the support, made the anomalies; a stated 1-σ is at
least its class's scatter from segment to segment in the run beyond σ0, :func:`class_scatter`), a change on its
lower 1-σ bound; an *anomaly* is found only where the graded level reaches the class's alert limit, the
rule "a step back from a former anomaly is that anomaly shrinking" judges the former level the same way
(with the history's median stated 1-σ), and a place reaches the intervention or immediate-action tier
only where its graded level or its change less its 1-σ reaches that limit (a found place keeps at least
the alert tier). ``severity_sd`` is the 1-σ of
``severity`` (of the size that sets it, in the same units). Without a stated 1-σ (NaN) all this is as
before.

The history is the speed-conditioned index, so passes within the matched-speed tolerance compare however
their speeds spread inside it. Without the speeds (``speed=None``) every earlier run counts, whatever its
speed — right on smooth rails, where the index is comparable across speeds, and wrong on rough ones (issue
33's line: one segment read −0.9 by one vehicle at 136 km/h and +0.5 by it at 91 km/h, each within ±0.1 run
after run; a place found at one speed was graded at the other on that difference).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from app.analysis.condition.change import (
    ChangeParams,
    combine_wheels,
    detect_changes,
    series_counts,
    series_labels,
)
from app.analysis.condition.interventions import since_actions
from app.analysis.condition.places import (
    EVIDENCE_ANOMALY,
    EVIDENCE_STEP,
    EVIDENCE_TREND,
    PlaceTable,
    merge_places,
)
from app.analysis.condition.tiers import TierLimits, TierTable
from app.analysis.robust import nan_median, robust_spread
from app.analysis.stiffness.reference_curve import ReferenceCurve
from app.analysis.units import DAYS_PER_YEAR

__all__ = [
    "DEFAULT_LEVEL_LIMITS",
    "HEALTHY_ALERT_Z",
    "graded_level",
    "DEFAULT_CHANGE_LIMITS",
    "DEFAULT_PLACE_PARAMS",
    "PlaceParams",
    "RunPlaces",
    "segment_index",
    "find_places",
    "mean_over_wheels",
]

#: Limits of ``|index|`` per superstructure class (ln units), measured (``bench/bench_places.py``: three
#: seeds of a uniform and a planted history, 12 runs each, through the real pipeline; BENCHMARKS.md): the
#: alert limit is about 3.3 standard deviations of the class's healthy 10 m index (slab 0.073, B91 without
#: pads 0.076, with pads 0.098: soft track has the lower signal-to-noise ratio) and above every healthy
#: 10 m segment measured (largest: 0.20, 0.24, 0.23); intervention and immediate action at 1.5 and 2.5
#: times it, the ratios of EN 13848-5's limits for isolated defects. Classes without a row (slab, B91
#: without pads, …) use the default.
DEFAULT_LEVEL_LIMITS = TierTable(TierLimits(0.25, 0.375, 0.625), {"b91_pads": TierLimits(0.30, 0.45, 0.75)})

#: A class's alert limit in standard deviations of its healthy 10 m index (the measurement behind
#: :data:`DEFAULT_LEVEL_LIMITS`): ``alert / HEALTHY_ALERT_Z`` is the healthy scatter the limits stand for.
HEALTHY_ALERT_Z = 3.3


def graded_level(level: np.ndarray | float, level_sd: np.ndarray | float,
                 alert: np.ndarray | float) -> np.ndarray:
    """A level's size as its tier limits grade it, given its stated 1-σ: ``|level|`` in units of the healthy
    scatter at its pass, on the scale of the limits.

    The limits stand for a healthy scatter ``σ0 = alert / HEALTHY_ALERT_Z`` of the class's 10 m index (the
    track's own variation and a pass's noise on smooth rails); a pass whose level is uncertain by ``sd`` (on
    rough rails mostly the rails' response at the sleeper spacing, which a support of the typical kind under
    them gives too) has a healthy scatter ``√(σ0² + sd²)``. A level reaches a limit where it lies that limit's
    multiple of ``σ0`` beyond the typical track in units of that scatter: graded is
    ``|level| / √(1 + (sd / σ0)²)``. With a small 1-σ this is the level less about its 1-σ (smooth rails: a
    stated 0.056 against σ0 0.076 needs 0.31 for the alert limit of 0.25, the lower 1-σ bound 0.306); with a
    large one it is not: on issue 33's rough line (1-σ 0.2–0.4, the class's spread across the segments of one
    run alike) the lower 1-σ bound put the alert limit at 1.8 σ of that spread, and every run listed the same
    segments of the rails' roughness as places.

    Parameters
    ----------
    level, level_sd : array_like
        The index (ln units) and its stated 1-σ (NaN: none stated, graded as it is).
    alert : array_like
        The alert limit of each level's class (inf: none).

    Returns
    -------
    numpy.ndarray
        The graded size (ln units, ≥ 0; NaN where ``level`` is NaN).
    """
    x = np.abs(np.asarray(level, dtype=np.float64))
    sd = np.nan_to_num(np.asarray(level_sd, dtype=np.float64), nan=0.0)
    sigma0 = np.asarray(alert, dtype=np.float64) / HEALTHY_ALERT_Z
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = np.where(np.isfinite(sigma0) & (sigma0 > 0), sd / sigma0, 0.0)
    return x / np.sqrt(1.0 + ratio * ratio)
#: Limits of ``|change|`` against the own history (ln units): 0.10 is above the largest significant
#: step of healthy segments between runs at different speeds (0.05–0.10: the VKF's resolution along
#: the track changes with speed) and below the changes to find (a 20 % change is 0.22: alert); a sudden
#: change of +35 % / −26 % is an intervention, of +65 % / −40 % immediate action.
DEFAULT_CHANGE_LIMITS = TierLimits(0.10, 0.30, 0.50)


#: The places' matched-speed window: passes within 25 % of the run's speed either way. The places compare the
#: speed-conditioned index (the class's curve over speed taken out), so only the rails' own response's change
#: with speed separates passes: a fleet whose cruise speeds spread over ±10 % (at most 1.1 / 0.9 = 1.22 apart)
#: stays one group — within the rule's ±10 % a run at the spread's end found 2 of 5 earlier runs and its new
#: change went untested (tests/condition/test_places_pipeline.py) — while speed groups as far apart as issue
#: 33's 26 and 40 m/s (1.54) never mix.
PLACE_SPEED_TOLERANCE = 0.25


@dataclass(frozen=True)
class PlaceParams:
    """How places are found and graded.

    Attributes
    ----------
    levels : TierTable
        Limits of ``|index|`` per superstructure class (ln units).
    changes : TierLimits
        Limits of ``|change|`` against the segment's own history (ln units).
    step_z : float
        Step score a change needs (repeatability units).
    trend_z : float
        Trend score a growth needs.
    min_rate_per_year : float
        Rate a trend needs, ln units per year (0.25: healthy track would reach the alert
        limit within a year).
    trend_window_days : float
        Days of history the trend is fitted over.
    agree_z : float
        A wheel agrees when its own score reaches this.
    min_history : int
        Earlier runs with a value a step test needs.
    history_runs : int
        Most recent runs the baseline is taken over.
    gap_m : float
        Gap tolerance of the merge, m.
    level_block_m : float
        Block of the run-level correction, m.
    watch_days : float
        A trend alone makes a place (tier watch) where it reaches the alert limit within so many days.
    speed_tolerance : float
        The matched-speed rule's tolerance (:mod:`app.analysis.speed_match`): the step and trend tests compare a
        run with its history's passes within ``1 + speed_tolerance`` of its speed either way (where
        :func:`find_places` is given the speeds).
    """

    levels: TierTable
    changes: TierLimits
    step_z: float = 4.5
    trend_z: float = 4.5
    min_rate_per_year: float = 0.25
    trend_window_days: float = 180.0
    agree_z: float = 2.0
    min_history: int = 5
    history_runs: int = 30
    gap_m: float = 10.0
    level_block_m: float = 1000.0
    watch_days: float = 180.0
    speed_tolerance: float = PLACE_SPEED_TOLERANCE

    def __post_init__(self) -> None:
        if not isinstance(self.levels, TierTable):
            raise TypeError("levels: must be a TierTable")
        if not isinstance(self.changes, TierLimits):
            raise TypeError("changes: must be a TierLimits")
        for name in ("step_z", "trend_z", "min_rate_per_year", "trend_window_days", "agree_z", "level_block_m",
                     "watch_days", "speed_tolerance"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"{name}: must be a finite number > 0, got {v!r}")
        if not (np.isfinite(self.gap_m) and self.gap_m >= 0):
            raise ValueError(f"gap_m: must be >= 0, got {self.gap_m!r}")
        if self.min_history < 2:
            raise ValueError(f"min_history: must be >= 2, got {self.min_history!r}")
        if self.history_runs < self.min_history:
            raise ValueError(f"history_runs: must be >= min_history, got {self.history_runs!r}")

    def change_params(self) -> ChangeParams:
        """The step and trend tests' parameters (matched passes within ``speed_tolerance``)."""
        return ChangeParams(step_z=self.step_z, trend_z=self.trend_z, trend_window_days=self.trend_window_days,
                            agree_z=self.agree_z, min_history=self.min_history,
                            history_runs=self.history_runs, history_scan_runs=max(self.history_runs, 60),
                            speed_tolerance=self.speed_tolerance, level_block_m=self.level_block_m)


@dataclass(frozen=True)
class RunPlaces:
    """The places of a run and the per-segment values they come from.

    Attributes
    ----------
    places : PlaceTable
        Extent, centre, peak, direction, evidence bits, agreeing-wheel bits.
    peak_m : numpy.ndarray
        Centre of each place's peak segment (the highest tier, then the largest magnitude), m.
    level, change, change_z : numpy.ndarray
        Per place at its peak segment: index (mean over wheels), change against the history
        and its combined score (NaN without a step test).
    cls : numpy.ndarray
        Superstructure class of the peak segment (object; None: no class there).
    level_tier, change_tier, tier : numpy.ndarray
        int64 tiers (0 … 3) of the level, of the change (0 without step evidence) and the higher.
    severity : numpy.ndarray
        The place's magnitude in units of the alert limit that gives its tier.
    n_agreeing : numpy.ndarray
        int64 wheels agreeing at the peak segment.
    rate_per_year, trend_z : numpy.ndarray
        Per place at its peak segment: the index's rate (ln units per year) and its combined trend score.
    seg : numpy.ndarray
        int64 segment numbers of the per-segment arrays; ``segment_m`` their length, m.
    seg_index, seg_change, seg_change_z : numpy.ndarray
        Per segment: index (mean over wheels), change and combined step score.
    seg_class : numpy.ndarray
        Per segment: superstructure class (object; None: none).
    seg_evidence : numpy.ndarray
        int64 evidence bits per segment.
    level_sd, change_sd, severity_sd : numpy.ndarray
        Per place at its peak segment: the 1-σ of ``level``, of ``change`` and of ``severity`` (NaN: none
        stated; module docstring).
    seg_level_sd : numpy.ndarray
        Per segment: the 1-σ of ``seg_index``.
    """

    places: PlaceTable
    peak_m: np.ndarray
    level: np.ndarray
    change: np.ndarray
    change_z: np.ndarray
    cls: np.ndarray
    level_tier: np.ndarray
    change_tier: np.ndarray
    tier: np.ndarray
    severity: np.ndarray
    n_agreeing: np.ndarray
    rate_per_year: np.ndarray
    trend_z: np.ndarray
    seg: np.ndarray
    segment_m: float
    seg_index: np.ndarray
    seg_change: np.ndarray
    seg_change_z: np.ndarray
    seg_class: np.ndarray
    seg_evidence: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    level_sd: np.ndarray = field(default_factory=lambda: np.zeros(0))
    change_sd: np.ndarray = field(default_factory=lambda: np.zeros(0))
    severity_sd: np.ndarray = field(default_factory=lambda: np.zeros(0))
    seg_level_sd: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def __len__(self) -> int:
        return len(self.places)


#: The measured defaults (step score 4.5 as the store's change tests, 5 earlier runs, gap 10 m).
DEFAULT_PLACE_PARAMS = PlaceParams(DEFAULT_LEVEL_LIMITS, DEFAULT_CHANGE_LIMITS)


def segment_index(log_amp: np.ndarray, speed_mps: np.ndarray, classes: np.ndarray,
                  curves: Mapping[str, ReferenceCurve]) -> np.ndarray:
    """``ln A − ln A_ref(class, v)`` of segments.

    Parameters
    ----------
    log_amp : numpy.ndarray
        ``ln(A / 1 m/s²)`` per segment (any shape ending in segments; e.g. wheels × segments).
    speed_mps : numpy.ndarray
        Speed, m/s (same shape).
    classes : numpy.ndarray
        (segments,) class label of each segment (None: no class, e.g. near a change of
        superstructure: no index).
    curves : mapping of str to ReferenceCurve
        The line's curves by class.

    Returns
    -------
    numpy.ndarray
        The index (NaN where the class has no curve or the speed no reference).
    """
    la = np.asarray(log_amp, dtype=np.float64)
    v = np.asarray(speed_mps, dtype=np.float64)
    if la.shape != v.shape:
        raise ValueError("log_amp, speed_mps: must have equal shapes")
    cls = np.asarray(classes, dtype=object)
    if la.ndim == 0 or cls.shape != (la.shape[-1],):
        raise ValueError(f"classes: must have one label per segment ({la.shape[-1] if la.ndim else 0})")
    out = np.full(la.shape, np.nan)
    labels = np.array(["\0" if c is None else str(c) for c in cls.tolist()], dtype=object)
    for name, curve in curves.items():
        m = labels == name
        if not m.any() or curve.log_speed.size == 0:
            continue
        g, _ = curve.evaluate(v[..., m])
        out[..., m] = la[..., m] - g
    return out


def mean_over_wheels(a: np.ndarray) -> np.ndarray:
    """Mean over axis 0 (the wheels) of the finite values (NaN where there is none)."""
    ok = np.isfinite(a)
    n = ok.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, np.where(ok, a, 0.0).sum(axis=0) / np.maximum(n, 1), np.nan)


#: Pairs of neighbouring segments of a class with an index a run needs for its scatter to count
#: (:func:`class_scatter`): 20 pairs (200 m) give that scatter to about ±16 %.
CLASS_SCATTER_MIN_PAIRS = 20


def class_scatter(level: np.ndarray, classes: np.ndarray, alert: np.ndarray, seg: np.ndarray, *,
                  min_pairs: int = CLASS_SCATTER_MIN_PAIRS) -> np.ndarray:
    """The scatter of each class's index from one 10 m segment to the next in the run, beyond the healthy
    scatter its limits stand for: a 1-σ every level of that class carries in that run.

    The limits stand for the class's healthy scatter ``σ0 = alert / HEALTHY_ALERT_Z``. The rails' response at
    the sleeper spacing differs from one 10 m segment to the next (the roughness that makes it is short-wave
    and each rail's own), while the support varies over longer lengths (a tamped extent, a transition, a soft
    zone); so the scatter is read from neighbouring segments: ``s`` the robust spread of the differences of
    neighbouring segments of the class over √2 (a few edges do not move it), and the run carries
    ``√(s² − σ0²)`` whatever the stated 1-σ of each segment says (:func:`find_places` takes a stated 1-σ as at
    least this). On issue 33's rough line a class scattered 0.29 in a run while one segment stated 0.14, read
    +0.6 at every pass and was listed as a place; on smooth rails ``s`` is a pass's noise, below ``σ0``, and
    this is 0 — also where a long extent of the class departs (the spread across the class's segments, not
    their differences, read a 200 m tamped extent of a smooth line as a scatter of 0.14).

    Parameters
    ----------
    level : numpy.ndarray
        (S,) the run's index per segment (mean over the wheels; NaN: none).
    classes : numpy.ndarray
        (S,) class per segment (None: none).
    alert : numpy.ndarray
        (S,) the alert limit of each segment's class.
    seg : numpy.ndarray
        (S,) segment numbers, ascending (neighbours: numbers one apart).
    min_pairs : int
        Pairs of neighbouring segments with an index a class needs in the run (fewer: NaN for its segments).

    Returns
    -------
    numpy.ndarray
        (S,) the excess scatter, ln units (NaN where not known).
    """
    x = np.asarray(level, dtype=np.float64)
    c = np.asarray(classes, dtype=object)
    a = np.asarray(alert, dtype=np.float64)
    sg = np.asarray(seg, dtype=np.int64)
    if c.shape != x.shape or a.shape != x.shape or sg.shape != x.shape:
        raise ValueError(f"classes, alert, seg: must have one value per segment ({x.size})")
    out = np.full(x.shape, np.nan)
    if x.size < 2:
        return out
    pair = (np.diff(sg) == 1) & (c[1:] == c[:-1]) & np.isfinite(x[1:]) & np.isfinite(x[:-1])
    d = np.diff(x)
    for name in {v for v in c.tolist() if v is not None}:
        rows = c == name
        use = pair & (c[:-1] == name)
        sigma0 = float(np.nanmedian(a[rows])) / HEALTHY_ALERT_Z
        if use.sum() < min_pairs or not np.isfinite(sigma0):
            continue
        _, spread = robust_spread(d[use][None, :])
        out[rows] = np.sqrt(max((float(spread[0]) / np.sqrt(2.0)) ** 2 - sigma0**2, 0.0))
    return out


def find_places(
    seg: np.ndarray,
    index: np.ndarray,
    history: np.ndarray,
    history_days: np.ndarray,
    now_day: float,
    classes: np.ndarray,
    *,
    segment_m: float,
    params: PlaceParams,
    wheel_bits: Sequence[int] | None = None,
    index_sd: np.ndarray | None = None,
    history_sd: np.ndarray | None = None,
    surface_days: np.ndarray | None = None,
    speed: np.ndarray | None = None,
    history_speed: np.ndarray | None = None,
    vehicle: object = None,
    history_vehicle: np.ndarray | None = None,
    support_days: np.ndarray | None = None,
    axles: Sequence[object] | None = None,
) -> RunPlaces:
    """Find and grade a run's places (module docstring).

    Parameters
    ----------
    seg : numpy.ndarray
        (S,) segment numbers, strictly ascending.
    index : numpy.ndarray
        (W, S) speed-conditioned index of the run per wheel (NaN: no value).
    history : numpy.ndarray
        (W, S, R) the index of the earlier runs on these segments and wheels, oldest first
        (NaN: none); R may be 0.
    history_days : numpy.ndarray
        (R,) time of each earlier run, days (the origin of ``now_day``).
    now_day : float
        Time of the run, days.
    classes : numpy.ndarray
        (S,) class per segment (None: none).
    segment_m : float
        Segment length, m.
    params : PlaceParams
    wheel_bits : sequence of int, optional
        Bit of each wheel (row of ``index``) in the places' wheel masks (default ``1 << row``).
    index_sd : numpy.ndarray, optional
        (W, S) stated 1-σ of ``index`` (NaN: none).
    history_sd : numpy.ndarray, optional
        (W, S, R) stated 1-σ of ``history`` (NaN: none).
    surface_days : numpy.ndarray, optional
        (S,) day of the latest rail-surface intervention (grinding, rail renewal) on each segment up to
        ``now_day`` (NaN: none; :func:`~app.analysis.condition.interventions.latest_action_days`).
    speed, history_speed : numpy.ndarray, optional
        (W, S) and (W, S, R) speed of the run's and the history's passes, m/s: the step and trend tests
        compare a wheel with its history's passes at a matched speed
        (:func:`~app.analysis.condition.change.matched_passes`); without them every history run counts.
    vehicle, history_vehicle : object and numpy.ndarray, optional
        The run's vehicle and that of each history run (R,): the tests compare with the same vehicle's
        passes (the other vehicles' brought to it where it has too few; None: all runs one vehicle's).
    support_days : numpy.ndarray, optional
        (S,) day of the latest action on the support (a tamping, ballast cleaning …) on each segment up to
        ``now_day`` (NaN: none; :func:`~app.analysis.condition.interventions.latest_action_days`): the
        segment's history starts anew there (:func:`~app.analysis.condition.interventions.since_actions`).
    axles : sequence, optional
        (W,) axle of each wheel (:func:`~app.analysis.condition.change.axle_labels`; default: the wheels'
        series): a step is one change under every axle, the combined score is scaled down by the axles'
        disagreement (:func:`~app.analysis.condition.change.combine_wheels`).

    Returns
    -------
    RunPlaces
    """
    if not isinstance(params, PlaceParams):
        raise TypeError("params: must be a PlaceParams")
    s = np.asarray(seg, dtype=np.int64)
    x = np.asarray(index, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] != s.size:
        raise ValueError(f"index: must be (wheels, {s.size}), got shape {x.shape}")
    h = np.asarray(history, dtype=np.float64)
    if h.ndim != 3 or h.shape[:2] != x.shape:
        raise ValueError(f"history: must be (wheels, segments, runs) = {x.shape} × runs, got shape {h.shape}")
    days = np.asarray(history_days, dtype=np.float64)
    if days.shape != (h.shape[2],):
        raise ValueError(f"history_days: must have one time per history run ({h.shape[2]}), got shape {days.shape}")
    if not np.isfinite(now_day):
        raise ValueError(f"now_day: must be finite, got {now_day!r}")
    cls = np.asarray(classes, dtype=object)
    if cls.shape != s.shape:
        raise ValueError(f"classes: must have one label per segment ({s.size}), got shape {cls.shape}")
    n_w = x.shape[0]
    bits = np.array([1 << i for i in range(n_w)] if wheel_bits is None else list(wheel_bits), dtype=np.int64)
    if bits.shape != (n_w,):
        raise ValueError(f"wheel_bits: must have one bit per wheel ({n_w})")
    xsd = np.full(x.shape, np.nan) if index_sd is None else np.asarray(index_sd, dtype=np.float64)
    if xsd.shape != x.shape:
        raise ValueError(f"index_sd: must have the shape of index {x.shape}, got {xsd.shape}")
    hsd = np.full(h.shape, np.nan) if history_sd is None else np.asarray(history_sd, dtype=np.float64)
    if hsd.shape != h.shape:
        raise ValueError(f"history_sd: must have the shape of history {h.shape}, got {hsd.shape}")
    for name, per_seg in (("surface_days", surface_days), ("support_days", support_days)):
        if per_seg is not None and np.shape(per_seg) != s.shape:
            raise ValueError(f"{name}: must have one day per segment ({s.size}), got shape {np.shape(per_seg)}")
    v_run = np.ones(x.shape) if speed is None else np.asarray(speed, dtype=np.float64)
    if v_run.shape != x.shape:
        raise ValueError(f"speed: must have the shape of index {x.shape}, got {v_run.shape}")
    v_hist = np.ones(h.shape) if history_speed is None else np.asarray(history_speed, dtype=np.float64)
    if v_hist.shape != h.shape:
        raise ValueError(f"history_speed: must have the shape of history {h.shape}, got {v_hist.shape}")
    if history_vehicle is not None and np.shape(history_vehicle) != (h.shape[2],):
        raise ValueError(f"history_vehicle: must have one label per history run ({h.shape[2]}), "
                         f"got shape {np.shape(history_vehicle)}")

    if support_days is not None:
        # an action on the support starts each segment's history anew: the track before it is another
        h = since_actions(h, days, support_days)
    level = mean_over_wheels(x)
    has_class = np.array([c is not None for c in cls.tolist()], dtype=bool)
    alert = params.levels.alert_limits(cls)
    # where a 1-σ is stated, at least the class's scatter across the run beyond the healthy one (without one,
    # as before)
    scatter = class_scatter(level, cls, alert, s)
    level_sd_seg = mean_over_wheels(np.where(np.isfinite(x), xsd, np.nan))
    level_sd_seg = np.where(np.isfinite(level_sd_seg), np.fmax(level_sd_seg, scatter), level_sd_seg)
    level_tier = np.zeros(s.size, np.int64)
    if has_class.any():
        # graded in units of the healthy scatter at its pass (:func:`graded_level`): a level within what the
        # rails' roughness gives a typical support is no anomaly (on rough rail one pass's 10 m level is
        # uncertain by tens of per cent)
        level_lo = graded_level(level, level_sd_seg, alert)
        level_tier[has_class] = params.levels.grade(level_lo[has_class], cls[has_class])
    # step against the segment's own history, every wheel
    wz = np.full(x.shape, np.nan)
    wchange = np.full(x.shape, np.nan)
    wtz = np.full(x.shape, np.nan)
    wrate = np.full(x.shape, np.nan)
    wsd = np.full(x.shape, np.nan)
    series = series_labels(x)
    axle_of = series if axles is None else np.asarray(list(axles), dtype=object)
    if axle_of.shape != (n_w,):
        raise ValueError(f"axles: must have one label per wheel ({n_w}), got shape {axle_of.shape}")
    if h.shape[2] >= params.min_history:
        cp = params.change_params()
        # the series with an index in this run (a wheel without any is no witness)
        n_series = max(int((series_counts(np.isfinite(x), series).sum(axis=1) > 0).sum()), 1)
        for w in range(n_w):
            ch = detect_changes(h[w], v_hist[w], days, x[w], v_run[w], float(now_day), s, segment_m=segment_m,
                                params=cp, trend=True, sd_value=xsd[w], sd_history=hsd[w], surface_days=surface_days,
                                stated_wheels=n_series, history_vehicle=history_vehicle, vehicle=vehicle)
            wz[w], wchange[w], wtz[w], wrate[w] = ch.change_z, ch.change, ch.trend_z, ch.trend_rate
            wsd[w] = ch.change_sd
    cz, agree = combine_wheels(wz, params.agree_z, series, change=wchange, sd=wsd, axles=axle_of)
    tz, t_agree = combine_wheels(wtz, params.agree_z, series)
    rate = mean_over_wheels(wrate)
    trend = (np.abs(np.nan_to_num(tz)) >= params.trend_z) & (np.abs(np.nan_to_num(rate)) >= params.min_rate_per_year) \
        & (np.sign(np.nan_to_num(tz)) == np.sign(np.nan_to_num(rate)))
    change = mean_over_wheels(wchange)
    change_tier = params.changes.grade(np.abs(change))
    step = (np.abs(np.nan_to_num(cz)) >= params.step_z) & (change_tier >= 1) & (np.sign(np.nan_to_num(cz))
                                                                               == np.sign(np.nan_to_num(change)))
    anomaly = level_tier >= 1
    # a step back towards the class's typical track on a segment that was an anomaly before it is that
    # anomaly shrinking (or repaired), not a new place the other way: the anomaly, while it lasts, stays
    # graded by its level; only where the segment overshoots into an anomaly of the other side is it one
    before = level - change
    before_tier = np.zeros(s.size, np.int64)
    if has_class.any():
        # the history's level graded the same way (with the median stated 1-σ of the history's values)
        before_sd = nan_median(np.where(np.isfinite(h), hsd, np.nan).transpose(1, 0, 2).reshape(s.size, -1), axis=1)
        before_sd = np.where(np.isfinite(before_sd), np.fmax(before_sd, scatter), before_sd)
        before_lo = graded_level(np.nan_to_num(before), before_sd, alert)
        before_tier[has_class] = params.levels.grade(before_lo[has_class], cls[has_class])
    back = (before_tier >= 1) & (np.sign(np.nan_to_num(change)) == -np.sign(np.nan_to_num(before))) \
        & ~(anomaly & (np.sign(np.nan_to_num(level)) == np.sign(np.nan_to_num(change))))
    step &= ~back
    change_size_tier = change_tier
    change_tier = np.where(step, change_tier, 0)
    # a trend counts where the index grows away from the class's typical track (a place recovering
    # towards it is no work): not against an anomaly's own side, nor back from a former anomaly unless
    # it overshoots into an anomaly of the other side
    trend &= ~anomaly | (np.sign(np.nan_to_num(rate)) == np.sign(np.nan_to_num(level)))
    trend &= ~((before_tier >= 1) & (np.sign(np.nan_to_num(rate)) == -np.sign(np.nan_to_num(before)))
               & ~(anomaly & (np.sign(np.nan_to_num(level)) == np.sign(np.nan_to_num(rate)))))
    # a trend alone (no anomaly, no step: tier watch) counts where the segment reaches its class's alert
    # limit within watch_days at its rate: a segment at typical track with a trend is a year or more away
    # from any limit, and where the curve is thin (a braking end) such trends were noise (measured)
    with np.errstate(invalid="ignore", divide="ignore"):
        to_alert = (alert - np.sign(np.nan_to_num(rate)) * level) / np.abs(rate) * DAYS_PER_YEAR
    trend &= anomaly | step | (np.nan_to_num(to_alert, nan=np.inf) <= params.watch_days)
    # a rail surface changed within the trend window (a grinding, a rail renewal) runs in: its roughness
    # response settles over the runs after it, which a trend over them would read as the support developing
    # (issue 33: a trend place 87 days after a grinding) — a ground surface makes no trend place
    if surface_days is not None:
        with np.errstate(invalid="ignore"):
            trend &= ~(float(now_day) - np.asarray(surface_days, dtype=np.float64) < params.trend_window_days)
    # a trend's change so far against the segment's matched passes (the way it grows) grades it as a step's
    # does: on rough rails the rails' response at a pass is the same at every matched pass and drops out of
    # the change, not out of the level (a place developing on pads read −0.55 ± 0.61: watch by its level)
    grows = trend & (np.sign(np.nan_to_num(change)) == np.sign(np.nan_to_num(rate)))
    change_tier = np.where(step | grows, change_size_tier, 0)
    evidence = (np.where(anomaly, EVIDENCE_ANOMALY, 0) | np.where(step, EVIDENCE_STEP, 0)
                | np.where(trend, EVIDENCE_TREND, 0))
    # a step segment goes the way of its change, a trend the way of its rate, an anomaly the way of its index
    # (a trend segment weighs by its change against the history, the growth so far, where that goes its way)
    tiny = 1e-9 * np.sign(np.nan_to_num(rate))
    trend_value = np.where(np.sign(np.nan_to_num(change)) == np.sign(np.nan_to_num(rate)), change, tiny)
    value = np.where(step, change, np.where(anomaly, level, np.where(trend, trend_value, level)))
    hot = anomaly | step | trend
    # agreeing wheels: on the step where there is one, else those whose own index reaches the level limit
    own_tier = np.zeros(x.shape, np.int64)
    for w in range(n_w):
        if has_class.any():
            own_tier[w, has_class] = params.levels.grade(np.abs(np.nan_to_num(x[w, has_class])), cls[has_class])
    level_agree = (own_tier >= 1) & (np.sign(np.nan_to_num(x)) == np.sign(np.nan_to_num(level))[None, :])
    agree_any = np.where(step[None, :], agree, np.where(anomaly[None, :], level_agree, t_agree))
    wheel_mask = (agree_any * bits[:, None]).sum(axis=0).astype(np.int64)
    places = merge_places(s, value, hot, segment_m=segment_m, gap_m=params.gap_m, evidence=evidence,
                          wheels=wheel_mask)
    n = len(places)
    peak = np.zeros(n, np.int64)
    for p in range(n):
        rows = np.arange(places.first[p], places.last[p] + 1)
        rows = rows[hot[rows]]
        tier_rows = np.maximum(level_tier[rows], change_tier[rows])
        mag = places.direction[p] * np.nan_to_num(value[rows])
        peak[p] = rows[np.lexsort((-mag, -tier_rows))[0]]
    lt, ct = level_tier[peak], change_tier[peak]
    level_sd = level_sd_seg
    # the denominators carry the stated part once per wheel (shared by the wheels): the mean change's 1-σ,
    # answered (and used for the tier) where a 1-σ is stated — without one, as before
    # (the wheels of one series — an axle's two under the two-rail estimate — are one witness)
    witnesses = (series_counts(np.isfinite(wchange), series) > 0).sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        change_sd = mean_over_wheels(np.where(np.isfinite(wchange), wsd, np.nan)) / np.sqrt(np.maximum(witnesses, 1))
    change_sd = np.where(np.isfinite(level_sd), change_sd, np.nan)
    # the tier rests on the size's lower 1-sigma bound (a found place keeps at least the alert tier)
    lo_level = graded_level(np.nan_to_num(level[peak]), level_sd[peak], alert[peak])
    lo_change = np.maximum(np.abs(np.nan_to_num(change[peak])) - np.nan_to_num(change_sd[peak]), 0.0)
    lt_lo = np.zeros(n, np.int64)
    pc = cls[peak]
    with_cls = np.array([c is not None for c in pc.tolist()], dtype=bool)
    if with_cls.any():
        lt_lo[with_cls] = params.levels.grade(lo_level[with_cls], pc[with_cls])
    ct_lo = np.where(ct >= 1, params.changes.grade(lo_change), 0)
    lt = np.where(lt >= 1, np.maximum(np.minimum(lt, lt_lo), 1), lt)
    ct = np.where(ct >= 1, np.maximum(np.minimum(ct, ct_lo), 1), ct)
    tier = np.maximum(lt, ct)
    lvl_alert = alert[peak]
    sev_level = np.abs(np.nan_to_num(level[peak])) / lvl_alert
    sev_change = np.where(ct >= 1, np.abs(np.nan_to_num(change[peak])) / params.changes.alert, 0.0)
    severity_sd = np.where(sev_change > sev_level, change_sd[peak] / params.changes.alert,
                           level_sd[peak] / lvl_alert)
    return RunPlaces(
        places=places, peak_m=(s[peak] + 0.5) * segment_m, level=level[peak], change=change[peak], change_z=cz[peak], cls=cls[peak],
        level_tier=lt, change_tier=ct, tier=tier, severity=np.maximum(sev_level, sev_change),
        n_agreeing=agree_any[:, peak].sum(axis=0).astype(np.int64), rate_per_year=rate[peak], trend_z=tz[peak],
        seg=s, segment_m=float(segment_m), seg_index=level, seg_change=change, seg_change_z=cz, seg_class=cls,
        seg_evidence=evidence.astype(np.int64), level_sd=level_sd[peak], change_sd=change_sd[peak],
        severity_sd=severity_sd, seg_level_sd=level_sd,
    )
