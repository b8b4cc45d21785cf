"""How runs become condition rows: the change-detection thresholds and the run's valid bins,
read once from the service settings (``TRACKVKF_CONDITION_*``, ``TRACKVKF_ANALYTICS_*``)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from app.analysis.condition import DEFAULT_CHANGE_PARAMS, ChangeParams
from app.analysis.stiffness.alignment import DEFAULT_MAX_SHIFT_M
from app.analysis.units import KMH_PER_MPS, MIN_SPEED_KMH
from app.analytics.settings import EDGE_TRIM_M

__all__ = ["ConditionConfig", "DEFAULT_CONDITION_CONFIG", "FLEET_SOURCE_FORMAT"]

#: ``runs.source_format`` of generated fleet runs (:mod:`app.condition.fleet`: condition rows, no 25 cm rows)
FLEET_SOURCE_FORMAT = "fleet"


@dataclass(frozen=True)
class ConditionConfig:
    """How runs become condition rows (from the service settings, :meth:`from_settings`).

    Attributes
    ----------
    change : ChangeParams
        Change-detection thresholds and windows.
    min_speed_mps : float
        Bins slower than this are not valid, m/s.
    edge_trim_m : float
        Metres at each end of a run's wheel profile left out.
    max_shift_m : float
        Largest alignment shift searched, m.
    min_shift_confidence : float
        An alignment less clear than this is not applied (shift 0).
    """

    change: ChangeParams = field(default_factory=lambda: DEFAULT_CHANGE_PARAMS)
    min_speed_mps: float = MIN_SPEED_KMH / KMH_PER_MPS
    edge_trim_m: float = EDGE_TRIM_M
    max_shift_m: float = DEFAULT_MAX_SHIFT_M
    min_shift_confidence: float = 0.2

    @classmethod
    def from_settings(cls, settings: Any) -> ConditionConfig:
        """From :class:`app.settings.Settings` (``condition_*`` and ``analytics_*`` settings)."""
        return cls(
            change=ChangeParams(
                step_z=settings.condition_step_z,
                trend_z=settings.condition_trend_z,
                agree_z=settings.condition_agree_z,
                min_history=settings.condition_min_history,
                history_runs=settings.condition_history_runs,
                history_scan_runs=settings.condition_history_scan_runs,
                trend_window_days=settings.condition_trend_window_days,
                speed_tolerance=settings.analytics_speed_tolerance,
                level_block_m=settings.condition_level_block_m,
            ),
            min_speed_mps=settings.analytics_min_speed_kmh / KMH_PER_MPS,
            edge_trim_m=settings.analytics_edge_trim_m,
            max_shift_m=settings.condition_max_shift_m,
            min_shift_confidence=settings.condition_min_shift_confidence,
        )


DEFAULT_CONDITION_CONFIG = ConditionConfig()
