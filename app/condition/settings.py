"""The condition store's settings group (``TRACKVKF_CONDITION_*``): the change tests of every run's
segments (:mod:`app.condition.config`). The defaults are the numerics' own
(:data:`app.analysis.condition.DEFAULT_CHANGE_PARAMS`)."""

from __future__ import annotations

from pydantic import Field

from app.analysis.condition.change import DEFAULT_CHANGE_PARAMS
from app.analysis.stiffness.alignment import DEFAULT_MAX_SHIFT_M
from app.condition.config import ConditionConfig
from app.core.config import SettingsGroup

_CHANGE = DEFAULT_CHANGE_PARAMS

__all__ = ["ConditionSettings"]


class ConditionSettings(SettingsGroup):
    """Condition store: the step and trend tests of a run's segments and its alignment.

    Attributes
    ----------
    condition_step_z, condition_trend_z : float
        Scores (repeatability units, wheels combined) beyond which the
        condition store flags a sudden change (step) or a gradual trend.
    condition_agree_z : float
        A wheel agrees with a flag when its own score reaches this.
    condition_min_history : int
        Fewest speed-matched earlier runs a change test needs.
    condition_history_runs : int
        Most recent speed-matched earlier runs the step test compares each
        segment with.
    condition_history_scan_runs : int
        Most recent earlier runs of the line looked at to find them.
    condition_trend_window_days : float
        Days of history the trend test regresses over.
    condition_level_block_m : float
        Length of the blocks whose median change is taken as a run's level
        (calibration, temperature), m.
    condition_max_shift_m : float
        Largest alignment shift of a run onto its line's reference, m.
    condition_min_shift_confidence : float
        Alignments less clear than this are not applied.
    """

    condition_step_z: float = Field(default=_CHANGE.step_z, gt=0)
    condition_trend_z: float = Field(default=_CHANGE.trend_z, gt=0)
    condition_agree_z: float = Field(default=_CHANGE.agree_z, gt=0)
    condition_min_history: int = Field(default=_CHANGE.min_history, ge=2)
    condition_history_runs: int = Field(default=_CHANGE.history_runs, ge=2, le=1000)
    condition_history_scan_runs: int = Field(default=_CHANGE.history_scan_runs, ge=2, le=2000)
    condition_trend_window_days: float = Field(default=_CHANGE.trend_window_days, gt=0)
    condition_level_block_m: float = Field(default=_CHANGE.level_block_m, gt=0)
    condition_max_shift_m: float = Field(default=DEFAULT_MAX_SHIFT_M, gt=0)
    condition_min_shift_confidence: float = Field(default=ConditionConfig.min_shift_confidence, ge=0, le=1)
