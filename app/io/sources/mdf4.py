"""ASAM MDF input (MDF4, also MDF3) read with asammdf, record range by record range."""

from __future__ import annotations

import datetime as dt
import logging
import zlib
from collections.abc import Hashable
from pathlib import Path

import numpy as np

from app.io.channel_map import RecorderChannel
from app.io.errors import RunFileError
from app.io.limits import DEFAULT_LIMITS, IngestLimits
from app.io.sources.recorder import RecorderReader

__all__ = ["Mdf4Reader"]

#: MDF4 channel types that hold time stamps (master, virtual master).
_MASTER_TYPES = (2, 3)
#: MDF4 DZ block types (asammdf ``DataBlockInfo.block_type``) of deflate-compressed data.
_DEFLATE_TYPES = (1, 2)
_PLAIN_TYPE = 0
_READ_BYTES = 1 << 20


def _group_label(group: object, index: int) -> str:
    cg = getattr(group, "channel_group", None)
    for attr in ("acq_name", "comment"):
        text = str(getattr(cg, attr, "") or "").strip()
        if text:
            return text[:200]
    return f"group {index}"


def _check_deflate(fh, address: int, compressed: int, original: int) -> None:  # noqa: ANN001
    """Inflate a DZ payload without keeping it: it must not exceed its declared size."""
    fh.seek(address)
    inflater = zlib.decompressobj()
    left, produced = compressed, 0
    while left > 0:
        data = fh.read(min(_READ_BYTES, left))
        if not data:
            break
        left -= len(data)
        while data:
            out = inflater.decompress(data, _READ_BYTES)
            produced += len(out)
            if produced > original:
                raise RunFileError(
                    "file",
                    f"an MDF data block inflates to more than its declared {original} bytes "
                    "(decompression bomb)",
                )
            data = inflater.unconsumed_tail
        if inflater.eof:
            break


class Mdf4Reader(RecorderReader):
    """An MDF file open with asammdf (metadata only; data read on demand).

    Before any sample is read, the channel count (``limits.max_recorder_channels``),
    the declared data size (records × record bytes, and the declared original
    size of the data blocks) against ``limits.max_decoded_bytes(file size)`` and
    every deflate-compressed block (inflated once, bounded, without keeping
    it) are checked; LZ4 and Zstandard blocks (MDF 4.3) are refused.

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
        logging.getLogger("asammdf").setLevel(logging.ERROR)
        try:
            self._mdf = MDF(path)
        except Exception as exc:  # noqa: BLE001 - asammdf raises many types on bad files
            raise RunFileError("file", f"cannot open MDF file: {str(exc)[:300]}") from None
        self._set_up_or_close(lambda: self._setup(path, file_bytes, limits))

    def _setup(self, path: Path, file_bytes: int, limits: IngestLimits) -> None:
        mdf = self._mdf
        channels: list[RecorderChannel] = []
        n_all = 0
        declared = 0
        blocks_original = 0
        deflated: list[tuple[int, int, int]] = []
        self._cycles: dict[int, int] = {}
        for gi, group in enumerate(mdf.groups):
            cg = group.channel_group
            cycles = int(getattr(cg, "cycles_nr", 0))
            record = int(getattr(cg, "samples_byte_nr", 0)) + int(
                getattr(cg, "invalidation_bytes_nr", 0)
            )
            self._cycles[gi] = cycles
            declared += cycles * max(record, 0)
            for info in group.get_data_blocks():
                kind = int(info.block_type)
                if kind in _DEFLATE_TYPES:
                    deflated.append((int(info.address), int(info.compressed_size), int(info.original_size)))
                elif kind != _PLAIN_TYPE:
                    raise RunFileError(
                        "file",
                        f"MDF data block compression type {kind} is not accepted (plain or deflate)",
                    )
                blocks_original += max(int(info.original_size), 0)
            label = _group_label(group, gi)
            for ci, ch in enumerate(group.channels):
                n_all += 1
                if n_all > limits.max_recorder_channels:
                    raise RunFileError(
                        "file",
                        f"more than {limits.max_recorder_channels} channels in the MDF file (limit)",
                    )
                if int(getattr(ch, "channel_type", 0)) in _MASTER_TYPES:
                    continue
                name = str(ch.name)
                unit = str(getattr(ch, "unit", "") or "")
                channels.append(RecorderChannel(name, label, gi, unit.strip(), (gi, ci)))
        limits.check_decoded(max(declared, blocks_original), file_bytes, "the MDF data")
        if deflated:
            with open(path, "rb") as fh:
                for address, compressed, original in deflated:
                    _check_deflate(fh, address, compressed, original)
        self.channels = channels
        start = getattr(mdf.header, "start_time", None)
        self.start_time = start if isinstance(start, dt.datetime) and start.tzinfo else None

    def length(self, ch: RecorderChannel) -> int:
        return self._cycles[ch.key[0]]

    def time_base(self, ch: RecorderChannel) -> Hashable:
        return ch.key[0]

    def describe_base(self, ch: RecorderChannel) -> str:
        return f"channel group {ch.group!r}, {self.length(ch)} records"

    def read(self, ch: RecorderChannel, a: int, b: int) -> np.ndarray:
        gi, ci = ch.key
        try:
            sig = self._mdf.get(
                group=gi, index=ci, record_offset=a, record_count=b - a, ignore_invalidation_bits=False
            )
        except Exception as exc:  # noqa: BLE001 - asammdf raises many types on bad data
            raise RunFileError(ch.name, f"cannot read records {a}:{b}: {str(exc)[:200]}") from None
        samples = np.asarray(sig.samples)
        if samples.ndim != 1 or samples.dtype.kind not in "iufb":
            raise RunFileError(
                ch.name, f"wrong dtype {samples.dtype} (shape {samples.shape}): channels must be numeric"
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
                ch.name, f"cannot read the time stamps of records {a}:{b}: {str(exc)[:200]}"
            ) from None
        return np.asarray(t, dtype=np.float64)

    def close(self) -> None:
        mdf = getattr(self, "_mdf", None)
        if mdf is not None:
            mdf.close()
            self._mdf = None

