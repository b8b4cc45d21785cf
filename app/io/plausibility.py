"""What an input run must be to be ingested: the channels it needs, one sample rate that the
metadata, the file and its time column agree on, a duration long enough to process, values that
fit their storage type and a plausible range, a position that moves one way, a speed in m/s, a
uniform time grid, and not too many gaps. Every refusal is a :class:`~app.io.errors.RunFileError`
naming the channel or field and the sample at fault."""

from __future__ import annotations

import math

import numpy as np

from app.core.i18n import _
from app.io.channels import (
    ACCEL_CHANNELS,
    ALL_CHANNELS,
    FORCE_CHANNELS,
    TIME_COLUMN,
    UNITS,
    storage_dtype,
)
from app.io.errors import RunFileError
from app.io.limits import IngestLimits
from app.io.metadata import RunMetadata
from app.io.sources import Source

__all__ = ["check_channels", "resolve_sample_rate", "check_sample_rate", "check_duration", "too_many_nan",
           "SampleChecks"]


def check_channels(channels: list[str]) -> list[str]:
    """The stored channels in canonical order: an acceleration and speed or position are required."""
    if not any(c in channels for c in ACCEL_CHANNELS):
        raise RunFileError(
            "Z11", _("missing channel: at least one of {items} is required", items=', '.join(ACCEL_CHANNELS))
        )
    if "speed" not in channels and "position" not in channels:
        raise RunFileError("speed", _("missing channel: speed or position is required"))
    return [c for c in ALL_CHANNELS if c in channels]


def resolve_sample_rate(
    meta: RunMetadata, source: Source, first: dict[str, np.ndarray]
) -> tuple[float, bool]:
    """The run's sample rate and whether it comes from the time column: ``(fs, from_time)``.

    The metadata's ``sample_rate_hz``, the file's own and the time column's must agree.
    """
    fs = meta.sample_rate_hz
    hint = source.info.fs_hint
    if fs is not None and hint is not None and not math.isclose(fs, hint, rel_tol=1e-9):
        raise RunFileError(
            "sample_rate_hz", _("metadata gives {fs:g} Hz but the file attribute says {hint:g} Hz", fs=fs, hint=hint)
        )
    fs = fs if fs is not None else hint
    time_fs = _fs_from_time(first.get(TIME_COLUMN))
    if fs is None:
        if time_fs is None:
            raise RunFileError(
                "sample_rate_hz",
                _("sample rate missing: give sample_rate_hz in the metadata (or a time column)"),
            )
        return time_fs, True
    if time_fs is not None and abs(time_fs - fs) > 1e-3 * fs:
        raise RunFileError(
            "sample_rate_hz",
            _("sample rate {fs:g} Hz disagrees with the time column ({time_fs:.6g} Hz)", fs=fs, time_fs=time_fs),
        )
    return float(fs), False


def _fs_from_time(t: np.ndarray | None) -> float | None:
    if t is None:
        return None
    idx = np.flatnonzero(np.isfinite(t))
    if idx.size < 2 or t[idx[-1]] <= t[idx[0]]:
        raise RunFileError("time", _("time column must increase (cannot derive the sample rate)"))
    fs = float((idx[-1] - idx[0]) / (t[idx[-1]] - t[idx[0]]))
    rounded = round(fs)
    return float(rounded) if abs(fs - rounded) <= 1e-6 * fs else fs


def check_sample_rate(fs: float, limits: IngestLimits) -> None:
    """The sample rate lies within ``min_sample_rate_hz`` … ``max_sample_rate_hz``."""
    if not (limits.min_sample_rate_hz <= fs <= limits.max_sample_rate_hz):
        raise RunFileError(
            "sample_rate_hz",
            _("invalid sample rate {fs:g} Hz; accepted {min_sample_rate_hz:g} … {max_sample_rate_hz:g} Hz", fs=fs, min_sample_rate_hz=limits.min_sample_rate_hz, max_sample_rate_hz=limits.max_sample_rate_hz),
        )


def check_duration(n: int, fs: float, limits: IngestLimits) -> None:
    """A run of ``n`` samples at ``fs`` lasts at least ``min_duration_s``."""
    if n < limits.min_duration_s * fs:
        raise RunFileError(
            "file",
            _("the run lasts {seconds:.3g} s ({n} samples at {fs:g} Hz); at least {min_duration_s:g} s are needed to process it", seconds=n / fs, n=n, fs=fs, min_duration_s=limits.min_duration_s),
        )


def too_many_nan(channel: str, count: int, n: int, limits: IngestLimits) -> None:
    """Refuse a channel with more NaN than ``max_nan_fraction`` of its samples."""
    raise RunFileError(
        channel,
        _("too many NaN: {count} of {n} samples ({percent:.3g} %) exceed the limit of {limit:.3g} %", count=count, n=n, percent=100.0 * count / n, limit=100.0 * limits.max_nan_fraction),
    )


_FLOAT32_MAX = float(np.finfo(np.float32).max)


class SampleChecks:
    """Per-block checks of the samples: values that fit their storage and a plausible range, a
    monotonic position, a plausible speed, a uniform time grid."""

    def __init__(
        self, meta: RunMetadata, fs: float, limits: IngestLimits, from_time: bool, direction: int
    ) -> None:
        self.meta, self.fs, self.limits, self.from_time = meta, fs, limits, from_time
        self.last_pos: float | None = None
        self.first_pos: float | None = None
        #: +1: position must not decrease (relative); 0: the first change decides (line km)
        self.direction = direction
        self.t0: tuple[int, float] | None = None

    def physical(self, name: str, x: np.ndarray) -> np.ndarray:
        gain, offset = self.meta.gain_offset(name)
        if (gain, offset) == (1.0, 0.0):
            return x
        with np.errstate(over="ignore", invalid="ignore"):
            return x * gain + offset

    def _bound(self, name: str) -> float | None:
        if name in ACCEL_CHANNELS:
            return self.limits.max_abs_accel_mps2
        if name in FORCE_CHANNELS:
            return self.limits.max_abs_force_kn
        if name == "position":
            return self.limits.max_abs_position_m
        return None  # speed: checked by speed()

    def magnitude(self, name: str, offset: int, raw: np.ndarray) -> None:
        """Raw values must fit their storage type and calibrated values a plausible range."""
        if storage_dtype(name) == np.float32:
            big = np.flatnonzero(np.abs(raw) > _FLOAT32_MAX)
            if big.size:
                i = int(big[0])
                raise RunFileError(
                    name,
                    _("value {raw:.6g} at sample {sample} does not fit the float32 storage of the channel (|x| <= {limit:.3g})", raw=raw[i], sample=offset + i, limit=_FLOAT32_MAX),
                )
        bound = self._bound(name)
        if bound is None:
            return
        with np.errstate(invalid="ignore"):
            bad = np.flatnonzero(~(np.abs(self.physical(name, raw)) <= bound) & ~np.isnan(raw))
        if not bad.size:
            return
        i = int(bad[0])
        value = float(self.physical(name, raw[i : i + 1])[0])
        gain, off = self.meta.gain_offset(name)
        unit = UNITS[name]
        if (gain, off) != (1.0, 0.0) and abs(raw[i]) <= bound:
            raise RunFileError(
                f"calibration.{name}",
                _("gain {gain:.6g} and offset {off:.6g} make sample {sample} ({raw:.6g}) {value:.6g} {unit}, beyond ±{bound:g} {unit}; check the calibration", gain=gain, off=off, sample=offset + i, raw=raw[i], value=value, unit=unit, bound=bound),
            )
        raise RunFileError(
            name, _("value {value:.6g} {unit} at sample {sample} is beyond ±{bound:g} {unit}", value=value, unit=unit, sample=offset + i, bound=bound)
        )

    def position(self, offset: int, raw: np.ndarray) -> None:
        p = self.physical("position", raw)
        idx = np.flatnonzero(~np.isnan(p))
        if idx.size == 0:
            return
        v = p[idx]
        if self.first_pos is None:
            self.first_pos = float(v[0])
        if self.direction == 0:
            moved = np.flatnonzero(v != self.first_pos)
            if moved.size:
                self.direction = 1 if v[moved[0]] > self.first_pos else -1
        d = self.direction or 1
        prev = np.concatenate(([v[0] if self.last_pos is None else self.last_pos], v[:-1]))
        bad = np.flatnonzero(d * v < d * prev)
        if bad.size:
            i = int(bad[0])
            if self.direction == 1 and self.meta.position_kind != "line_km":
                rule = _(
                    "position must be non-decreasing along the run (the km direction is given "
                    "by metadata km_increasing; an absolute line km is position_kind line_km)"
                )
            else:
                rule = _("a line km channel must change in one direction along the run")
            raise RunFileError(
                "position",
                (_("non-monotonic position: decreases from {prev:.6g} m to {v:.6g} m at sample {sample}; {rule}", prev=prev[i], v=v[i], sample=offset + int(idx[i]), rule=rule)
                 if d > 0 else
                 _("non-monotonic position: increases from {prev:.6g} m to {v:.6g} m at sample {sample}; {rule}", prev=prev[i], v=v[i], sample=offset + int(idx[i]), rule=rule)),
            )
        self.last_pos = float(v[-1])

    def speed(self, offset: int, raw: np.ndarray) -> None:
        v = self.physical("speed", raw)
        with np.errstate(invalid="ignore"):
            hi = np.flatnonzero(v > self.limits.max_speed_mps)
            lo = np.flatnonzero(v < -self.limits.speed_tolerance_mps)
        if hi.size:
            i = int(hi[0])
            raise RunFileError(
                "speed",
                _("speed {v:.6g} m/s at sample {sample} exceeds {max_speed_mps:g} m/s; speed must be given in m/s (not km/h)", v=v[i], sample=offset + i, max_speed_mps=self.limits.max_speed_mps),
            )
        if lo.size:
            i = int(lo[0])
            raise RunFileError(
                "speed", _("negative speed {v:.6g} m/s at sample {sample}; speed must be >= 0", v=v[i], sample=offset + i)
            )

    def time(self, offset: int, t: np.ndarray) -> None:
        idx = np.flatnonzero(np.isfinite(t))
        if idx.size == 0:
            return
        if self.t0 is None:
            self.t0 = (offset + int(idx[0]), float(t[idx[0]]))
        k0, t0 = self.t0
        expected = t0 + (offset + idx - k0) / self.fs
        err = np.abs(t[idx] - expected)
        bad = np.flatnonzero(err > 0.5 / self.fs)
        if bad.size:
            i = int(idx[bad[0]])
            what = _("derived from the time column") if self.from_time else _("as given")
            raise RunFileError(
                "time",
                _("time {t:.9g} s at sample {sample} is off the uniform grid of the sample rate {fs:g} Hz ({what}); one sample rate per file is required", t=t[i], sample=offset + i, fs=self.fs, what=what),
            )
