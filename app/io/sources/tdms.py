"""NI TDMS input: structurally validated, then read with npTDMS slice by slice (``TdmsFile.open``)."""

from __future__ import annotations

import datetime as dt
from collections.abc import Hashable
from pathlib import Path
from typing import Any

import numpy as np

from app.core.i18n import _
from app.io.channel_map import RecorderChannel
from app.io.errors import RunFileError
from app.io.limits import DEFAULT_LIMITS, IngestLimits
from app.io.sources.recorder import RecorderReader
from app.io.sources.tdms_segments import TdmsLayout, check_tdms

__all__ = ["TdmsReader", "TIME_CHANNEL_NAMES"]

#: Channel names (lower case) taken as the time stamps (s) of the other channels of their group.
TIME_CHANNEL_NAMES = frozenset({"time", "t", "timestamp", "zeit"})


def _seconds(value: Any) -> float | None:
    """A TDMS timestamp property (UTC) as POSIX seconds."""
    if value is None:
        return None
    try:
        return float(np.datetime64(value, "ns").astype(np.int64)) / 1e9
    except (TypeError, ValueError):
        return None


def _float_prop(props: dict[str, Any], key: str) -> float | None:
    value = props.get(key)
    if value is None:
        return None
    try:
        out = float(value)
    except (TypeError, ValueError):
        return None
    return out if np.isfinite(out) else None


class TdmsReader(RecorderReader):
    """A TDMS file open with npTDMS.

    Time base of a channel: its waveform properties (``wf_increment``,
    ``wf_start_offset``, ``wf_start_time``), else a channel named ``time``
    (``t``, ``timestamp``, ``zeit``; seconds or TDMS timestamps) in the same
    group. Before npTDMS sees the file,
    :func:`app.io.sources.tdms_segments.check_tdms` walks its segments
    (offsets, metadata, chunk sizes; DAQmx refused). Before any sample is
    read, the object count (``limits.max_recorder_channels``), the data size
    (samples × bytes per sample) against ``limits.max_decoded_bytes(file
    size)`` and every channel's length against the segments' value counts are
    checked.

    Parameters
    ----------
    path : Path
        Input file.
    limits : IngestLimits
        Acceptance limits.
    """

    def __init__(self, path: Path, limits: IngestLimits = DEFAULT_LIMITS) -> None:
        from nptdms import TdmsFile

        path = Path(path)
        file_bytes = path.stat().st_size
        with open(path, "rb") as fh:
            layout = check_tdms(fh, file_bytes, limits)
        try:
            self._tdms = TdmsFile.open(path)
        except Exception as exc:  # noqa: BLE001 - npTDMS raises many types on bad files
            raise RunFileError("file", _("cannot open TDMS file: {error}", error=str(exc)[:300])) from None
        self._set_up_or_close(lambda: self._setup(file_bytes, limits, layout))

    def _setup(self, file_bytes: int, limits: IngestLimits, layout: TdmsLayout) -> None:
        groups = self._tdms.groups()
        n_objects = sum(1 + len(g.channels()) for g in groups)
        if n_objects > limits.max_recorder_channels:
            raise RunFileError(
                "file",
                _("{n_objects} groups and channels exceed the limit of {max_recorder_channels} in a TDMS file", n_objects=n_objects, max_recorder_channels=limits.max_recorder_channels),
            )
        decoded = 0
        starts: list[float] = []
        self._chan: dict[tuple[int, str], Any] = {}
        self._time_of: dict[int, Any] = {}
        self._base: dict[tuple[int, str], Hashable] = {}
        self._wf: dict[tuple[int, str], tuple[float, float]] = {}
        channels: list[RecorderChannel] = []
        for gi, group in enumerate(groups):
            time_ch = None
            for ch in group.channels():
                if len(ch) != layout.values.get(ch.path, 0):
                    raise RunFileError(
                        "file", _("npTDMS reads {n_ch} values of {path}, the file's segments declare {declared}", n_ch=len(ch), path=ch.path, declared=layout.values.get(ch.path, 0))
                    )
                decoded += len(ch) * max(int(getattr(ch.dtype, "itemsize", 8) or 8), 1)
                if ch.name.strip().lower() in TIME_CHANNEL_NAMES and time_ch is None:
                    time_ch = ch
            if time_ch is not None:
                self._time_of[gi] = time_ch
            for ch in group.channels():
                if ch is time_ch:
                    continue
                key = (gi, ch.name)
                props = dict(ch.properties)
                inc = _float_prop(props, "wf_increment")
                start = _seconds(props.get("wf_start_time"))
                if start is not None:
                    starts.append(start)
                if inc is not None and inc > 0:
                    offset = _float_prop(props, "wf_start_offset") or 0.0
                    self._wf[key] = (inc, offset + (start or 0.0))
                    self._base[key] = ("wf", inc, offset, start, len(ch))
                elif time_ch is not None:
                    self._base[key] = ("time", gi, len(time_ch))
                else:
                    self._base[key] = ("none", gi, ch.name)
                self._chan[key] = ch
                unit = str(props.get("unit_string", "") or "").strip()
                channels.append(RecorderChannel(ch.name, group.name, gi, unit, key))
        limits.check_decoded(decoded, file_bytes, _("the TDMS data"))
        self._zero = min(starts) if starts else 0.0
        self.channels = channels
        self.start_time = (
            dt.datetime.fromtimestamp(self._zero, tz=dt.UTC) if starts else None
        )

    def length(self, ch: RecorderChannel) -> int:
        return len(self._chan[ch.key])

    def time_base(self, ch: RecorderChannel) -> Hashable:
        return self._base[ch.key]

    def describe_base(self, ch: RecorderChannel) -> str:
        wf = self._wf.get(ch.key)
        if wf is not None:
            return f"group {ch.group!r}, {1.0 / wf[0]:.6g} Hz, {self.length(ch)} samples"
        return f"group {ch.group!r}, time channel, {self.length(ch)} samples"

    def rate_hint(self, ch: RecorderChannel) -> float | None:
        wf = self._wf.get(ch.key)
        return None if wf is None else 1.0 / wf[0]

    def read(self, ch: RecorderChannel, a: int, b: int) -> np.ndarray:
        try:
            data = self._chan[ch.key].read_data(offset=a, length=b - a, scaled=True)
        except Exception as exc:  # noqa: BLE001 - npTDMS raises many types on bad data
            raise RunFileError(ch.name, _("cannot read samples {a}:{b}: {error}", a=a, b=b, error=str(exc)[:200])) from None
        data = np.asarray(data)
        if data.ndim != 1 or data.dtype.kind not in "iufb":
            raise RunFileError(ch.name, _("wrong dtype {dtype}: channels must be numeric", dtype=data.dtype))
        return data.astype(np.float64)

    def times(self, ch: RecorderChannel, a: int, b: int) -> np.ndarray:
        wf = self._wf.get(ch.key)
        if wf is not None:
            inc, t0 = wf
            return (t0 - self._zero) + np.arange(a, b, dtype=np.float64) * inc
        gi = ch.key[0]
        time_ch = self._time_of.get(gi)
        if time_ch is None:
            raise RunFileError(
                ch.name,
                _("no time base: the channel has no wf_increment and group {group!r} no time channel", group=ch.group),
            )
        if len(time_ch) != self.length(ch):
            raise RunFileError(
                ch.name,
                _("{length} samples but the time channel {name!r} of its group has {n_time}", length=self.length(ch), name=time_ch.name, n_time=len(time_ch)),
            )
        raw = np.asarray(time_ch.read_data(offset=a, length=b - a))
        if raw.dtype.kind == "M":
            return raw.astype("datetime64[ns]").astype(np.int64) / 1e9 - self._zero
        if raw.dtype.kind not in "iuf":
            raise RunFileError(time_ch.name, _("wrong dtype {dtype} of a time channel", dtype=raw.dtype))
        return raw.astype(np.float64)

    def close(self) -> None:
        tdms = getattr(self, "_tdms", None)
        if tdms is not None:
            tdms.close()
            self._tdms = None

