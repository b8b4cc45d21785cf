"""How places are found, graded and followed: the ``TRACKVKF_PLACES_*`` settings read once into the
numerics' parameter objects (:class:`~app.analysis.condition.run_places.PlaceParams`,
:class:`~app.analysis.condition.lifecycle.LifecycleParams`, the tier tables). The one place that
builds them; every caller (publish step, API, benchmark) takes a :class:`PlacesConfig`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from app.analysis.condition.discontinuities import ASSET_TYPES
from app.analysis.condition.extent_level import DEFAULT_AROUND_M, DEFAULT_MARGIN_M
from app.analysis.condition.lifecycle import LifecycleParams
from app.analysis.condition.run_places import (
    DEFAULT_LEVEL_LIMITS,
    DEFAULT_PLACE_PARAMS,
    PlaceParams,
)
from app.analysis.condition.section_class import DEFAULT_SECTION_LIMITS
from app.analysis.condition.segment_curves import DEFAULT_MIN_LOCATIONS
from app.analysis.condition.tiers import TIER_NAMES, TierLimits, TierTable
from app.analytics.settings import SECTION_MARGIN_M

__all__ = ["PlacesConfig", "DEFAULT_PLACES_CONFIG", "FollowupPolicy", "tier_table", "default_places_config"]


def tier_table(levels: dict[str, list[float]]) -> TierTable:
    """A :class:`TierTable` from ``{class: [alert, intervention, immediate]}`` (``""``: every other class)."""
    rows = {str(k): TierLimits(*[float(v) for v in lim]) for k, lim in levels.items()}
    default = rows.pop("", DEFAULT_LEVEL_LIMITS.default)
    return TierTable(default, rows)


@dataclass(frozen=True)
class PlacesConfig:
    """The places' parameters (from the service settings: :meth:`from_settings`).

    Attributes
    ----------
    place : PlaceParams
        How a run's places are found and graded.
    lifecycle : LifecycleParams
        Identity, confirmation, tier changes, maintenance.
    curve_min_locations : int
        Locations a speed needs for the line's reference curve.
    curve_runs : int
        Newest history runs (with the run) the line's reference curves are fitted on.
    section_m : float
        Section length of the section classes, m.
    section_limits : tuple of float
        rms limits of the classes A/B … D/E.
    asset_buffer_m : float
        Labelling distance of assets, m.
    muted_asset_types : frozenset of str
        Asset types whose places are muted.
    effect_around_m, effect_margin_m : float
        An action's effect: surroundings and margin, m.
    alerts : bool
        Queue the places' alerts in the webhooks' outbox.
    section_margin_m : float
        Segments this close to a change of superstructure class have no class (no index), m
        (``TRACKVKF_ANALYTICS_SECTION_MARGIN_M``).
    """

    place: PlaceParams = DEFAULT_PLACE_PARAMS
    lifecycle: LifecycleParams = field(default_factory=LifecycleParams)
    curve_min_locations: int = DEFAULT_MIN_LOCATIONS
    curve_runs: int = 20
    section_m: float = 200.0
    section_limits: tuple[float, ...] = tuple(float(v) for v in DEFAULT_SECTION_LIMITS.limits)
    asset_buffer_m: float = 20.0
    muted_asset_types: frozenset[str] = frozenset()
    effect_around_m: float = DEFAULT_AROUND_M
    effect_margin_m: float = DEFAULT_MARGIN_M
    section_margin_m: float = SECTION_MARGIN_M
    alerts: bool = True

    def asset_settings(self) -> Any:
        """The asset-labelling settings as :func:`app.assets.labels.label_places` reads them."""
        from types import SimpleNamespace

        return SimpleNamespace(places_asset_buffer_m=self.asset_buffer_m,
                               places_muted_asset_types=",".join(sorted(self.muted_asset_types)))

    @property
    def levels(self) -> TierTable:
        """Level limits per class."""
        return self.place.levels

    def to_dict(self) -> dict[str, Any]:
        """The parameters that decide a place (its method's provenance)."""
        p, lc = self.place, self.lifecycle
        return {
            "levels": p.levels.to_dict(), "changes": [p.changes.alert, p.changes.intervention, p.changes.immediate],
            "step_z": p.step_z, "trend_z": p.trend_z, "min_rate_per_year": p.min_rate_per_year,
            "trend_window_days": p.trend_window_days, "min_history": p.min_history,
            "history_runs": p.history_runs, "gap_m": p.gap_m, "watch_days": p.watch_days,
            "speed_tolerance": p.speed_tolerance,
            "curve_min_locations": self.curve_min_locations, "curve_runs": self.curve_runs, "tolerance_m": lc.tolerance_m,
            "min_confirmations": lc.min_confirmations, "confirm_tier": TIER_NAMES[lc.confirm_tier],
            "drop_after": lc.drop_after, "tier_down_runs": lc.tier_down_runs, "hold_change": lc.hold_change,
            "explain_days": lc.explain_days,
        }

    @classmethod
    def from_settings(cls, settings: Any) -> PlacesConfig:
        """From :class:`app.settings.Settings` (``places_*``).

        Raises
        ------
        ValueError
            Naming the setting (an unknown muted asset type).
        """
        muted = frozenset(t for t in settings.places_muted_asset_types.split(",") if t)
        unknown = sorted(muted - set(ASSET_TYPES))
        if unknown:
            raise ValueError(f"TRACKVKF_PLACES_MUTED_ASSET_TYPES: unknown type(s) {', '.join(unknown)}; "
                             f"known: {', '.join(ASSET_TYPES)}")
        place = PlaceParams(
            tier_table(settings.places_level_limits), TierLimits(*settings.places_change_limits),
            step_z=settings.places_step_z, trend_z=settings.places_trend_z,
            min_rate_per_year=settings.places_min_rate_per_year,
            trend_window_days=settings.places_trend_window_days, min_history=settings.places_min_history,
            history_runs=max(settings.places_history_runs, settings.places_min_history),
            gap_m=settings.places_gap_m, watch_days=settings.places_watch_days,
            speed_tolerance=settings.places_speed_tolerance,
        )
        lifecycle = LifecycleParams(
            tolerance_m=settings.places_match_tolerance_m, min_confirmations=settings.places_min_confirmations,
            confirm_tier=TIER_NAMES.index(settings.places_confirm_tier), drop_after=settings.places_drop_after,
            tier_down_runs=settings.places_tier_down_runs, hold_change=settings.places_hold_change,
            explain_days=settings.places_explain_days,
        )
        return cls(place=place, lifecycle=lifecycle, curve_min_locations=settings.places_curve_min_locations,
                   curve_runs=settings.places_curve_runs,
                   section_m=settings.places_section_m, section_limits=tuple(settings.places_section_limits),
                   asset_buffer_m=settings.places_asset_buffer_m, muted_asset_types=muted,
                   effect_around_m=settings.places_effect_around_m,
                   effect_margin_m=settings.places_effect_margin_m,
                   section_margin_m=settings.analytics_section_margin_m, alerts=settings.places_alerts)


DEFAULT_PLACES_CONFIG = PlacesConfig()


def default_places_config() -> PlacesConfig:
    """The defaults (what a service with no ``TRACKVKF_PLACES_*`` setting uses)."""
    return DEFAULT_PLACES_CONFIG


@dataclass(frozen=True)
class FollowupPolicy:
    """How the places follow-up retries (from the service settings: :meth:`from_settings`).

    Attributes
    ----------
    max_attempts : int
        Failed attempts after which a run's places update is given up (kept, reported).
    retry_base_s, retry_max_s : float
        Back-off after the n-th failure: ``retry_base_s * 2**(n-1)``, at most ``retry_max_s``, s.
    interval_s : float
        Pause of the worker's ``places-followup`` loop after a round with nothing to do, s.
    grace_s : float
        The loop leaves a run marked less than this long ago to the worker that published it (which runs
        its follow-up at once), s: no two workers compute the same run's places meanwhile.
    """

    max_attempts: int = 10
    retry_base_s: float = 5.0
    retry_max_s: float = 3600.0
    interval_s: float = 10.0
    grace_s: float = 30.0

    def __post_init__(self) -> None:
        if self.max_attempts < 1:
            raise ValueError(f"max_attempts must be >= 1, got {self.max_attempts}")
        for name in ("retry_base_s", "retry_max_s", "interval_s"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        if not self.grace_s >= 0:
            raise ValueError(f"grace_s must be >= 0, got {self.grace_s}")

    @classmethod
    def from_settings(cls, settings: Any) -> FollowupPolicy:
        """The policy of the service settings (``TRACKVKF_PLACES_MAX_ATTEMPTS`` …)."""
        return cls(max_attempts=settings.places_max_attempts, retry_base_s=settings.places_retry_base_s,
                   retry_max_s=settings.places_retry_max_s, interval_s=settings.places_followup_interval_s,
                   grace_s=settings.places_followup_grace_s)

    def backoff_s(self, attempts: int) -> float:
        """Wait after the ``attempts``-th failure, s."""
        return float(min(self.retry_max_s, self.retry_base_s * 2.0 ** max(attempts - 1, 0)))
