"""The places' settings group (``TRACKVKF_PLACES_*``): where to act, how places are graded and followed
(:mod:`app.places.config` reads them into the numerics' parameters). The defaults are the numerics'
own (:class:`~app.analysis.condition.run_places.PlaceParams`,
:class:`~app.analysis.condition.lifecycle.LifecycleParams`, :mod:`~app.analysis.condition.extent_level`)."""

from __future__ import annotations

import math
from typing import Any

from pydantic import Field, field_validator

from app.analysis.condition.extent_level import DEFAULT_AROUND_M, DEFAULT_MARGIN_M
from app.analysis.condition.lifecycle import LifecycleParams
from app.analysis.condition.run_places import (
    DEFAULT_CHANGE_LIMITS,
    DEFAULT_LEVEL_LIMITS,
    PlaceParams,
)
from app.analysis.condition.section_class import DEFAULT_SECTION_LIMITS
from app.analysis.condition.segment_curves import DEFAULT_MIN_LOCATIONS
from app.analysis.condition.tiers import TIER_NAMES
from app.core.config import SettingsGroup
from app.places.config import FollowupPolicy, PlacesConfig

_PLACE = PlaceParams  # a frozen dataclass: its class attributes are the defaults
_LIFE = LifecycleParams

__all__ = ["PlacesSettings"]


class PlacesSettings(SettingsGroup):
    """Places: where to act — tiers, evidence, confirmation, sections, assets, follow-up.

    Attributes
    ----------
    places_level_limits : dict of str to [float, float, float]
        Tier limits of a place's ``|index|`` (speed-conditioned stiffness
        index, ln units) per superstructure class: alert, intervention,
        immediate action (JSON: ``{"": [...], "b91_pads": [...]}``; ``""`` is
        every other class). Alert ≈ 3.3 σ of the class's healthy index, above
        every healthy segment measured; intervention and immediate 1.5 and 2.5
        times it (EN 13848-5's ratios). docs/places.md.
    places_change_limits : [float, float, float]
        Tier limits of a place's change against its own history (ln units):
        above healthy steps between runs at different speeds (≤ 0.10), below
        a 20 % change (0.22).
    places_step_z, places_trend_z : float
        Scores (wheels combined) a place's step and trend evidence need.
    places_min_rate_per_year : float
        Rate (ln units a year) a trend needs to be evidence of a place.
    places_watch_days : float
        A trend alone makes a place (tier watch) where it reaches the alert
        limit within so many days.
    places_trend_window_days : float
        Days of history a place's trend test regresses over.
    places_min_history : int
        Earlier runs with a value the step test of a place needs.
    places_history_runs : int
        Most recent earlier runs read for a run's places (baseline, repeatability).
    places_speed_tolerance : float
        The places' matched-speed window: a run's places are tested, and a place's change read, against
        the passes within ``1 + tolerance`` of its speed either way, by the same vehicle (0.25; the
        speed-conditioned index leaves only the rails' own response's change with speed).
    places_gap_m : float
        Exceeding 10 m segments at most this far apart merge into one place, m.
    places_curve_min_locations : int
        Distinct locations (10 m of one rail) a speed needs for the line's
        reference curve there (400 m of track both rails: no false places at a
        braking end); fewer: no index at that speed.
    places_curve_runs : int
        Newest earlier runs (with the run) the line's reference curves of the
        places are fitted on at each publish (enough passes over a fleet's
        speed spread; a longer history costs seconds a run and changes the
        curves little).
    places_match_tolerance_m : float
        Widening of the extents when a run's places are matched to the known
        places of the line, m.
    places_min_confirmations : int
        Runs that must find a place before it is listed (a one-run exceedance
        is that run's noise).
    places_confirm_tier : str
        A place of this tier or higher is listed at once (``alert``,
        ``intervention`` or ``immediate``).
    places_drop_after : int
        Consecutive runs covering a place without finding it after which it
        is not active (off the work list until found again).
    places_tier_down_runs : int
        Consecutive lower runs before a place's tier falls (no alert
        ping-pong at a limit).
    places_hold_change : float
        Departure from its baseline (ln units) that still holds a known place
        a run's tests did not flag.
    places_explain_days : float
        A place appearing this many days or fewer after a maintenance action
        over it is the action's effect (kept, never listed), days.
    places_section_m : float
        Length of the sections classed A … E by the index's level and spread, m.
    places_section_limits : [float, float, float, float]
        rms limits of the section classes A/B, B/C, C/D, D/E (ln units).
    places_class_scheme : dict, optional
        The railway's own class scheme: each section class A … E mapped to one of its classes,
        with their names per language (JSON; :mod:`app.places.class_scheme`), e.g.
        ``{"name": {"en": "Condition class", "de": "Zustandsklasse"}, "classes": [{"code": "1",
        "of": ["A"], "name": {"en": "as new", "de": "neuwertig"}}, …]}``. The API, CSV, the
        Condition page and the planning report show it; checked when the service starts.
        Default: none (classes A … E).
    places_asset_buffer_m : float
        Assets (switches, bridges, …) within this distance of a place label it, m.
    places_muted_asset_types : str
        Asset types (comma separated, e.g. ``weld,insulated_joint``) whose
        places are muted on the work list (labelled, never dropped). Default none.
    places_alerts : bool
        Send the places' alerts (a new place, a tier change, a place back:
        webhook event ``condition.places``) to the webhooks; the flags'
        alerts (``condition.flags``) go whatever this says.
    places_effect_around_m, places_effect_margin_m : float
        An extent against its surroundings (an action's effect on
        ``/condition/maintenance-effect``, a trend's ``relative``): its condition
        index against the track within ``around`` m of its centre, outside the
        extent widened by ``margin`` m.
    places_followup_interval_s : float
        Pause of a worker's places follow-up loop after a round with nothing
        due, s (the publish step's own follow-up runs at once; the loop
        completes what a killed worker left and the retries).
    places_followup_grace_s : float
        The loop leaves a run published less than this long ago to the
        worker that published it (it runs the run's follow-up at once), s.
    places_max_attempts : int
        Failed places updates of a run after which it is given up (kept and
        reported; its line's later runs go on).
    places_retry_base_s, places_retry_max_s : float
        Back-off of a failed places update: base doubling per attempt, at most max, s.
    """

    places_level_limits: dict[str, list[float]] = Field(
        default_factory=lambda: {k: [v["alert"], v["intervention"], v["immediate"]]
                                 for k, v in DEFAULT_LEVEL_LIMITS.to_dict().items()})
    places_change_limits: list[float] = Field(default_factory=lambda: [DEFAULT_CHANGE_LIMITS.alert, DEFAULT_CHANGE_LIMITS.intervention,
                                                                     DEFAULT_CHANGE_LIMITS.immediate])
    places_step_z: float = Field(default=_PLACE.step_z, gt=0)
    places_trend_z: float = Field(default=_PLACE.trend_z, gt=0)
    places_min_rate_per_year: float = Field(default=_PLACE.min_rate_per_year, gt=0)
    places_watch_days: float = Field(default=_PLACE.watch_days, gt=0)
    places_trend_window_days: float = Field(default=_PLACE.trend_window_days, gt=0)
    places_min_history: int = Field(default=_PLACE.min_history, ge=2)
    places_history_runs: int = Field(default=_PLACE.history_runs, ge=2, le=1000)
    places_speed_tolerance: float = Field(default=_PLACE.speed_tolerance, gt=0, le=1)
    places_gap_m: float = Field(default=_PLACE.gap_m, ge=0)
    places_curve_min_locations: int = Field(default=DEFAULT_MIN_LOCATIONS, ge=0)
    places_curve_runs: int = Field(default=PlacesConfig.curve_runs, ge=1, le=1000)
    places_match_tolerance_m: float = Field(default=_LIFE.tolerance_m, ge=0)
    places_min_confirmations: int = Field(default=_LIFE.min_confirmations, ge=1)
    places_confirm_tier: str = TIER_NAMES[_LIFE.confirm_tier]
    places_drop_after: int = Field(default=_LIFE.drop_after, ge=1)
    places_tier_down_runs: int = Field(default=_LIFE.tier_down_runs, ge=1)
    places_hold_change: float = Field(default=_LIFE.hold_change, gt=0)
    places_explain_days: float = Field(default=_LIFE.explain_days, ge=0)
    places_section_m: float = Field(default=PlacesConfig.section_m, gt=0)
    places_section_limits: list[float] = Field(default_factory=lambda: [float(v) for v in DEFAULT_SECTION_LIMITS.limits])
    places_class_scheme: dict[str, Any] | None = None
    places_asset_buffer_m: float = Field(default=PlacesConfig.asset_buffer_m, ge=0)
    places_muted_asset_types: str = Field(default="", max_length=500)
    places_alerts: bool = PlacesConfig.alerts
    places_effect_around_m: float = Field(default=DEFAULT_AROUND_M, gt=0)
    places_effect_margin_m: float = Field(default=DEFAULT_MARGIN_M, ge=0)
    places_followup_interval_s: float = Field(default=FollowupPolicy.interval_s, gt=0)
    places_followup_grace_s: float = Field(default=FollowupPolicy.grace_s, ge=0)
    places_max_attempts: int = Field(default=FollowupPolicy.max_attempts, ge=1, le=1000)
    places_retry_base_s: float = Field(default=FollowupPolicy.retry_base_s, gt=0)
    places_retry_max_s: float = Field(default=FollowupPolicy.retry_max_s, gt=0)

    @field_validator("places_level_limits")
    @classmethod
    def _check_level_limits(cls, value: dict[str, list[float]]) -> dict[str, list[float]]:
        for name, lim in value.items():
            _check_increasing(f"places_level_limits[{name!r}]", lim, 3)
        return value

    @field_validator("places_change_limits")
    @classmethod
    def _check_change_limits(cls, value: list[float]) -> list[float]:
        return _check_increasing("places_change_limits", value, 3)

    @field_validator("places_section_limits")
    @classmethod
    def _check_section_limits(cls, value: list[float]) -> list[float]:
        return _check_increasing("places_section_limits", value, 4)

    @field_validator("places_confirm_tier")
    @classmethod
    def _check_confirm_tier(cls, value: str) -> str:
        if value not in TIER_NAMES[1:]:
            raise ValueError(f"places_confirm_tier must be alert, intervention or immediate, got {value!r}")
        return value

    @field_validator("places_muted_asset_types")
    @classmethod
    def _check_muted(cls, value: str) -> str:
        # the known types are checked where the places' settings are read (app.places.config)
        return ",".join(t.strip() for t in value.split(",") if t.strip())


def _check_increasing(name: str, value: list[float], n: int) -> list[float]:
    if len(value) != n or not all(math.isfinite(v) for v in value) \
            or not all(0 < a < b for a, b in zip(value, value[1:], strict=False)) or not value[0] > 0:
        raise ValueError(f"{name}: must be {n} finite increasing numbers > 0, got {value!r}")
    return [float(v) for v in value]
