"""Smooth speed profiles: plateaus joined by raised-cosine ramps.

A profile is a list of segments ``[t0, t0 + T)`` from speed ``v0`` to ``v1``::

    v(t) = v0 + (v1 - v0) * (1 - cos(pi * tau)) / 2          tau = (t - t0) / T
    a(t) = (v1 - v0) * pi / (2 T) * sin(pi * tau)
    s(t) = s0 + v0 (t - t0) + (v1 - v0) * T * (tau / 2 - sin(pi * tau) / (2 pi))

(a plateau has ``v0 == v1``). Speed, acceleration and distance are analytic, so
any block of samples is evaluated exactly and phases derived from the distance
stay continuous across blocks. After the last segment the speed stays constant.
The peak acceleration of a ramp is ``pi |v1 - v0| / (2 T)``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from app.analysis.units import KMH_PER_MPS

__all__ = ["SpeedProfile"]

_KMH = 1.0 / KMH_PER_MPS


@dataclass(frozen=True)
class SpeedProfile:
    """Piecewise raised-cosine speed profile (speeds in m/s, times in s).

    Attributes
    ----------
    t0, duration, v0, v1 : numpy.ndarray
        Segment start times, durations (> 0), start and end speeds.
    """

    t0: np.ndarray
    duration: np.ndarray
    v0: np.ndarray
    v1: np.ndarray

    def __post_init__(self) -> None:
        n = len(self.t0)
        if n == 0 or not all(len(a) == n for a in (self.duration, self.v0, self.v1)):
            raise ValueError("t0, duration, v0, v1 must be non-empty and of equal length")
        if np.any(self.duration <= 0) or not np.all(np.isfinite(self.duration)):
            raise ValueError("duration: segment durations must be finite and > 0 s")
        if np.any(self.v0 <= 0) or np.any(self.v1 <= 0):
            raise ValueError("v0/v1: speeds must be > 0 m/s (the simulator needs a moving train)")
        if not np.allclose(self.t0[1:], self.t0[:-1] + self.duration[:-1]) or self.t0[0] != 0:
            raise ValueError("t0: segments must start at 0 s and follow each other")

    # --- construction -------------------------------------------------------
    @classmethod
    def from_segments(cls, v_start: float, segments: Sequence[tuple[float, float]]) -> SpeedProfile:
        """Build from ``v_start`` (m/s) and ``(duration_s, v_end_mps)`` pairs."""
        if not segments:
            raise ValueError("segments must not be empty")
        dur = np.array([float(d) for d, _ in segments])
        v1 = np.array([float(v) for _, v in segments])
        v0 = np.concatenate(([float(v_start)], v1[:-1]))
        t0 = np.concatenate(([0.0], np.cumsum(dur)[:-1]))
        return cls(t0, dur, v0, v1)

    @classmethod
    def constant(cls, speed_mps: float) -> SpeedProfile:
        """Constant speed (m/s)."""
        return cls.from_segments(speed_mps, [(1.0, speed_mps)])

    @classmethod
    def random(
        cls,
        seed: int | np.random.Generator = 0,
        *,
        length_m: float | None = None,
        duration_s: float | None = None,
        v_min_kmh: float = 40.0,
        v_max_kmh: float = 200.0,
        accel_mps2: tuple[float, float] = (0.5, 0.9),
        cruise_s: tuple[float, float] = (15.0, 60.0),
    ) -> SpeedProfile:
        """A realistic random profile: cruise, accelerate, brake, a slow section, …

        Targets cycle through *high* (upper fifth of the range), *slow* (lower
        fifth) and *medium* speeds; ramps have a peak acceleration drawn from
        ``accel_mps2`` (m/s²); plateaus last ``cruise_s`` (s). Segments are
        added until the profile covers ``length_m`` (m) or ``duration_s`` (s).
        """
        if (length_m is None) == (duration_s is None):
            raise ValueError("give exactly one of length_m and duration_s")
        if not 0 < v_min_kmh < v_max_kmh:
            raise ValueError(f"need 0 < v_min_kmh < v_max_kmh, got {v_min_kmh}, {v_max_kmh}")
        rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
        lo, hi = v_min_kmh * _KMH, v_max_kmh * _KMH
        span = hi - lo
        bands = [(hi - 0.2 * span, hi), (lo, lo + 0.2 * span), (lo + 0.35 * span, lo + 0.7 * span)]
        v = rng.uniform(lo + 0.05 * span, lo + 0.25 * span)
        segs: list[tuple[float, float]] = [(rng.uniform(5.0, 20.0), v)]
        dist, time = segs[0][0] * v, segs[0][0]
        k = 0
        target_len = length_m if length_m is not None else np.inf
        target_dur = duration_s if duration_s is not None else np.inf
        while dist < target_len and time < target_dur:
            band = bands[k % 3]
            k += 1
            v_new = rng.uniform(*band)
            a_peak = rng.uniform(*accel_mps2)
            ramp = np.pi * abs(v_new - v) / (2.0 * a_peak)
            if ramp > 0:
                segs.append((ramp, v_new))
                dist += ramp * (v + v_new) / 2.0
                time += ramp
            cruise = rng.uniform(*cruise_s)
            segs.append((cruise, v_new))
            dist += cruise * v_new
            time += cruise
            v = v_new
        return cls.from_segments(segs[0][1], segs)

    # --- evaluation -----------------------------------------------------------
    @property
    def end_time(self) -> float:
        """End of the last segment, s."""
        return float(self.t0[-1] + self.duration[-1])

    def _segment_distance(self) -> np.ndarray:
        return np.concatenate(([0.0], np.cumsum(self.duration * (self.v0 + self.v1) / 2.0)))

    def evaluate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Speed (m/s), acceleration (m/s²) and distance since t = 0 (m) at times ``t`` (s)."""
        t = np.asarray(t, dtype=np.float64)
        s_start = self._segment_distance()
        i = np.clip(np.searchsorted(self.t0, t, side="right") - 1, 0, len(self.t0) - 1)
        T = self.duration[i]
        dt = t - self.t0[i]
        tau = np.clip(dt / T, 0.0, 1.0)
        v0, dv = self.v0[i], self.v1[i] - self.v0[i]
        v = v0 + dv * 0.5 * (1.0 - np.cos(np.pi * tau))
        a = np.where(dt <= T, dv * np.pi / (2.0 * T) * np.sin(np.pi * tau), 0.0)
        s = (
            s_start[i]
            + v0 * np.minimum(dt, T)
            + dv * T * (tau / 2.0 - np.sin(np.pi * tau) / (2 * np.pi))
        )
        s = s + self.v1[i] * np.maximum(dt - T, 0.0)
        return v, a, s

    def speed(self, t: np.ndarray) -> np.ndarray:
        """Speed at times ``t`` (s), m/s."""
        return self.evaluate(t)[0]

    def distance(self, t: np.ndarray) -> np.ndarray:
        """Distance since t = 0 at times ``t`` (s), m."""
        return self.evaluate(t)[2]

    def time_at_distance(self, s: np.ndarray) -> np.ndarray:
        """Times (s) at which the distance reaches ``s`` (m, >= 0); Newton on a coarse table."""
        s = np.asarray(s, dtype=np.float64)
        if s.size == 0:
            return s.copy()
        s_max = float(np.max(s))
        v_end = float(self.v1[-1])
        t_end = self.end_time
        s_end = float(self._segment_distance()[-1])
        horizon = t_end + max(0.0, (s_max - s_end) / v_end) + 1.0
        grid = np.linspace(0.0, horizon, int(min(max(horizon * 10, 100), 1e6)))
        t = np.interp(s, self.distance(grid), grid)
        for _ in range(6):
            v, _, d = self.evaluate(t)
            t = np.maximum(t - (d - s) / v, 0.0)
        return t

    def max_abs_acceleration(self) -> float:
        """Largest |acceleration| of the profile, m/s²."""
        return float(np.max(np.pi * np.abs(self.v1 - self.v0) / (2.0 * self.duration)))
