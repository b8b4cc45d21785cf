"""HDF5 input: one 1-D numeric dataset per channel at the file root."""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from app.core.i18n import _
from app.io.canonical import check_hdf5_tree
from app.io.channels import TIME_COLUMN, UNIT_SYNONYMS, UNITS
from app.io.errors import RunFileError
from app.io.limits import DEFAULT_LIMITS, IngestLimits
from app.io.metadata import load_metadata_json
from app.io.sources.base import Source, SourceInfo, map_channel_names

__all__ = ["Hdf5Source", "ALLOWED_FILTERS"]

#: HDF5 filters a dataset may use: built into the HDF5 library or h5py (LZF).
#: Anything else would load a plugin library from HDF5_PLUGIN_PATH.
ALLOWED_FILTERS: dict[int, str] = {
    1: "deflate (gzip)",
    2: "shuffle",
    3: "fletcher32",
    4: "szip",
    5: "nbit",
    6: "scaleoffset",
    32000: "lzf",
}


def _check_filters(name: str, ds: h5py.Dataset) -> None:
    plist = ds.id.get_create_plist()
    for i in range(plist.get_nfilters()):
        filter_id = int(plist.get_filter(i)[0])
        if filter_id not in ALLOWED_FILTERS:
            raise RunFileError(
                name,
                _("HDF5 filter {filter_id} is not allowed (allowed: {items})", filter_id=filter_id, items=', '.join(ALLOWED_FILTERS.values())),
            )


#: What h5py raises on a file whose metadata libhdf5 cannot decode.
_H5_ERRORS = (OSError, RuntimeError, KeyError, ValueError, TypeError, IndexError, OverflowError)


def _check_extents(name: str, ds: h5py.Dataset, file_bytes: int) -> None:
    """The dataset's stored bytes (contiguous block or every chunk) lie inside the file."""
    dsid = ds.id
    if ds.chunks is None:
        offset = dsid.get_offset()
        size = int(dsid.get_storage_size())
        if offset is not None and int(offset) + size > file_bytes:
            raise RunFileError(name, _("its data (byte {offset}, {size} bytes) reach beyond the end of the {file_bytes}-byte file", offset=int(offset), size=size, file_bytes=file_bytes))
        return

    def visit(info: Any) -> None:
        end = int(info.byte_offset) + int(info.size)
        if end > file_bytes:
            raise RunFileError(name, _("a chunk at byte {byte_offset} ({size} bytes) reaches beyond the end of the {file_bytes}-byte file", byte_offset=int(info.byte_offset), size=int(info.size), file_bytes=file_bytes))

    dsid.chunk_iter(visit)


def _attr_text(value: Any) -> str:
    if isinstance(value, bytes):
        return value.decode("utf-8", errors="replace")
    if isinstance(value, np.ndarray) and value.shape == ():
        return _attr_text(value[()])
    return str(value)


def _attr_float(value: Any, field: str) -> float:
    try:
        out = float(np.asarray(value).reshape(()))
    except (TypeError, ValueError):
        raise RunFileError(field, _("attribute must be a number, got {value!r}", value=value)) from None
    if not math.isfinite(out):
        raise RunFileError(field, _("attribute must be finite, got {out}", out=out))
    return out


class Hdf5Source(Source):
    """Read an HDF5 run file.

    The tree is checked before any data are read: more root members than
    ``limits.max_columns``, external links, soft links that do not resolve to a
    dataset inside the file, groups, virtual datasets, datasets with external
    storage and filters other than :data:`ALLOWED_FILTERS` are rejected, and so
    is a file whose datasets would decode to more than
    ``limits.max_decoded_bytes(file size)`` (compression or sparse-allocation
    bomb).

    Parameters
    ----------
    path : Path
        Input file.
    limits : IngestLimits
        Root member count (``max_columns``) and decoded size
        (``max_decoded_bytes``) limits.
    """

    def __init__(self, path: Path, limits: IngestLimits = DEFAULT_LIMITS) -> None:
        self._limits = limits
        self._file_bytes = Path(path).stat().st_size
        self._outside_bytes = self._file_bytes
        try:
            self._h5 = h5py.File(path, "r")
        except _H5_ERRORS as exc:
            raise RunFileError("file", _("cannot open HDF5 file: {error}", error=str(exc)[:300])) from None
        self._set_up_or_close(self._checked_setup)

    def _checked_setup(self) -> None:
        """:meth:`_setup`, with libhdf5's errors on corrupt metadata answered as the file's fault."""
        try:
            self._setup()
        except RunFileError:
            raise
        except _H5_ERRORS as exc:
            raise RunFileError("file", _("corrupt HDF5 structure: {kind}: {error}", kind=type(exc).__name__, error=str(exc)[:300])) from None

    def _setup(self) -> None:
        n_members = len(self._h5)
        if n_members > self._limits.max_columns:
            raise RunFileError(
                "file",
                _("{n_members} root members exceed the limit of {max_columns} (one dataset per channel)", n_members=n_members, max_columns=self._limits.max_columns),
            )
        members = check_hdf5_tree(self._h5)
        # what the file holds besides the datasets' data bounds its variable-length attributes
        self._outside_bytes = self._file_bytes - sum(int(d.id.get_storage_size()) for d in members.values())
        names = map_channel_names(members)
        self._ds: dict[str, h5py.Dataset] = {}
        calibration: dict[str, dict[str, float]] = {}
        for orig, canon in names.items():
            ds = members[orig]
            if ds.ndim != 1:
                raise RunFileError(orig, _("must be a 1-D dataset, got shape {shape}", shape=ds.shape))
            if ds.dtype.kind not in "iuf":
                raise RunFileError(orig, _("wrong dtype {dtype}: channels must be numeric", dtype=ds.dtype))
            _check_filters(orig, ds)
            _check_extents(orig, ds, self._file_bytes)
            units = self._attr(ds, "units", f"{orig}.units")
            if units is not None:
                text = _attr_text(units).strip()
                want = UNITS[canon]
                if text.lower() not in {u.lower() for u in UNIT_SYNONYMS[want]}:
                    raise RunFileError(orig, _("units {text!r} not accepted; expected {want}", text=text, want=want))
            if canon != TIME_COLUMN and ("gain" in ds.attrs or "offset" in ds.attrs):
                gain = _attr_float(self._attr(ds, "gain", f"{orig}.gain", 1.0), f"{orig}.gain")
                offset = _attr_float(self._attr(ds, "offset", f"{orig}.offset", 0.0), f"{orig}.offset")
                if (gain, offset) != (1.0, 0.0):
                    calibration[canon] = {"gain": gain, "offset": offset}
            self._ds[canon] = ds
        lengths = {c: d.shape[0] for c, d in self._ds.items()}
        if len(set(lengths.values())) > 1:
            ref = max(lengths, key=lambda c: list(lengths.values()).count(lengths[c]))
            bad = next(c for c in lengths if lengths[c] != lengths[ref])
            listing = ", ".join(f"{c}={n}" for c, n in lengths.items())
            raise RunFileError(bad, _("channels of unequal length ({listing})", listing=listing))
        decoded = sum(int(d.shape[0]) * d.dtype.itemsize for d in self._ds.values())
        allowed = self._limits.max_decoded_bytes(self._file_bytes)
        if decoded > allowed:
            raise RunFileError(
                "file",
                _("the datasets decode to {decoded} bytes, more than {allowed} bytes allowed for a {file_bytes}-byte file (compression bomb or unallocated storage)", decoded=decoded, allowed=allowed, file_bytes=self._file_bytes),
            )
        attrs = self._h5.attrs
        file_meta: dict[str, Any] = {}
        raw_meta = self._attr(self._h5, "metadata", "metadata", max_bytes=self._limits.max_metadata_bytes)
        if raw_meta is not None:
            file_meta = load_metadata_json(_attr_text(raw_meta), field="metadata")
        fs_hint = None
        for key in ("sample_rate_hz", "sample_rate"):
            if key in attrs:
                fs_hint = _attr_float(self._attr(self._h5, key, "sample_rate_hz"), "sample_rate_hz")
                break
        self.info = SourceInfo(
            channels=[c for c in self._ds if c != TIME_COLUMN],
            has_time=TIME_COLUMN in self._ds,
            n_samples=next(iter(lengths.values())) if lengths else 0,
            file_metadata=file_meta,
            fs_hint=fs_hint,
            calibration=calibration,
        )

    def _attr(
        self, obj: h5py.HLObject, name: str, field: str, default: Any = None, *, max_bytes: int | None = None
    ) -> Any:
        """Attribute ``name`` of ``obj`` (``default`` if absent), its size checked before it is read.

        A fixed-size attribute larger than ``max_bytes`` (default
        ``limits.max_attribute_bytes``) is refused from its stored size. A
        variable-length one (a string) is read only when everything the file
        holds outside its datasets' data (the attributes, among others) is at
        most ``limits.max_attribute_read_bytes``: that bounds what reading it costs.
        """
        if name not in obj.attrs:
            return default
        limit = self._limits.max_attribute_bytes if max_bytes is None else max_bytes
        aid = obj.attrs.get_id(name)
        if h5py.check_vlen_dtype(aid.dtype) is not None or aid.dtype.kind == "O":
            if self._outside_bytes > self._limits.max_attribute_read_bytes:
                raise RunFileError(
                    field,
                    _("variable-length attribute in a file with {outside_bytes} bytes outside its datasets (attributes or unused space); at most {max_attribute_read_bytes} bytes are read (repack the file, e.g. with h5repack)", outside_bytes=self._outside_bytes, max_attribute_read_bytes=self._limits.max_attribute_read_bytes),
                )
        elif int(aid.get_storage_size()) > limit:
            raise RunFileError(
                field, _("attribute of {size} bytes exceeds {limit} bytes", size=int(aid.get_storage_size()), limit=limit)
            )
        value = obj.attrs[name]
        if isinstance(value, str | bytes) and len(value) > limit:
            raise RunFileError(field, _("attribute of {n} characters exceeds {limit} bytes", n=len(value), limit=limit))
        return value

    def blocks(self, size: int) -> Iterator[dict[str, np.ndarray]]:
        n = self.info.n_samples or 0
        for a in range(0, n, size):
            b = min(a + size, n)
            block: dict[str, np.ndarray] = {}
            for canon, ds in self._ds.items():
                try:
                    block[canon] = np.asarray(ds[a:b], dtype=np.float64)
                except _H5_ERRORS as exc:
                    raise RunFileError(canon, _("cannot read samples {a}:{b}: {error}", a=a, b=b, error=str(exc)[:300])) from None
            yield block

    def close(self) -> None:
        if self._h5.id.valid:
            self._h5.close()
