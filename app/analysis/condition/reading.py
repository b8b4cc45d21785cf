"""What a place's direction and rate say in words and units an engineer can act on.

**Direction.** The sleeper-passage amplitude ranks typical ballasted track (40–160 MN/m) by stiffness
only where the sleeper-passing frequency lies above the coupled wheel–track resonance: from
``≈ 42 m/s`` (docs/indicator.md, "Speed": monotonic at 42.5, 50 and 60 m/s; **inverted** at 27.5 m/s,
not monotonic at 35 m/s, nearly blind below 20 m/s). A place read at such a speed is *stiffer* /
*softer* than typical track; one read slower only has a *higher* / *lower amplitude than typical*.

**Rate.** A place's trend is fitted in ln units of the index a year (the severity ``direction · index``,
:mod:`~app.analysis.condition.outlook`); as a change of the amplitude it is ``expm1`` of the amplitude's
ln rate (−1 ln unit a year is −63 % a year, never "−100 %"; ln × 100 is not a per cent).
"""

from __future__ import annotations

import math

__all__ = ["STIFFNESS_RANKING_MIN_SPEED_MPS", "direction_words", "amplitude_percent_per_year"]

#: The speed from which the amplitude ranks stiffness (docs/indicator.md, "Speed"), m/s.
STIFFNESS_RANKING_MIN_SPEED_MPS = 42.0


def direction_words(direction: int, speed_mps: float | None) -> str:
    """``"stiffer"`` / ``"softer"`` (than typical track) where the place was read at or above
    :data:`STIFFNESS_RANKING_MIN_SPEED_MPS`, else ``"higher amplitude"`` / ``"lower amplitude"``.

    Parameters
    ----------
    direction : int
        +1 (index above typical) or −1 (below).
    speed_mps : float or None
        Speed of the reading, m/s (None or NaN: unknown — read as amplitude).
    """
    if direction not in (-1, 1):
        raise ValueError(f"direction: must be +1 or -1, got {direction!r}")
    fast = speed_mps is not None and math.isfinite(speed_mps) and speed_mps >= STIFFNESS_RANKING_MIN_SPEED_MPS
    if fast:
        return "stiffer" if direction > 0 else "softer"
    return "higher amplitude" if direction > 0 else "lower amplitude"


def amplitude_percent_per_year(direction: int, severity_rate_per_year: float | None) -> float | None:
    """The amplitude's change a year, per cent, of a place whose severity (``direction · index``) changes by
    ``severity_rate_per_year`` ln units a year: ``100 · expm1(direction · rate)`` (None: no rate)."""
    if severity_rate_per_year is None or not math.isfinite(severity_rate_per_year):
        return None
    try:
        return 100.0 * math.expm1(direction * severity_rate_per_year)
    except OverflowError:
        return math.inf
