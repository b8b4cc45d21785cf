"""Recorder files (MDF4, TDMS): channels on several time bases → blocks on the ABA time base.

A recorder file holds groups of channels, each group with its own time base
(24 kHz accelerations, 100 Hz odometry from the vehicle bus, 10 Hz GNSS …). A
:class:`RecorderReader` lists the channels and reads any record range of one;
:class:`RecorderSource` maps them to trackvkf channels
(:func:`app.io.channel_map.resolve_channels`) and yields blocks on the time
base of the ABA channels:

* ABA (``Z..``) and force (``Q..``) channels are never resampled: they must
  share the time base of the first mapped ABA channel, else the file is
  refused naming the channel.
* ``speed`` and ``position`` are linearly interpolated onto the ABA time
  stamps; they must cover the ABA time span (within half a second or two of
  their own sample intervals; no extrapolation beyond).
* ``lat``/``lon`` are interpolated where a fix exists; outside the GNSS
  records and across gaps longer than three GNSS sample intervals (at least
  1 s: an outage) they are NaN.

Everything is read in chunks: memory does not grow with the file.
"""

from __future__ import annotations

import abc
import datetime as dt
from collections.abc import Hashable, Iterator
from typing import Any

import numpy as np

from app.core.i18n import _
from app.io._closing import Closing
from app.io.channel_map import ChannelMap, MappedChannel, RecorderChannel, resolve_channels
from app.io.channels import ACCEL_CHANNELS, FORCE_CHANNELS, GNSS_CHANNELS, TIME_COLUMN
from app.io.errors import RunFileError
from app.io.limits import IngestLimits
from app.io.sources.base import Source, SourceInfo

__all__ = ["RecorderReader", "RecorderSource", "COVERAGE_TOLERANCE_S", "GNSS_MIN_GAP_S"]

#: A speed/position channel may start/end this much (s) inside the ABA time span.
COVERAGE_TOLERANCE_S = 0.5
#: Shortest gap between two GNSS records (s) treated as an outage (no fix between).
GNSS_MIN_GAP_S = 1.0
_SLOW_CHUNK = 65_536


class RecorderReader(Closing, abc.ABC):
    """A recorder file open for chunked reading.

    Attributes
    ----------
    channels : list of RecorderChannel
        The numeric data channels (no master/time channels).
    start_time : datetime or None
        Time zone-aware start of the recording from the file header.
    """

    channels: list[RecorderChannel]
    start_time: dt.datetime | None = None

    @abc.abstractmethod
    def length(self, ch: RecorderChannel) -> int:
        """Number of samples of a channel."""

    @abc.abstractmethod
    def time_base(self, ch: RecorderChannel) -> Hashable:
        """Key equal for channels sharing their time stamps."""

    @abc.abstractmethod
    def read(self, ch: RecorderChannel, a: int, b: int) -> np.ndarray:
        """Samples ``a:b`` in the recorder's physical unit, float64 (NaN where invalid)."""

    @abc.abstractmethod
    def times(self, ch: RecorderChannel, a: int, b: int) -> np.ndarray:
        """Time stamps of samples ``a:b``, s, float64, on one clock for the whole file."""

    def rate_hint(self, ch: RecorderChannel) -> float | None:
        """Nominal sample rate stored in the file, Hz (None if the file gives none)."""
        return None

    def describe_base(self, ch: RecorderChannel) -> str:
        """Human-readable time base of a channel (for messages)."""
        return f"group {ch.group!r}, {self.length(ch)} samples"

    @abc.abstractmethod
    def close(self) -> None:
        """Release the file."""


class _Resampled:
    """Channels of one slow time base, read chunk by chunk and interpolated."""

    def __init__(
        self, reader: RecorderReader, chans: dict[str, MappedChannel], gnss: bool
    ) -> None:
        self._reader = reader
        self._chans = chans
        self._ref = next(iter(chans.values())).channel
        self._n = reader.length(self._ref)
        self._gnss = gnss
        self._pos = 0
        self._t = np.zeros(0)
        self._v = {c: np.zeros(0) for c in chans}
        self._gap: float | None = None

    def _pull(self) -> None:
        a, b = self._pos, min(self._pos + _SLOW_CHUNK, self._n)
        t = np.asarray(self._reader.times(self._ref, a, b), dtype=np.float64)
        prev = self._t[-1:] if self._t.size else t[:0]
        dts = np.diff(np.concatenate((prev, t)))
        bad = np.flatnonzero(~(dts >= 0))
        if bad.size or not np.isfinite(t).all():
            i = int(bad[0]) if bad.size else int(np.flatnonzero(~np.isfinite(t))[0])
            raise RunFileError(
                self._ref.name,
                _("time stamps of group {group!r} are not increasing at record {record}; it cannot be resampled onto the ABA time base", group=self._ref.group, record=a + i - (1 if prev.size else 0) + 1),
            )
        if self._gap is None and t.size > 1:
            self._gap = max(3.0 * float(np.median(np.diff(t))), GNSS_MIN_GAP_S)
        self._t = np.concatenate((self._t, t))
        for canon, m in self._chans.items():
            v = np.asarray(self._reader.read(m.channel, a, b), dtype=np.float64) * m.factor
            self._v[canon] = np.concatenate((self._v[canon], v))
        self._pos = b

    def at(self, t: np.ndarray) -> dict[str, np.ndarray]:
        """Values at the (increasing) ABA time stamps ``t`` (later calls: later times)."""
        while (self._t.size == 0 or self._t[-1] < t[-1]) and self._pos < self._n:
            self._pull()
        out: dict[str, np.ndarray] = {}
        if self._t.size == 0:
            return {c: np.full(t.shape, np.nan) for c in self._chans}
        for canon in self._chans:
            out[canon] = np.interp(t, self._t, self._v[canon])
        if self._gnss:
            j = np.searchsorted(self._t, t, side="right")
            outside = (j == 0) | ((j == self._t.size) & (t > self._t[-1]))
            lo = np.clip(j - 1, 0, self._t.size - 1)
            hi = np.clip(j, 0, self._t.size - 1)
            gap = self._gap if self._gap is not None else GNSS_MIN_GAP_S
            no_fix = outside | ((self._t[hi] - self._t[lo]) > gap)
            for canon in out:
                out[canon][no_fix] = np.nan
        keep = max(int(np.searchsorted(self._t, t[-1], side="right")) - 1, 0)
        self._t = self._t[keep:]
        for canon in self._v:
            self._v[canon] = self._v[canon][keep:]
        return out


class RecorderSource(Source):
    """Blocks of trackvkf channels on the ABA time base of a recorder file.

    Parameters
    ----------
    reader : RecorderReader
        The open file (closed with the source).
    channel_map : ChannelMap or None
        Recorder channel → trackvkf channel (``None``: channels named like
        trackvkf's).
    limits : IngestLimits
        Acceptance limits (channel counts are checked by the reader).
    """

    def __init__(
        self, reader: RecorderReader, channel_map: ChannelMap | None, limits: IngestLimits
    ) -> None:
        self._reader = reader
        self._set_up_or_close(lambda: self._setup(channel_map, limits))

    def _setup(self, channel_map: ChannelMap | None, limits: IngestLimits) -> None:
        reader = self._reader
        mapped = resolve_channels(reader.channels, channel_map)
        if len(mapped) > limits.max_columns:  # pragma: no cover - at most 17 channels exist
            raise RunFileError("file", _("{n_mapped} channels exceed {max_columns}", n_mapped=len(mapped), max_columns=limits.max_columns))
        self.mapped = mapped
        ref_canon = next(c for c in ACCEL_CHANNELS if c in mapped)
        ref = mapped[ref_canon].channel
        base = reader.time_base(ref)
        self._ref = ref
        self._n = reader.length(ref)
        self._fast: dict[str, MappedChannel] = {}
        slow: dict[Hashable, dict[str, MappedChannel]] = {}
        for canon, m in mapped.items():
            if reader.time_base(m.channel) == base:
                self._fast[canon] = m
            elif canon in ACCEL_CHANNELS or canon in FORCE_CHANNELS:
                raise RunFileError(
                    m.channel.name,
                    _("({canon}) is sampled on another time base ({base}) than {name!r} ({ref_canon}: {ref_base}); acceleration and force channels are not resampled: record them on one time base", canon=canon, base=reader.describe_base(m.channel), name=ref.name, ref_canon=ref_canon, ref_base=reader.describe_base(ref)),
                )
            else:
                slow.setdefault((reader.time_base(m.channel), canon in GNSS_CHANNELS), {})[canon] = m
        if self._n > 0:
            self._check_coverage(slow)
        self._slow = slow
        meta: dict[str, Any] = {}
        if reader.start_time is not None:
            meta["start_time"] = reader.start_time.isoformat()
        self.info = SourceInfo(
            channels=list(mapped),
            has_time=True,
            n_samples=self._n,
            file_metadata=meta,
            fs_hint=reader.rate_hint(ref),
        )

    def _check_coverage(self, slow: dict[Hashable, dict[str, MappedChannel]]) -> None:
        reader, ref, n = self._reader, self._ref, self._n
        t0 = float(reader.times(ref, 0, 1)[0])
        t1 = float(reader.times(ref, n - 1, n)[0])
        for (_base, gnss), chans in slow.items():
            if gnss:
                continue
            for canon, m in chans.items():
                k = reader.length(m.channel)
                if k < 2:
                    raise RunFileError(
                        m.channel.name,
                        _("({canon}) has {k} sample(s); it cannot be resampled onto the ABA time base", canon=canon, k=k),
                    )
                c0 = float(reader.times(m.channel, 0, 1)[0])
                c1 = float(reader.times(m.channel, k - 1, k)[0])
                tol = max(COVERAGE_TOLERANCE_S, 2.0 * (c1 - c0) / (k - 1))
                if c0 > t0 + tol or c1 < t1 - tol:
                    raise RunFileError(
                        m.channel.name,
                        _("({canon}) is recorded from {c0:.3f} s to {c1:.3f} s but the ABA channels from {t0:.3f} s to {t1:.3f} s; it cannot be resampled onto the ABA time base (no extrapolation beyond {tol:.3g} s)", canon=canon, c0=c0, c1=c1, t0=t0, t1=t1, tol=tol),
                    )

    def channel_sources(self) -> dict[str, dict[str, Any]]:
        """trackvkf channel → where it came from (recorder name, group, unit, factor)."""
        return {c: m.describe() for c, m in self.mapped.items()}

    def blocks(self, size: int) -> Iterator[dict[str, np.ndarray]]:
        resamplers = [
            _Resampled(self._reader, chans, gnss) for (_base, gnss), chans in self._slow.items()
        ]
        reader = self._reader
        for a in range(0, self._n, size):
            b = min(a + size, self._n)
            t = np.asarray(reader.times(self._ref, a, b), dtype=np.float64)
            block: dict[str, np.ndarray] = {TIME_COLUMN: t}
            for canon, m in self._fast.items():
                v = np.asarray(reader.read(m.channel, a, b), dtype=np.float64)
                if v.shape != t.shape:
                    raise RunFileError(
                        m.channel.name, _("({canon}) read {shape} samples for records {a}:{b}", canon=canon, shape=v.shape, a=a, b=b)
                    )
                block[canon] = v * m.factor if m.factor != 1.0 else v
            for r in resamplers:
                block.update(r.at(t))
            yield block

    def close(self) -> None:
        self._reader.close()
