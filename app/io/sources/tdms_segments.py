"""Structural validation of an NI TDMS file before npTDMS reads it.

npTDMS is forgiving: a segment whose ``next_segment_offset`` reaches past the
end of the file is read "to the end of the file", a partial last chunk is
read as far as it goes, DAQmx raw data is decoded by its own scaler
descriptions. :func:`check_tdms` walks the segments once with its own
bounded reader and refuses a file that is not structurally valid, naming
the segment's byte offset and the field:

* **Lead-in**: tag ``TDSm``, no unknown table-of-contents bits, version 4712
  or 4713; ``next_segment_offset`` ends the segment inside the file (the last
  one exactly at its end; ``0xFFFF…`` — a recording the writer did not
  close — is refused), ``raw_data_offset`` inside the segment.
* **Metadata** (when the segment has any): it ends exactly at
  ``raw_data_offset``; every object path is ``/``, ``/'group'`` or
  ``/'group'/'channel'`` in UTF-8; every raw data index is "none", "as
  before" (for an object seen before) or 20 bytes (28 for strings) with a
  known data type, dimension 1 and a value count; every property has a known
  type whose value lies inside the metadata.
* **Data**: the segment's raw data is a whole number of chunks (the sum of
  the value counts × type sizes of the objects with data in it); interleaved
  data have equal counts and fixed-size types.
* **DAQmx** raw data (table-of-contents flag or index marker) is refused:
  export the file as standard TDMS.
* **Work**: at most ``limits.max_recorder_blocks`` metadata objects in all
  segments; segments are at least 28 bytes, so their number is bounded by the
  file size.

What no structure check can see: a flipped bit inside sample data or a
property value (``wf_increment``, a unit, a time stamp) is another valid value
(TDMS has no checksums).
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass, field
from typing import BinaryIO

from app.core.i18n import _
from app.io.errors import RunFileError
from app.io.limits import IngestLimits

__all__ = ["TdmsLayout", "check_tdms"]

_LEAD_IN = 28
_TOC_META, _TOC_NEW_LIST, _TOC_RAW, _TOC_INTERLEAVED, _TOC_BIG_ENDIAN, _TOC_DAQMX = (
    1 << 1, 1 << 2, 1 << 3, 1 << 5, 1 << 6, 1 << 7,
)
_TOC_KNOWN = _TOC_META | _TOC_NEW_LIST | _TOC_RAW | _TOC_INTERLEAVED | _TOC_BIG_ENDIAN | _TOC_DAQMX
_NO_DATA, _AS_BEFORE = 0xFFFFFFFF, 0x00000000
_DAQMX_MARKERS = (0x69120000, 0x69130000)
_STRING = 0x20
#: Data types of raw data and their sizes, bytes (strings: variable).
_DATA_SIZES = {1: 1, 2: 2, 3: 4, 4: 8, 5: 1, 6: 2, 7: 4, 8: 8, 9: 4, 10: 8, 0x19: 4, 0x1A: 8,
               0x21: 1, 0x44: 16, 0x08000C: 8, 0x10000D: 16}
_PATH = re.compile(r"/(?:'(?:[^']|'')*'(?:/'(?:[^']|'')*')?)?", re.DOTALL)


def _fail(where: str, message: str) -> RunFileError:
    return RunFileError("file", _("TDMS {where}: {message}", where=where, message=message))


@dataclass
class _Index:
    data_type: int
    n_values: int
    total_bytes: int  # strings: the declared total; others n_values × size


@dataclass
class TdmsLayout:
    """What :func:`check_tdms` learned.

    Attributes
    ----------
    values : dict
        Object path → number of values its raw data hold in the whole file.
    segments : int
        Number of segments.
    """

    values: dict[str, int] = field(default_factory=dict)
    segments: int = 0


class _Meta:
    """A bounded cursor over one segment's metadata."""

    def __init__(self, data: bytes, endian: str, where: str) -> None:
        self.data, self.endian, self.where, self.pos = data, endian, where, 0

    def take(self, n: int, what: str) -> bytes:
        if n > len(self.data) - self.pos:
            raise _fail(self.where, _("{what} at metadata byte {pos} reaches beyond raw_data_offset ({n_data} bytes of metadata)", what=what, pos=self.pos, n_data=len(self.data)))
        out = self.data[self.pos:self.pos + n]
        self.pos += n
        return out

    def u32(self, what: str) -> int:
        return struct.unpack(self.endian + "I", self.take(4, what))[0]

    def u64(self, what: str) -> int:
        return struct.unpack(self.endian + "Q", self.take(8, what))[0]

    def string(self, what: str) -> str:
        n = self.u32(_("the length of {what}", what=what))
        raw = self.take(n, what)
        try:
            return raw.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise _fail(self.where, _("{what} at metadata byte {value} is not UTF-8 (byte {start})", what=what, value=self.pos - n, start=exc.start)) from None

    def property_value(self, name: str) -> None:
        kind = self.u32(_("the type of property {name!r}", name=name))
        if kind == _STRING:
            self.string(_("property {name!r}", name=name))
        elif kind in _DATA_SIZES:
            self.take(_DATA_SIZES[kind], _("property {name!r}", name=name))
        else:
            raise _fail(self.where, _("property {name!r} has an unknown data type 0x{kind:x}", name=name, kind=kind))


def check_tdms(fh: BinaryIO, size: int, limits: IngestLimits) -> TdmsLayout:
    """Validate the structure of a TDMS file (see the module docstring).

    Parameters
    ----------
    fh : binary file
        The file, open for reading.
    size : int
        Its size, bytes.
    limits : IngestLimits
        ``max_recorder_blocks`` (metadata objects in all segments) and
        ``max_recorder_text_bytes`` (metadata bytes of one segment).

    Returns
    -------
    TdmsLayout

    Raises
    ------
    RunFileError
        ``field == "file"``; the message names the segment by its byte offset
        and the field at fault.
    """
    layout = TdmsLayout()
    seen: dict[str, _Index | None] = {}
    current: list[str] = []
    has_data: dict[str, bool] = {}
    n_objects = 0
    pos = 0
    while pos < size:
        where = _("segment at byte {pos}", pos=pos)
        if size - pos < _LEAD_IN:
            raise _fail(where, _("{value} bytes left, too few for a lead-in ({LEAD_IN} bytes)", value=size - pos, LEAD_IN=_LEAD_IN))
        fh.seek(pos)
        lead = fh.read(_LEAD_IN)
        if lead[:4] != b"TDSm":
            raise _fail(where, _("tag {lead!r} is not 'TDSm'", lead=lead[:4]))
        toc = struct.unpack_from("<I", lead, 4)[0]
        if toc & ~_TOC_KNOWN:
            raise _fail(where, _("table of contents 0x{toc:08x} has unknown bits", toc=toc))
        if toc & _TOC_DAQMX:
            raise _fail(where, _("DAQmx raw data (kTocDAQmxRawData) is not accepted: export the file as standard TDMS"))
        endian = ">" if toc & _TOC_BIG_ENDIAN else "<"
        version, next_offset, raw_offset = struct.unpack_from(endian + "IQQ", lead, 8)
        if version not in (4712, 4713):
            raise _fail(where, _("version {version} (4712 or 4713)", version=version))
        if next_offset == 0xFFFFFFFFFFFFFFFF:
            raise _fail(where, _("next_segment_offset 0xFFFFFFFFFFFFFFFF: the writer did not close the segment (an interrupted recording)"))
        left = size - pos - _LEAD_IN
        if next_offset > left:
            raise _fail(where, _("next_segment_offset {next_offset} reaches beyond the end of the file ({left} bytes left)", next_offset=next_offset, left=left))
        if raw_offset > next_offset:
            raise _fail(where, _("raw_data_offset {raw_offset} lies beyond next_segment_offset {next_offset}", raw_offset=raw_offset, next_offset=next_offset))
        if raw_offset > limits.max_recorder_text_bytes:
            raise _fail(where, _("{raw_offset} bytes of metadata (at most {max_recorder_text_bytes})", raw_offset=raw_offset, max_recorder_text_bytes=limits.max_recorder_text_bytes))
        if toc & _TOC_META:
            meta = _Meta(fh.read(raw_offset), endian, where)
            n_objects += _read_metadata(meta, bool(toc & _TOC_NEW_LIST) or not layout.segments,
                                        seen, current, has_data, limits.max_recorder_blocks - n_objects)
            if meta.pos != raw_offset:
                raise _fail(where, _("the metadata end at byte {pos} of raw_data_offset {raw_offset}", pos=meta.pos, raw_offset=raw_offset))
        elif raw_offset:
            raise _fail(where, _("raw_data_offset {raw_offset} without metadata (kTocMetaData not set)", raw_offset=raw_offset))
        elif not layout.segments:
            raise _fail(where, _("the first segment has no metadata"))
        data_bytes = next_offset - raw_offset
        if toc & _TOC_RAW:
            _count_chunks(where, data_bytes, bool(toc & _TOC_INTERLEAVED), current, has_data, seen, layout)
        elif data_bytes:
            raise _fail(where, _("{data_bytes} bytes of raw data but kTocRawData is not set", data_bytes=data_bytes))
        layout.segments += 1
        pos += _LEAD_IN + next_offset
    if not layout.segments:
        raise _fail(_("file"), _("no segments"))
    return layout


def _read_metadata(meta: _Meta, new_list: bool, seen: dict[str, _Index | None], current: list[str],
                   has_data: dict[str, bool], budget: int) -> int:
    count = meta.u32(_("the object count"))
    if count > budget:
        raise _fail(meta.where, _("{count} metadata objects exceed the limit of the file's objects", count=count))
    if new_list:
        current.clear()
        has_data.clear()
    for k in range(count):
        path = meta.string(_("the path of object {k}", k=k))
        if not _PATH.fullmatch(path):
            raise _fail(meta.where, _("object path {path!r} is not /'group'/'channel'", path=path[:80]))
        index = meta.u32(_("the raw data index of {path!r}", path=path))
        if index in _DAQMX_MARKERS:
            raise _fail(meta.where, _("object {path!r} holds DAQmx raw data (index 0x{index:08x}); export the file as standard TDMS", path=path, index=index))
        if index == _NO_DATA:
            has_data[path] = False
            seen.setdefault(path, None)
        elif index == _AS_BEFORE:
            if seen.get(path) is None:
                raise _fail(meta.where, _("object {path!r} reuses a raw data index it never had", path=path))
            has_data[path] = True
        elif index in (20, 28):
            if path.count("/'") != 2:
                raise _fail(meta.where, _("object {path!r} is not a channel but has raw data", path=path))
            kind = meta.u32(_("the data type of {path!r}", path=path))
            dims = meta.u32(_("the dimension of {path!r}", path=path))
            n = meta.u64(_("the value count of {path!r}", path=path))
            if dims != 1:
                raise _fail(meta.where, _("object {path!r} has array dimension {dims} (1)", path=path, dims=dims))
            if kind == _STRING:
                if index != 28:
                    raise _fail(meta.where, _("string object {path!r} has a raw data index of {index} bytes (28)", path=path, index=index))
                total = meta.u64(_("the total size of {path!r}", path=path))
            elif kind in _DATA_SIZES:
                if index != 20:
                    raise _fail(meta.where, _("object {path!r} has a raw data index of {index} bytes (20)", path=path, index=index))
                total = n * _DATA_SIZES[kind]
            else:
                raise _fail(meta.where, _("object {path!r} has raw data of unknown type 0x{kind:x}", path=path, kind=kind))
            seen[path] = _Index(kind, n, total)
            has_data[path] = True
        else:
            raise _fail(meta.where, _("object {path!r} has a raw data index of {index} bytes (20, 28, 0 or 0xFFFFFFFF)", path=path, index=index))
        if path not in current:
            current.append(path)
        n_props = meta.u32(_("the property count of {path!r}", path=path))
        if n_props > (len(meta.data) - meta.pos) // 9:
            raise _fail(meta.where, _("object {path!r} declares {n_props} properties, more than its metadata hold", path=path, n_props=n_props))
        for j in range(n_props):
            name = meta.string(_("the name of property {j} of {path!r}", j=j, path=path))
            meta.property_value(name)
    return count


def _count_chunks(where: str, data_bytes: int, interleaved: bool, current: list[str],
                  has_data: dict[str, bool], seen: dict[str, _Index | None], layout: TdmsLayout) -> None:
    objects = [(p, seen[p]) for p in current if has_data.get(p) and seen.get(p) is not None]
    chunk = sum(ix.total_bytes for _, ix in objects if ix is not None)
    if interleaved:
        counts = {ix.n_values for _, ix in objects if ix is not None}
        if len(counts) > 1 or any(ix is not None and ix.data_type == _STRING for _, ix in objects):
            raise _fail(where, _("interleaved data need fixed-size types and equal value counts"))
    if chunk == 0:
        if data_bytes:
            raise _fail(where, _("{data_bytes} bytes of raw data but its objects declare none", data_bytes=data_bytes))
        return
    if data_bytes % chunk:
        raise _fail(where, _("{data_bytes} bytes of raw data are not a whole number of chunks of {chunk} bytes (the objects' value counts × sizes)", data_bytes=data_bytes, chunk=chunk))
    chunks = data_bytes // chunk
    for path, ix in objects:
        if ix is not None:
            layout.values[path] = layout.values.get(path, 0) + chunks * ix.n_values
