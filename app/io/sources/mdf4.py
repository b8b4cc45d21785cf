"""ASAM MDF 4 input: structurally validated, then read with asammdf record range by record range."""

from __future__ import annotations

import datetime as dt
import logging
from collections.abc import Hashable
from pathlib import Path

import numpy as np

from app.core.i18n import _
from app.io.channel_map import RecorderChannel
from app.io.errors import RunFileError
from app.io.limits import DEFAULT_LIMITS, IngestLimits
from app.io.sources.mdf4_blocks import ChannelLayout, Mdf4Layout, check_mdf4
from app.io.sources.recorder import RecorderReader

__all__ = ["Mdf4Reader"]

#: MDF4 channel types that hold time stamps (master, virtual master).
_MASTER_TYPES = (2, 3)
#: Channel types read as samples: fixed-length values and masters (not VLSD, MLSD, virtual).
_READABLE_TYPES = (0, 2, 4)
#: MDF4 data types read: unsigned, signed integers and IEEE floats (Intel and Motorola order).
_NUMERIC_DATA_TYPES = (0, 1, 2, 3, 4, 5)
#: Conversions applied: identity, linear, rational, value tables (not formulae or texts).
_NUMERIC_CONVERSIONS = (None, 0, 1, 2, 4, 5, 6)


def _group_label(group: object, index: int) -> str:
    cg = getattr(group, "channel_group", None)
    for attr in ("acq_name", "comment"):
        text = str(getattr(cg, attr, "") or "").strip()
        if text:
            return text[:200]
    return f"group {index}"


class Mdf4Reader(RecorderReader):
    """An MDF4 file, structurally validated, then open with asammdf (data read on demand).

    :func:`app.io.sources.mdf4_blocks.check_mdf4` walks the file's blocks
    before asammdf sees it: links, lengths, channel layouts, data sizes (every
    DZ block inflated once, bounded, nothing kept), the channel count
    (``limits.max_recorder_channels``) and the decoded size
    (``limits.max_decoded_bytes(file size)``). asammdf then opens it without
    bus-logging decoding; what asammdf reports must agree with the walk.
    Channels are read only when they are numeric fixed-length values with a
    numeric conversion.

    Parameters
    ----------
    path : Path
        Input file.
    limits : IngestLimits
        Acceptance limits.
    """

    def __init__(self, path: Path, limits: IngestLimits = DEFAULT_LIMITS) -> None:
        from asammdf import MDF

        path = Path(path)
        file_bytes = path.stat().st_size
        with open(path, "rb") as fh:
            layout = check_mdf4(fh, file_bytes, limits)
        logging.getLogger("asammdf").setLevel(logging.ERROR)
        try:
            self._mdf = MDF(path, process_bus_logging=False)
        except Exception as exc:  # noqa: BLE001 - asammdf raises many types on bad files
            raise RunFileError("file", _("cannot open MDF file: {error}", error=str(exc)[:300])) from None
        self._set_up_or_close(lambda: self._setup(layout))

    def _setup(self, layout: Mdf4Layout) -> None:
        mdf = self._mdf
        if len(mdf.groups) != len(layout.groups):
            raise RunFileError(
                "file", _("asammdf reads {n_groups} channel groups, the file's blocks hold {n_blocks}", n_groups=len(mdf.groups), n_blocks=len(layout.groups))
            )
        channels: list[RecorderChannel] = []
        self._cycles: dict[int, int] = {}
        self._layout: dict[tuple[int, int], ChannelLayout | None] = {}
        for gi, group in enumerate(mdf.groups):
            cycles = int(getattr(group.channel_group, "cycles_nr", 0))
            if cycles != layout.groups[gi][0]:
                raise RunFileError(
                    "file", _("asammdf reads {cycles} records in channel group {gi}, its CG block declares {declared}", cycles=cycles, gi=gi, declared=layout.groups[gi][0])
                )
            self._cycles[gi] = cycles
            label = _group_label(group, gi)
            for ci, ch in enumerate(group.channels):
                self._layout[(gi, ci)] = layout.channels.get(int(getattr(ch, "address", -1)))
                if int(getattr(ch, "channel_type", 0)) in _MASTER_TYPES:
                    continue
                name = str(ch.name)
                unit = str(getattr(ch, "unit", "") or "")
                channels.append(RecorderChannel(name, label, gi, unit.strip(), (gi, ci)))
        self.channels = channels
        start = getattr(mdf.header, "start_time", None)
        self.start_time = start if isinstance(start, dt.datetime) and start.tzinfo else None

    def _readable(self, ch: RecorderChannel) -> None:
        """Refuse, before asammdf reads it, a channel that is not numeric fixed-length data."""
        info = self._layout.get(ch.key)
        if info is None:
            raise RunFileError(ch.name, _("asammdf lists a channel the file's CN blocks do not hold"))
        if (
            info.channel_type not in _READABLE_TYPES
            or info.data_type not in _NUMERIC_DATA_TYPES
            or info.composed
        ):
            raise RunFileError(
                ch.name, _("is not a numeric fixed-length channel (cn_type {channel_type}, cn_data_type {data_type}, composed); channels must be numeric", channel_type=info.channel_type, data_type=info.data_type)
                if info.composed else
                _("is not a numeric fixed-length channel (cn_type {channel_type}, cn_data_type {data_type}); channels must be numeric", channel_type=info.channel_type, data_type=info.data_type)
            )
        if info.conversion_type not in _NUMERIC_CONVERSIONS:
            raise RunFileError(
                ch.name, _("has a conversion of cc_type {conversion_type} (formula or text); only identity, linear, rational and value-table conversions are applied", conversion_type=info.conversion_type)
            )

    def length(self, ch: RecorderChannel) -> int:
        return self._cycles[ch.key[0]]

    def time_base(self, ch: RecorderChannel) -> Hashable:
        return ch.key[0]

    def describe_base(self, ch: RecorderChannel) -> str:
        return f"channel group {ch.group!r}, {self.length(ch)} records"

    def read(self, ch: RecorderChannel, a: int, b: int) -> np.ndarray:
        gi, ci = ch.key
        self._readable(ch)
        try:
            sig = self._mdf.get(
                group=gi, index=ci, record_offset=a, record_count=b - a, ignore_invalidation_bits=False
            )
        except Exception as exc:  # noqa: BLE001 - asammdf raises many types on bad data
            raise RunFileError(ch.name, _("cannot read records {a}:{b}: {error}", a=a, b=b, error=str(exc)[:200])) from None
        samples = np.asarray(sig.samples)
        if samples.ndim != 1 or samples.dtype.kind not in "iufb":
            raise RunFileError(
                ch.name, _("wrong dtype {dtype} (shape {shape}): channels must be numeric", dtype=samples.dtype, shape=samples.shape)
            )
        out = samples.astype(np.float64)
        invalid = getattr(sig, "invalidation_bits", None)
        if invalid is not None:
            mask = np.asarray(invalid, dtype=bool)
            if mask.shape == out.shape and mask.any():
                out[mask] = np.nan
        return out

    def times(self, ch: RecorderChannel, a: int, b: int) -> np.ndarray:
        try:
            t = self._mdf.get_master(ch.key[0], record_offset=a, record_count=b - a)
        except Exception as exc:  # noqa: BLE001 - asammdf raises many types on bad data
            raise RunFileError(
                ch.name, _("cannot read the time stamps of records {a}:{b}: {error}", a=a, b=b, error=str(exc)[:200])
            ) from None
        return np.asarray(t, dtype=np.float64)

    def close(self) -> None:
        mdf = getattr(self, "_mdf", None)
        if mdf is not None:
            mdf.close()
            self._mdf = None

