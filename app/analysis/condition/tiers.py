"""Severity tiers of places: alert / intervention / immediate action, per superstructure class.

As EN 13848-5 grades an isolated track-geometry defect against three limits,
each with the action it implies, a place is graded by its **severity** — a
magnitude in natural-log units of the speed-conditioned stiffness index (0.2 ≈
a 22 % higher or 18 % lower amplitude than the reference it is measured
against) — against the limits of its superstructure class:

==========  ==========================================================================
tier        action
==========  ==========================================================================
watch       (below the alert limit, listed because it grows) watch the time to limit
alert       analyse: confirm on the next runs, look at it at the next inspection, plan
intervention plan the repair before the place would reach the immediate-action limit
            (the time to limit says by when)
immediate   act now: inspect on site, restrict speed until it is understood
==========  ==========================================================================

Limits are per class because what is unusual depends on the superstructure
(a class whose track varies more from place to place needs wider limits to
keep the same rate of false alerts); the defaults, chosen by measurement, are
in the service's settings and ``docs/condition.md``.

The work list ranks places by tier (highest first), then by the time until the
next tier (soonest first; places without a significant trend towards it after
those with one), then by severity.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "TIER_NONE",
    "TIER_ALERT",
    "TIER_INTERVENTION",
    "TIER_IMMEDIATE",
    "TIER_NAMES",
    "TIER_ACTIONS",
    "TierLimits",
    "TierTable",
    "rank_places",
]

TIER_NONE, TIER_ALERT, TIER_INTERVENTION, TIER_IMMEDIATE = 0, 1, 2, 3
#: Name of each tier (index = tier).
TIER_NAMES: tuple[str, ...] = ("watch", "alert", "intervention", "immediate")
#: The action each tier implies.
TIER_ACTIONS: dict[str, str] = {
    "watch": "below the alert limit but growing: the time to limit says when it will reach it",
    "alert": "analyse: confirm on the next runs, look at it at the next inspection, plan",
    "intervention": "plan the repair before the place reaches the immediate-action limit (see time to limit)",
    "immediate": "act now: inspect on site, restrict speed until it is understood",
}


@dataclass(frozen=True)
class TierLimits:
    """The three limits of one class on the severity, natural-log units (``0 < alert < intervention < immediate``).

    Attributes
    ----------
    alert, intervention, immediate : float
        A place is in the highest tier whose limit its severity reaches.
    """

    alert: float
    intervention: float
    immediate: float

    def __post_init__(self) -> None:
        vals = (self.alert, self.intervention, self.immediate)
        if not all(isinstance(v, (int, float)) and math.isfinite(v) for v in vals):
            raise ValueError(f"alert, intervention, immediate: must be finite numbers, got {vals!r}")
        if not 0 < self.alert < self.intervention < self.immediate:
            raise ValueError(f"alert, intervention, immediate: need 0 < alert < intervention < immediate, got {vals!r}")

    @property
    def limits(self) -> np.ndarray:
        """``[alert, intervention, immediate]``."""
        return np.array([self.alert, self.intervention, self.immediate])

    def grade(self, severity: np.ndarray) -> np.ndarray:
        """Tier (0 … 3, int64) of each severity (NaN: 0)."""
        s = np.nan_to_num(np.asarray(severity, dtype=np.float64), nan=-np.inf)
        return np.searchsorted(self.limits, s, side="right").astype(np.int64)

    def next_limit(self, tier: np.ndarray) -> np.ndarray:
        """Limit of the tier above each tier (NaN for the immediate tier)."""
        t = np.asarray(tier, dtype=np.int64)
        if np.any((t < 0) | (t > TIER_IMMEDIATE)):
            raise ValueError(f"tier: must be in 0 … {TIER_IMMEDIATE}")
        return np.r_[self.limits, np.nan][t]


@dataclass(frozen=True)
class TierTable:
    """Tier limits per superstructure class, with a default for the others (and for ``""``: no section).

    Attributes
    ----------
    default : TierLimits
    classes : mapping of str to TierLimits
    """

    default: TierLimits
    classes: Mapping[str, TierLimits] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.default, TierLimits):
            raise TypeError("default: must be a TierLimits")
        for name, lim in self.classes.items():
            if not isinstance(lim, TierLimits):
                raise TypeError(f"classes[{name!r}]: must be a TierLimits")

    def limits_for(self, cls: str | None) -> TierLimits:
        """The limits of a class (the default for unknown ones)."""
        return self.classes.get(cls or "", self.default)

    def _per_class(self, classes: object, n: int) -> np.ndarray:
        c = np.asarray(classes, dtype=object)
        if c.ndim == 0:
            c = np.full(n, c.item(), dtype=object)
        if c.shape != (n,):
            raise ValueError(f"classes: must have one label per place ({n}), got shape {c.shape}")
        return c

    def grade(self, severity: np.ndarray, classes: object) -> np.ndarray:
        """Tier of each place from its severity and class."""
        s = np.asarray(severity, dtype=np.float64)
        if s.ndim != 1:
            raise ValueError("severity: must be 1-D")
        c = self._per_class(classes, s.size)
        out = np.zeros(s.size, np.int64)
        for name in set(c.tolist()):
            m = c == name
            out[m] = self.limits_for(name).grade(s[m])
        return out

    def next_limit(self, tier: np.ndarray, classes: object) -> np.ndarray:
        """Limit of the next tier of each place (NaN at the immediate tier)."""
        t = np.asarray(tier, dtype=np.int64)
        if t.ndim != 1:
            raise ValueError("tier: must be 1-D")
        c = self._per_class(classes, t.size)
        out = np.full(t.size, np.nan)
        for name in set(c.tolist()):
            m = c == name
            out[m] = self.limits_for(name).next_limit(t[m])
        return out

    def alert_limits(self, classes: object) -> np.ndarray:
        """The alert limit of each segment's class (1-D labels; inf where a segment has none: ``None``)."""
        c = np.asarray(classes, dtype=object)
        if c.ndim != 1:
            raise ValueError("classes: must be 1-D")
        return np.array([self.limits_for(x).alert if x is not None else np.inf for x in c.tolist()],
                        dtype=np.float64)

    def to_dict(self) -> dict[str, dict[str, float]]:
        """``{"": default, class: limits, …}`` as plain numbers (for answers and provenance)."""
        out = {"": {"alert": self.default.alert, "intervention": self.default.intervention,
                    "immediate": self.default.immediate}}
        for name, lim in self.classes.items():
            out[name] = {"alert": lim.alert, "intervention": lim.intervention, "immediate": lim.immediate}
        return out


def rank_places(tier: np.ndarray, days_to_next: np.ndarray, severity: np.ndarray) -> np.ndarray:
    """Order of the work list: tier descending, then days to the next tier ascending (NaN last), then
    severity descending.

    Parameters
    ----------
    tier : numpy.ndarray
        int tiers.
    days_to_next : numpy.ndarray
        Days until the next tier's limit (NaN: no significant trend towards it, or top tier).
    severity : numpy.ndarray
        Severity (ln units).

    Returns
    -------
    numpy.ndarray
        int64 indices into the inputs, first place first.
    """
    t = np.asarray(tier, dtype=np.int64)
    d = np.asarray(days_to_next, dtype=np.float64)
    s = np.asarray(severity, dtype=np.float64)
    if not (t.ndim == 1 and d.shape == t.shape and s.shape == t.shape):
        raise ValueError("tier, days_to_next, severity: must be 1-D of equal length")
    d_key = np.where(np.isfinite(d), d, np.inf)
    s_key = -np.nan_to_num(s, nan=-np.inf)
    return np.lexsort((s_key, d_key, -t)).astype(np.int64)
