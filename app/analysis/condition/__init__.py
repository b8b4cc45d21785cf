"""Track condition over time (pure numpy): segment statistics of a run, change detection
against a segment's history, the places (where to act) and the effect of maintenance actions.

Modules: :mod:`segments` (25 cm bins → 10 m / 100 m segment rows), :mod:`change`
(step and trend tests against the repeatability of the history), :mod:`assess` (a run's
tests per wheel and its flags per place; the in-memory history of generated runs),
:mod:`index` (the condition index ln A); where to act: :mod:`run_places`, :mod:`lifecycle`, :mod:`tiers`
and their kin (the places, served by :mod:`app.places`).
"""

from app.analysis.condition.assess import (
    TREND_SEGMENT_M,
    Flag,
    HistoryMatrix,
    HistorySource,
    RollingHistory,
    RunAssessment,
    assess_run,
)
from app.analysis.condition.change import (
    DEFAULT_CHANGE_PARAMS,
    ChangeParams,
    SpeedMatch,
    StepResult,
    TrendResult,
    WheelChange,
    combine_wheels,
    detect_changes,
    level_offsets,
    nan_median,
    pooled_spread,
    robust_spread,
    speed_matched,
    step_change,
    trend_change,
)
from app.analysis.condition.segments import (
    FINE_SEGMENT_M,
    OVERVIEW_SEGMENT_M,
    SEGMENT_LENGTHS_M,
    SegmentStats,
    segment_stats,
)

__all__ = [
    "SEGMENT_LENGTHS_M",
    "OVERVIEW_SEGMENT_M",
    "FINE_SEGMENT_M",
    "SegmentStats",
    "segment_stats",
    "ChangeParams",
    "DEFAULT_CHANGE_PARAMS",
    "SpeedMatch",
    "StepResult",
    "TrendResult",
    "WheelChange",
    "combine_wheels",
    "detect_changes",
    "level_offsets",
    "nan_median",
    "pooled_spread",
    "robust_spread",
    "speed_matched",
    "step_change",
    "trend_change",
    "TREND_SEGMENT_M",
    "Flag",
    "HistoryMatrix",
    "HistorySource",
    "RollingHistory",
    "RunAssessment",
    "assess_run",
]
