"""Track condition over time (pure numpy): segment statistics of a run, change detection
against a segment's history, the places (where to act) and the effect of maintenance actions.

Modules: :mod:`segments` (25 cm bins → 10 m / 100 m segment rows), :mod:`change`
(step and trend tests against the repeatability of the history), :mod:`assess` (a run's
tests per wheel and its flags per place; the in-memory history of generated runs),
:mod:`index` (the condition index ln A); where to act: :mod:`run_places`, :mod:`lifecycle`, :mod:`tiers`
and their kin (the places, served by :mod:`app.places`).

The names below are imported when first used (PEP 562), so that a light module of the package
(the defaults the settings groups name) loads without the numerics of the others.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from app.analysis.condition.assess import (  # noqa: F401
        TREND_SEGMENT_M,
        Flag,
        HistoryMatrix,
        HistorySource,
        RollingHistory,
        RunAssessment,
        assess_run,
    )
    from app.analysis.condition.change import (  # noqa: F401
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
    from app.analysis.condition.segments import (  # noqa: F401
        FINE_SEGMENT_M,
        OVERVIEW_SEGMENT_M,
        SEGMENT_LENGTHS_M,
        SegmentStats,
        segment_stats,
    )

#: where each public name lives (imported when first asked for)
_WHERE = {
    "TREND_SEGMENT_M": "app.analysis.condition.assess",
    "Flag": "app.analysis.condition.assess",
    "HistoryMatrix": "app.analysis.condition.assess",
    "HistorySource": "app.analysis.condition.assess",
    "RollingHistory": "app.analysis.condition.assess",
    "RunAssessment": "app.analysis.condition.assess",
    "assess_run": "app.analysis.condition.assess",
    "DEFAULT_CHANGE_PARAMS": "app.analysis.condition.change",
    "ChangeParams": "app.analysis.condition.change",
    "SpeedMatch": "app.analysis.condition.change",
    "StepResult": "app.analysis.condition.change",
    "TrendResult": "app.analysis.condition.change",
    "WheelChange": "app.analysis.condition.change",
    "combine_wheels": "app.analysis.condition.change",
    "detect_changes": "app.analysis.condition.change",
    "level_offsets": "app.analysis.condition.change",
    "nan_median": "app.analysis.condition.change",
    "pooled_spread": "app.analysis.condition.change",
    "robust_spread": "app.analysis.condition.change",
    "speed_matched": "app.analysis.condition.change",
    "step_change": "app.analysis.condition.change",
    "trend_change": "app.analysis.condition.change",
    "FINE_SEGMENT_M": "app.analysis.condition.segments",
    "OVERVIEW_SEGMENT_M": "app.analysis.condition.segments",
    "SEGMENT_LENGTHS_M": "app.analysis.condition.segments",
    "SegmentStats": "app.analysis.condition.segments",
    "segment_stats": "app.analysis.condition.segments",
}

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


def __getattr__(name: str) -> Any:
    try:
        module = _WHERE[name]
    except KeyError:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
