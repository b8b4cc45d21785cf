"""Structural validation of an ASAM MDF 4 file before asammdf reads it.

asammdf follows the file's links as they are: a DG or CN block whose next
link points back loops forever, a block longer than the file or a data block
shorter than its records reads out of bounds (a crash in C code), a lying DZ
block spins or decodes garbage. :func:`check_mdf4` walks the block graph once
with its own bounded reader and refuses a file that is not structurally
valid, naming the block, its byte offset and the field:

* **Blocks**: every block a link reaches starts at a multiple of 8 inside the
  file, has a known id, a length that holds its header, links and data
  section (exactly, for the blocks whose data section has a fixed size) and
  ends inside the file; no two blocks overlap.
* **Links**: each link is 0 or reaches a block of a kind the link may point
  to; the chains (DG, CG, CN, FH, AT, EV, CH, DL, SR) are walked with each
  block owned by one chain only, so a cycle or a shared chain is refused;
  conversion (CC) references form no cycle.
* **Fields**: record id size, channel types, data types with their bit
  counts, bit offsets, invalidation bit positions and byte ranges inside the
  record, conversion types with their value and reference counts, channel
  array dimensions, data list counts and offsets, compression types.
* **Sizes**: the data of every data group (DT blocks, DZ blocks inflated,
  DL lists) holds exactly cycle count × record size bytes; every DZ block
  inflates, within its declared compressed size, to exactly its declared
  original size (streamed, nothing kept; LZ4/Zstandard refused).
* **Work**: at most ``limits.max_recorder_blocks`` blocks, at most
  ``limits.max_recorder_text_bytes`` of text and comments (counted at every
  reference), metadata blocks of at most 16 MiB; XML with a document type
  declaration (entity expansion) is refused.

Not accepted (refused with the reason): MDF 3, unfinalised files, unsorted
data groups (record ids), variable-length signal data groups, remote masters
and column storage (MDF 4.2), channel arrays other than "CN template".

What no structure check can see: a flipped bit inside sample data, a time
stamp, a text or a conversion coefficient is another valid value (MDF has no
checksums).
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import BinaryIO

from app.core.i18n import _
from app.io.errors import RunFileError
from app.io.limits import IngestLimits

__all__ = ["Mdf4Layout", "ChannelLayout", "check_mdf4", "inflate_exactly"]

_ID_SIZE = 64
_HD_AT = 64
_HEADER = 24
_READ_BYTES = 1 << 20
#: Largest data section of a metadata block read into memory (DT/DZ payloads are streamed).
_MAX_META_BLOCK = 16 << 20
_PAYLOAD = frozenset({"DT", "SD", "RD", "DV", "DI", "RV", "RI"})
_TEXT = frozenset({"TX", "MD"})
#: Blocks whose data section is read only up to here (a DZ header, an AT header before its
#: embedded data); the rest is streamed (DZ) or never read (AT).
_HEAD_ONLY = {"DZ": 24, "AT": 40}
_KNOWN = frozenset(
    {"HD", "FH", "CH", "AT", "EV", "DG", "CG", "SI", "CN", "CC", "CA", "TX", "MD", "DT", "SD",
     "RD", "DZ", "DL", "HL", "SR", "RV", "RI", "DV", "DI", "LD"}
)
#: Fixed size of the data section (after the links) for MDF 4.0/4.1.
_DATA_SIZE = {"HD": 32, "FH": 16, "DG": 8, "CG": 32, "SI": 8, "CN": 72, "HL": 8, "SR": 24, "CH": 8}
_LINKS = {
    "HD": ("hd_dg_first", "hd_fh_first", "hd_ch_first", "hd_at_first", "hd_ev_first", "hd_md_comment"),
    "FH": ("fh_fh_next", "fh_md_comment"),
    "AT": ("at_at_next", "at_tx_filename", "at_tx_mimetype", "at_md_comment"),
    "EV": ("ev_ev_next", "ev_ev_parent", "ev_ev_range", "ev_tx_name", "ev_md_comment"),
    "CH": ("ch_ch_next", "ch_ch_first", "ch_tx_name", "ch_md_comment"),
    "DG": ("dg_dg_next", "dg_cg_first", "dg_data", "dg_md_comment"),
    "CG": ("cg_cg_next", "cg_cn_first", "cg_tx_acq_name", "cg_si_acq_source", "cg_sr_first",
           "cg_md_comment"),
    "SI": ("si_tx_name", "si_tx_path", "si_md_comment"),
    "CN": ("cn_cn_next", "cn_composition", "cn_tx_name", "cn_si_source", "cn_cc_conversion",
           "cn_data", "cn_md_unit", "cn_md_comment"),
    "CC": ("cc_tx_name", "cc_md_unit", "cc_md_comment", "cc_cc_inverse"),
    "CA": ("ca_composition",),
    "DL": ("dl_dl_next",),
    "HL": ("hl_dl_first",),
    "SR": ("sr_sr_next", "sr_data"),
}
#: Bit counts a channel of each data type may have (None: any positive multiple of 8).
_INT_TYPES = (0, 1, 2, 3)
_FLOAT_TYPES = (4, 5)
_FLOAT_BITS = (16, 32, 64)
_COMPLEX_BITS = (32, 64, 128)
#: Conversion type → (value count, reference count) as a function of the declared counts.
_MAX_CC_DEPTH = 8
_CG_FLAGS = 0x1 | 0x2 | 0x4 | 0x8 | 0x10
_CG_VLSD, _CG_REMOTE_MASTER = 0x1, 0x8
_CN_INVALIDATION = 1 << 1
_CN_DEFAULT_X = 1 << 12
_CN_KNOWN_FLAGS = (1 << 20) - 1


def _fail(where: str, message: str) -> RunFileError:
    return RunFileError("file", _("MDF4 {where}: {message}", where=where, message=message))


@dataclass(frozen=True)
class _Block:
    offset: int
    kind: str
    length: int
    links: tuple[int, ...]
    data: bytes  # the data section (header of it only for payload and DZ blocks)

    @property
    def where(self) -> str:
        return _("{kind} block at byte {offset}", kind=self.kind, offset=self.offset)

    def link_name(self, i: int) -> str:
        names = _LINKS.get(self.kind, ())
        if i < len(names):
            return names[i]
        return f"{self.kind.lower()}_link[{i}]"


@dataclass(frozen=True)
class ChannelLayout:
    """A channel as the file declares it (what asammdf will read)."""

    offset: int
    channel_type: int
    data_type: int
    bit_count: int
    conversion_type: int | None
    composed: bool


@dataclass
class Mdf4Layout:
    """What :func:`check_mdf4` learned: data groups, channels, sizes.

    Attributes
    ----------
    version : int
        Version number (410 for 4.10).
    groups : list of (cycle count, record bytes, channel count)
        One per channel group (= data group: only sorted files are accepted), file order.
    channels : dict
        CN block offset → :class:`ChannelLayout` of every channel.
    decoded_bytes : int
        Bytes of all records and signal data once inflated.
    """

    version: int
    groups: list[tuple[int, int, int]] = field(default_factory=list)
    channels: dict[int, ChannelLayout] = field(default_factory=dict)
    decoded_bytes: int = 0


class _Walker:
    def __init__(self, fh: BinaryIO, size: int, limits: IngestLimits) -> None:
        self.fh, self.size, self.limits = fh, size, limits
        self.blocks: dict[int, _Block] = {}
        self.held = 0
        self.owner: dict[int, str] = {}
        self.text_bytes = 0
        self.checked_text: set[int] = set()
        self.checked_cc: set[int] = set()
        self.checked_si: set[int] = set()
        self.refs: list[tuple[_Block, int, frozenset[str]]] = []
        self.declared_payload = 0
        self.deflated: list[tuple[_Block, int, int]] = []

    # --- reading ---------------------------------------------------------------------------
    def read(self, offset: int, n: int) -> bytes:
        self.fh.seek(offset)
        data = self.fh.read(n)
        if len(data) != n:  # pragma: no cover - bounds are checked before every read
            raise _fail(_("byte {offset}", offset=offset), _("the file ends inside a block"))
        return data

    def block(self, offset: int, kinds: frozenset[str] | set[str], parent: _Block | None, name: str) -> _Block:
        """The block at ``offset`` (checked once), of one of ``kinds``."""
        src = _("{where}: link {name}", where=parent.where, name=name) if parent is not None else name
        if offset < _ID_SIZE or offset % 8 or offset + _HEADER > self.size:
            raise _fail(src, _("points to byte {offset}, not a block inside the {size}-byte file (blocks start at a multiple of 8 after the identification block)", offset=offset, size=self.size))
        blk = self.blocks.get(offset)
        if blk is None:
            blk = self._parse(offset, src)
        if blk.kind not in kinds:
            raise _fail(src, _("points to a {kind} block at byte {offset}; expected {items}", kind=blk.kind, offset=offset, items=' or '.join(sorted(kinds))))
        return blk

    def _parse(self, offset: int, src: str) -> _Block:
        if len(self.blocks) >= self.limits.max_recorder_blocks:
            raise _fail(src, _("more than {max_recorder_blocks} blocks (limit)", max_recorder_blocks=self.limits.max_recorder_blocks))
        head = self.read(offset, _HEADER)
        tag, _reserved, length, n_links = struct.unpack("<4sIQQ", head)
        kind = tag[2:].decode("latin-1")
        where = _("block at byte {offset} (reached from {source})", offset=offset, source=src)
        if tag[:2] != b"##" or kind not in _KNOWN:
            raise _fail(where, _("unknown block id {tag!r}", tag=tag))
        where = _("{kind} block at byte {offset}", kind=kind, offset=offset)
        if length > self.size - offset:
            raise _fail(where, _("block_length {length} reaches beyond the end of the file ({value} bytes left)", length=length, value=self.size - offset))
        if n_links > (length - _HEADER) // 8 or length < _HEADER:
            raise _fail(where, _("block_length {length} cannot hold the header and {n_links} links", length=length, n_links=n_links))
        data_len = length - _HEADER - 8 * n_links
        if 8 * n_links > _MAX_META_BLOCK:
            raise _fail(where, _("{n_links} links (at most {value})", n_links=n_links, value=_MAX_META_BLOCK // 8))
        if kind in _PAYLOAD:
            keep = 0
        elif kind in _HEAD_ONLY:
            keep = min(data_len, _HEAD_ONLY[kind])
        else:
            if data_len > _MAX_META_BLOCK:
                raise _fail(where, _("a data section of {data_len} bytes (at most {MAX_META_BLOCK})", data_len=data_len, MAX_META_BLOCK=_MAX_META_BLOCK))
            keep = data_len
        # blocks do not overlap (checked at the end): what they hold cannot exceed the file
        self.held += 8 * n_links + keep
        if self.held > self.size:
            raise _fail(where, _("the blocks read so far hold more bytes than the file: blocks overlap"))
        links = struct.unpack(f"<{n_links}q", self.read(offset + _HEADER, 8 * n_links))
        data = self.read(offset + _HEADER + 8 * n_links, keep) if keep else b""
        blk = _Block(offset, kind, length, links, data)
        want = _DATA_SIZE.get(kind)
        if want is not None and data_len != want and kind != "CN":
            raise _fail(where, _("block_length {length}: {n_links} links and a data section of {data_len} bytes; a {kind} block has {want}", length=length, n_links=n_links, data_len=data_len, kind=kind, want=want))
        self.blocks[offset] = blk
        return blk

    def claim(self, blk: _Block, owner: str, chain: set[int] | None = None) -> None:
        """Make ``blk`` part of the structure once: a second owner is a cycle or a shared chain."""
        prev = self.owner.get(blk.offset)
        if prev is not None:
            what = _("a cycle") if chain is not None and blk.offset in chain else _("already linked from {owner}", owner=prev)
            raise _fail(owner, _("points to the {where}, {what} (each {kind} block belongs to one chain)", where=blk.where, what=what, kind=blk.kind))
        self.owner[blk.offset] = owner

    def chain(self, parent: _Block, i: int, kind: str) -> Iterator[_Block]:
        """Blocks of a next-linked chain starting at link ``i`` of ``parent``, each claimed once."""
        seen: set[int] = set()
        prev, j = parent, i
        while prev.links[j] if j < len(prev.links) else 0:
            name = prev.link_name(j)
            blk = self.block(prev.links[j], {kind}, prev, name)
            self.claim(blk, _("{where}: link {name}", where=prev.where, name=name), seen)
            seen.add(blk.offset)
            yield blk
            prev, j = blk, 0

    def link(self, blk: _Block, i: int, kinds: frozenset[str] | set[str], *, required: bool = False) -> _Block | None:
        target = blk.links[i]
        if target == 0:
            if required:
                raise _fail(blk.where, _("link {link_name} is 0 (required)", link_name=blk.link_name(i)))
            return None
        return self.block(target, kinds, blk, blk.link_name(i))

    def ref(self, blk: _Block, i: int, kinds: frozenset[str]) -> None:
        """A link that refers to a block elsewhere in the structure (checked at the end)."""
        if blk.links[i]:
            self.block(blk.links[i], kinds, blk, blk.link_name(i))
            self.refs.append((blk, i, kinds))

    # --- shared blocks ---------------------------------------------------------------------
    def text(self, blk: _Block, i: int, *, required: bool = False, kinds: frozenset[str] = _TEXT) -> None:
        tx = self.link(blk, i, kinds, required=required)
        if tx is None:
            return
        self.text_bytes += tx.length
        if self.text_bytes > self.limits.max_recorder_text_bytes:
            raise _fail(_("{where}: link {name}", where=blk.where, name=blk.link_name(i)),
                        _("the file's texts and comments exceed {max_recorder_text_bytes} bytes, counted at every reference (limit)", max_recorder_text_bytes=self.limits.max_recorder_text_bytes))
        if tx.offset in self.checked_text:
            return
        self.checked_text.add(tx.offset)
        if tx.links:
            raise _fail(tx.where, _("{n_links} links; a {kind} block has none", n_links=len(tx.links), kind=tx.kind))
        end = tx.data.find(b"\0")
        if end < 0:
            raise _fail(tx.where, _("the text is not zero-terminated inside the block"))
        try:
            text = tx.data[:end].decode("utf-8")
        except UnicodeDecodeError as exc:
            raise _fail(tx.where, _("the text is not UTF-8 (byte {start})", start=exc.start)) from None
        if tx.kind == "MD" and "<!DOCTYPE" in text.upper():
            raise _fail(tx.where, _("XML with a document type declaration (entities) is not accepted"))

    def source(self, blk: _Block, i: int) -> None:
        si = self.link(blk, i, {"SI"})
        if si is None or si.offset in self.checked_si:
            return
        self.checked_si.add(si.offset)
        self.n_links(si, 3)
        kind, bus = si.data[0], si.data[1]
        if kind > 6 or bus > 8:
            raise _fail(si.where, _("si_type {kind} / si_bus_type {bus} out of range", kind=kind, bus=bus))
        self.text(si, 0)
        self.text(si, 1)
        self.text(si, 2)

    def conversion(self, blk: _Block, i: int, stack: tuple[int, ...] = ()) -> int | None:
        cc = self.link(blk, i, {"CC"})
        if cc is None:
            return None
        if cc.offset in stack:
            raise _fail(_("{where}: link {name}", where=blk.where, name=blk.link_name(i)),
                        _("points back to the {where}: a cycle of conversions", where=cc.where))
        if len(stack) >= _MAX_CC_DEPTH:
            raise _fail(cc.where, _("conversions nested deeper than {MAX_CC_DEPTH}", MAX_CC_DEPTH=_MAX_CC_DEPTH))
        kind = cc.data[0] if cc.data else -1
        if cc.offset in self.checked_cc:
            return kind
        if len(cc.data) < 24:
            raise _fail(cc.where, _("a data section of {n_data} bytes; a CC block has at least 24", n_data=len(cc.data)))
        kind, _precision, _flags, n_refs, n_vals = struct.unpack_from("<BBHHH", cc.data)
        if len(cc.links) != 4 + n_refs:
            raise _fail(cc.where, _("{n_links} links but cc_ref_count {n_refs} (4 + references)", n_links=len(cc.links), n_refs=n_refs))
        if len(cc.data) != 24 + 8 * n_vals:
            raise _fail(cc.where, _("block_length {length} does not hold cc_val_count {n_vals} values", length=cc.length, n_vals=n_vals))
        if not _conversion_counts_ok(kind, n_refs, n_vals):
            raise _fail(cc.where, _("cc_type {kind} with {n_refs} references and {n_vals} values is not a valid conversion", kind=kind, n_refs=n_refs, n_vals=n_vals))
        for j in range(3):
            self.text(cc, j)
        inner = (*stack, cc.offset)
        self.conversion(cc, 3, inner)
        for j in range(4, 4 + n_refs):
            target = cc.links[j]
            if target:
                ref = self.block(target, {"TX", "MD", "CC"}, cc, f"cc_ref[{j - 4}]")
                if ref.kind == "CC":
                    self.conversion(cc, j, inner)
                else:
                    self.text(cc, j)
        self.checked_cc.add(cc.offset)
        return kind

    def n_links(self, blk: _Block, want: int) -> None:
        if len(blk.links) != want:
            raise _fail(blk.where, _("{n_links} links; a {kind} block has {want}", n_links=len(blk.links), kind=blk.kind, want=want))

    # --- data ------------------------------------------------------------------------------
    def data(self, parent: _Block, i: int, org: str) -> int:
        """Bytes of the data reached from link ``i`` of ``parent`` (DT/SD, DZ, DL, HL), checked."""
        top = self.link(parent, i, {org, "DZ", "DL", "HL"})
        if top is None:
            return 0
        owner = _("{where}: link {name}", where=parent.where, name=parent.link_name(i))
        if top.kind == "HL":
            self.claim(top, owner)
            self.n_links(top, 1)
            _flags, zip_type = struct.unpack_from("<HB", top.data)
            if zip_type > 1:
                raise _fail(top.where, _("hl_zip_type {zip_type} is not accepted (0 deflate, 1 transposed deflate)", zip_type=zip_type))
            return self.data_list(top, 0, org, _("{where}: link hl_dl_first", where=top.where))
        if top.kind == "DL":
            return self.data_list(parent, i, org, owner)
        self.claim(top, owner)
        return self.leaf(top, org)

    def data_list(self, parent: _Block, i: int, org: str, owner: str) -> int:
        total = 0
        for dl in self.chain(parent, i, "DL"):
            if len(dl.data) < 8:
                raise _fail(dl.where, _("a data section shorter than 8 bytes"))
            flags, count = dl.data[0], struct.unpack_from("<I", dl.data, 4)[0]
            if flags & ~0x0F:
                raise _fail(dl.where, _("dl_flags 0x{flags:02x} has unknown bits", flags=flags))
            if count < 1 or len(dl.links) != 1 + count:
                raise _fail(dl.where, _("{n_links} links but dl_count {count} (1 + data blocks)", n_links=len(dl.links), count=count))
            equal = flags & 1
            need = 8 + (8 if equal else 8 * count) + 8 * count * bin(flags & 0x0E).count("1")
            if len(dl.data) < need:
                raise _fail(dl.where, _("block_length {length} does not hold dl_count {count} entries", length=dl.length, count=count))
            if equal:
                step = struct.unpack_from("<Q", dl.data, 8)[0]
                offsets = None
            else:
                offsets = struct.unpack_from(f"<{count}Q", dl.data, 8)
            for j in range(count):
                if offsets is not None and offsets[j] != total:
                    raise _fail(dl.where, _("dl_offset[{j}] is {offsets} but the blocks before it hold {total} bytes", j=j, offsets=offsets[j], total=total))
                leaf = self.block(dl.links[1 + j], {org, "DZ"}, dl, f"dl_data[{j}]")
                self.claim(leaf, _("{where}: link dl_data[{j}]", where=dl.where, j=j))
                n = self.leaf(leaf, org)
                if equal and j + 1 < count and n != step:
                    raise _fail(leaf.where, _("holds {n} bytes but the DL block at byte {offset} declares dl_equal_length {step}", n=n, offset=dl.offset, step=step))
                total += n
        return total

    def leaf(self, blk: _Block, org: str) -> int:
        if blk.links:
            raise _fail(blk.where, _("{n_links} links; a {kind} block has none", n_links=len(blk.links), kind=blk.kind))
        if blk.kind != "DZ":
            n = blk.length - _HEADER
            self.declared_payload += n
            return n
        if len(blk.data) < 24:
            raise _fail(blk.where, _("block_length too short for the DZ header"))
        org_kind, zip_type, _res, param, original, compressed = struct.unpack("<2sBBIQQ", blk.data)
        if org_kind.decode("latin-1") != org:
            raise _fail(blk.where, _("dz_org_block_type {org_kind!r} where {org} data belong", org_kind=org_kind, org=org))
        if zip_type not in (0, 1):
            raise _fail(blk.where, _("dz_zip_type {zip_type} is not accepted (0 deflate, 1 transposed deflate; LZ4 and Zstandard are not)", zip_type=zip_type))
        if zip_type == 1 and param == 0:
            raise _fail(blk.where, _("dz_zip_parameter 0 for a transposition (columns must be > 0)"))
        if compressed != blk.length - 2 * _HEADER:
            raise _fail(blk.where, _("dz_data_length {compressed} but the block holds {value} compressed bytes", compressed=compressed, value=blk.length - 2 * _HEADER))
        self.declared_payload += original
        self.deflated.append((blk, compressed, original))
        return original


def _conversion_counts_ok(kind: int, refs: int, vals: int) -> bool:
    """MDF 4.1 table 59: references and values each conversion type needs."""
    if kind == 0:
        return vals == 0 and refs == 0
    if kind == 1:
        return vals == 2 and refs == 0
    if kind == 2:
        return vals == 6 and refs == 0
    if kind == 3:
        return vals == 0 and refs == 1
    if kind in (4, 5):
        return vals >= 2 and vals % 2 == 0 and refs == 0
    if kind == 6:
        return vals >= 1 and vals % 3 == 1 and refs == 0
    if kind == 7:
        return refs == vals + 1
    if kind == 8:
        return vals % 2 == 0 and refs == vals // 2 + 1
    if kind == 9:
        return vals == refs + 1
    if kind == 10:
        return vals == 0 and refs >= 1 and refs % 2 == 1
    if kind == 11:
        return vals == refs and refs >= 1
    return False


def _bits_ok(data_type: int, bits: int) -> bool:
    if data_type in _INT_TYPES:
        return 1 <= bits <= 64
    if data_type in _FLOAT_TYPES:
        return bits in _FLOAT_BITS
    if data_type in (15, 16):
        return bits in _COMPLEX_BITS
    if data_type == 13:
        return bits == 56
    if data_type == 14:
        return bits == 48
    return bits >= 8 and bits % 8 == 0  # strings, byte arrays, MIME


def inflate_exactly(fh: BinaryIO, address: int, compressed: int, original: int, where: str) -> None:
    """Inflate a deflate stream of ``compressed`` bytes at ``address`` without keeping it.

    It must end exactly at its last byte and yield exactly ``original`` bytes;
    memory is bounded (1 MiB pieces) and so is the work (every step consumes
    input or produces output, output never beyond ``original``).

    Raises
    ------
    RunFileError
        ``field == "file"``, naming ``where``.
    """
    fh.seek(address)
    inflater = zlib.decompressobj()
    left, produced = compressed, 0
    while left > 0:
        piece = fh.read(min(_READ_BYTES, left))
        if not piece:
            raise _fail(where, _("the deflate stream is cut short by the end of the file ({left} bytes missing)", left=left))
        left -= len(piece)
        while piece:
            try:
                out = inflater.decompress(piece, _READ_BYTES)
            except zlib.error as exc:
                raise _fail(where, _("corrupt deflate stream ({error})", error=exc)) from None
            produced += len(out)
            if produced > original:
                raise _fail(where, _("inflates to more than its declared dz_org_data_length {original} bytes (decompression bomb or corrupt)", original=original))
            tail = inflater.unconsumed_tail
            if inflater.eof:
                if tail or inflater.unused_data or left:
                    raise _fail(where, _("the deflate stream ends before dz_data_length ({compressed} bytes) does", compressed=compressed))
                break
            if not out and len(tail) == len(piece):  # pragma: no cover - zlib always progresses
                raise _fail(where, _("the deflate stream makes no progress"))
            piece = tail
    if not inflater.eof:
        raise _fail(where, _("the deflate stream does not end within dz_data_length ({compressed} bytes)", compressed=compressed))
    if produced != original:
        raise _fail(where, _("inflates to {produced} bytes but declares dz_org_data_length {original}", produced=produced, original=original))


def check_mdf4(fh: BinaryIO, size: int, limits: IngestLimits) -> Mdf4Layout:
    """Validate the structure of an MDF 4 file (see the module docstring).

    Parameters
    ----------
    fh : binary file
        The file, open for reading.
    size : int
        Its size, bytes.
    limits : IngestLimits
        ``max_recorder_blocks``, ``max_recorder_text_bytes``,
        ``max_recorder_channels`` and the decoded-size limit.

    Returns
    -------
    Mdf4Layout

    Raises
    ------
    RunFileError
        ``field == "file"``; the message names the block, its byte offset and
        the field at fault.
    """
    if size < _ID_SIZE + _HEADER:
        raise _fail(_("identification block"), _("the file has {size} bytes, too short for MDF", size=size))
    fh.seek(0)
    ident = fh.read(_ID_SIZE)
    if ident[:8] != b"MDF     ":
        raise _fail(_("identification block"), _("id_file {ident!r} is not 'MDF     '", ident=ident[:8]))
    version = struct.unpack_from("<H", ident, 28)[0]
    if version < 400:
        raise _fail(_("identification block"), _("version {value:.2f}: MDF 3 files are not accepted (convert to MDF 4, e.g. with asammdf)", value=version / 100))
    if version >= 500:
        raise _fail(_("identification block"), _("id_ver {version} is not an MDF 4 version", version=version))
    unfinished, custom = struct.unpack_from("<HH", ident, 60)
    if unfinished or custom:
        raise _fail(_("identification block"), _("id_unfin_flags 0x{unfinished:04x}/0x{custom:04x}: the recorder did not finalise the file (finalise it, e.g. with the recorder's tool)", unfinished=unfinished, custom=custom))
    w = _Walker(fh, size, limits)
    hd = w.block(_HD_AT, {"HD"}, None, "the header (byte 64)")
    w.claim(hd, "the identification block")
    w.n_links(hd, 6)
    w.text(hd, 5)
    layout = Mdf4Layout(version=version)
    for fh_block in w.chain(hd, 1, "FH"):
        w.n_links(fh_block, 2)
        w.text(fh_block, 1)
    for at in w.chain(hd, 3, "AT"):
        _attachment(w, at)
    _channel_hierarchy(w, hd)
    for ev in w.chain(hd, 4, "EV"):
        _event(w, ev)
    n_channels = 0
    for dg in w.chain(hd, 0, "DG"):
        w.n_links(dg, 4)
        w.text(dg, 3)
        rec_id = dg.data[0]
        if rec_id not in (0, 1, 2, 4, 8):
            raise _fail(dg.where, _("dg_rec_id_size {rec_id} (0, 1, 2, 4 or 8)", rec_id=rec_id))
        cgs = list(w.chain(dg, 1, "CG"))
        if rec_id or len(cgs) > 1:
            raise _fail(dg.where, _("an unsorted data group ({n_cgs} channel groups, record ids of {rec_id} bytes) is not accepted: sort the file first (asammdf: MDF(path).save(out))", n_cgs=len(cgs), rec_id=rec_id))
        expected = 0
        for cg in cgs:
            cycles, record, n = _channel_group(w, cg, layout)
            n_channels += n
            if n_channels > limits.max_recorder_channels:
                raise _fail(cg.where, _("more than {max_recorder_channels} channels in the file (limit)", max_recorder_channels=limits.max_recorder_channels))
            layout.groups.append((cycles, record, n))
            expected += cycles * record
        limits.check_decoded(w.declared_payload + expected, size, _("the MDF data"))
        held = w.data(dg, 2, "DT")
        if held != expected:
            where = cgs[0].where if cgs else dg.where
            raise _fail(where, _("cg_cycle_count × record size make {expected} bytes of data but the data blocks of the DG block at byte {offset} hold {held}", expected=expected, offset=dg.offset, held=held))
    _check_refs(w)
    _check_overlaps(w)
    limits.check_decoded(w.declared_payload, size, _("the MDF data"))
    for blk, compressed, original in w.deflated:
        inflate_exactly(fh, blk.offset + 2 * _HEADER, compressed, original, blk.where)
    layout.decoded_bytes = w.declared_payload
    return layout


def _attachment(w: _Walker, at: _Block) -> None:
    w.n_links(at, 4)
    if len(at.data) < 40:
        raise _fail(at.where, _("a data section shorter than 40 bytes"))
    flags = struct.unpack_from("<H", at.data)[0]
    embedded = struct.unpack_from("<Q", at.data, 32)[0]
    if flags & ~0x7:
        raise _fail(at.where, _("at_flags 0x{flags:04x} has unknown bits", flags=flags))
    if at.length - _HEADER - 8 * len(at.links) != 40 + embedded:
        raise _fail(at.where, _("at_embedded_size {embedded} does not match the block_length {length}", embedded=embedded, length=at.length))
    for j in (1, 2, 3):
        w.text(at, j, kinds=frozenset({"TX"}) if j < 3 else _TEXT)


def _event(w: _Walker, ev: _Block) -> None:
    if len(ev.data) < 32 or len(ev.links) < 5:
        raise _fail(ev.where, _("too short for an EV block (5 links, 32 bytes of data)"))
    scope, attachments = struct.unpack_from("<IH", ev.data, 8)
    if len(ev.links) not in (5 + scope + attachments, 6 + scope + attachments):
        raise _fail(ev.where, _("{n_links} links but ev_scope_count {scope} and ev_attachment_count {attachments}", n_links=len(ev.links), scope=scope, attachments=attachments))
    w.ref(ev, 1, frozenset({"EV"}))
    w.ref(ev, 2, frozenset({"EV"}))
    w.text(ev, 3)
    w.text(ev, 4)
    for j in range(5, 5 + scope):
        w.ref(ev, j, frozenset({"CG", "CN"}))
    for j in range(5 + scope, 5 + scope + attachments):
        w.ref(ev, j, frozenset({"AT"}))
    if len(ev.links) == 6 + scope + attachments:
        w.text(ev, len(ev.links) - 1)


def _channel_hierarchy(w: _Walker, hd: _Block) -> None:
    todo: list[tuple[_Block, int]] = [(hd, 2)]
    while todo:
        parent, i = todo.pop()
        for ch in w.chain(parent, i, "CH"):
            count = struct.unpack_from("<I", ch.data)[0]
            if len(ch.links) != 4 + 3 * count:
                raise _fail(ch.where, _("{n_links} links but ch_element_count {count}", n_links=len(ch.links), count=count))
            w.text(ch, 2)
            w.text(ch, 3)
            for j in range(count):
                w.ref(ch, 4 + 3 * j, frozenset({"DG"}))
                w.ref(ch, 5 + 3 * j, frozenset({"CG"}))
                w.ref(ch, 6 + 3 * j, frozenset({"CN"}))
            todo.append((ch, 1))


def _channel_group(w: _Walker, cg: _Block, layout: Mdf4Layout) -> tuple[int, int, int]:
    _record_id, cycles, flags, _sep, _res, data_bytes, inval_bytes = struct.unpack("<QQHHIII", cg.data)
    if flags & ~_CG_FLAGS:
        raise _fail(cg.where, _("cg_flags 0x{flags:04x} has unknown bits", flags=flags))
    if flags & (_CG_VLSD | _CG_REMOTE_MASTER):
        raise _fail(cg.where, _("cg_flags 0x{flags:04x}: variable-length signal data groups and remote masters are not accepted", flags=flags))
    w.n_links(cg, 6)
    w.text(cg, 2)
    w.source(cg, 3)
    w.text(cg, 5)
    for sr in w.chain(cg, 4, "SR"):
        w.n_links(sr, 2)
        w.data(sr, 1, "RD")
    record = data_bytes + inval_bytes
    n, masters = 0, 0
    todo: list[tuple[_Block, int]] = [(cg, 1)]
    while todo:
        parent, i = todo.pop()
        top_level = parent is cg
        for cn in w.chain(parent, i, "CN"):
            n += 1
            if n > w.limits.max_recorder_channels:
                raise _fail(cn.where, _("more than {max_recorder_channels} channels (limit)", max_recorder_channels=w.limits.max_recorder_channels))
            info = _channel(w, cn, data_bytes, inval_bytes, todo)
            layout.channels[cn.offset] = info
            if top_level and info.channel_type in (2, 3):
                masters += 1
                if masters > 1:
                    raise _fail(cn.where, _("a second master channel in the CG block at byte {offset}", offset=cg.offset))
    return cycles, record, n


def _channel(w: _Walker, cn: _Block, data_bytes: int, inval_bytes: int,
             todo: list[tuple[_Block, int]]) -> ChannelLayout:
    if len(cn.links) < 8:
        raise _fail(cn.where, _("{n_links} links; a CN block has at least 8", n_links=len(cn.links)))
    if len(cn.data) != 72:
        raise _fail(cn.where, _("block_length {length}: {n_links} links and a data section of {n_data} bytes; a CN block has 72", length=cn.length, n_links=len(cn.links), n_data=len(cn.data)))
    (ctype, sync, dtype, bit_offset, byte_offset, bits, flags, inval_pos, _precision, _res,
     attachments) = struct.unpack_from("<BBBBIIIIBBH", cn.data)
    want_links = 8 + attachments + (3 if flags & _CN_DEFAULT_X else 0)
    if len(cn.links) != want_links:
        raise _fail(cn.where, _("{n_links} links but cn_attachment_count {attachments} and cn_flags 0x{flags:x} need {want_links}", n_links=len(cn.links), attachments=attachments, flags=flags, want_links=want_links))
    if ctype > 6:
        raise _fail(cn.where, _("cn_type {ctype} is not a channel type of MDF 4.0–4.2", ctype=ctype))
    if sync > 4:
        raise _fail(cn.where, _("cn_sync_type {sync} out of range (0–4)", sync=sync))
    if dtype > 17:
        raise _fail(cn.where, _("cn_data_type {dtype} out of range (0–17)", dtype=dtype))
    if bit_offset > 7:
        raise _fail(cn.where, _("cn_bit_offset {bit_offset} (0–7; whole bytes go to cn_byte_offset)", bit_offset=bit_offset))
    if flags & ~_CN_KNOWN_FLAGS:
        raise _fail(cn.where, _("cn_flags 0x{flags:x} has unknown bits", flags=flags))
    virtual = ctype in (3, 6)
    if bit_offset and dtype not in _INT_TYPES:
        raise _fail(cn.where, _("cn_bit_offset {bit_offset} for cn_data_type {dtype}: only integers may start inside a byte", bit_offset=bit_offset, dtype=dtype))
    if not virtual:
        if not _bits_ok(dtype, bits):
            raise _fail(cn.where, _("cn_bit_count {bits} does not fit cn_data_type {dtype}", bits=bits, dtype=dtype))
        end = byte_offset + (bit_offset + bits + 7) // 8
        if end > data_bytes:
            raise _fail(cn.where, _("cn_byte_offset {byte_offset} + {bits} bits end at byte {end} of a record of cg_data_bytes {data_bytes}", byte_offset=byte_offset, bits=bits, end=end, data_bytes=data_bytes))
    if flags & _CN_INVALIDATION and inval_pos >= 8 * inval_bytes:
        raise _fail(cn.where, _("cn_inval_bit_pos {inval_pos} outside the {inval_bytes} invalidation bytes", inval_pos=inval_pos, inval_bytes=inval_bytes))
    composed = False
    comp = w.link(cn, 1, {"CN", "CA"})
    if comp is not None:
        composed = True
        if comp.kind == "CN":
            todo.append((cn, 1))
        else:
            w.claim(comp, _("{where}: link cn_composition", where=cn.where))
            _array(w, comp, cn, byte_offset, bits, data_bytes, todo)
    w.text(cn, 2, required=True)
    w.source(cn, 3)
    conversion = w.conversion(cn, 4)
    if ctype == 1:
        w.data(cn, 5, "SD")
    elif ctype == 5:
        w.ref(cn, 5, frozenset({"CN"}))
    elif cn.links[5]:
        raise _fail(cn.where, _("link cn_data is set for cn_type {ctype} (only VLSD and MLSD channels have one)", ctype=ctype))
    w.text(cn, 6)
    w.text(cn, 7)
    for j in range(8, 8 + attachments):
        w.ref(cn, j, frozenset({"AT"}))
    if flags & _CN_DEFAULT_X:
        for j, kinds in zip(range(8 + attachments, 11 + attachments), ("DG", "CG", "CN"), strict=True):
            w.ref(cn, j, frozenset({kinds}))
    return ChannelLayout(cn.offset, ctype, dtype, bits, conversion, composed)


def _array(w: _Walker, ca: _Block, cn: _Block, byte_offset: int, bits: int, data_bytes: int,
           todo: list[tuple[_Block, int]]) -> None:
    if len(ca.data) < 16:
        raise _fail(ca.where, _("a data section shorter than 16 bytes"))
    _ca_type, storage, dims, flags, base, _inval_base = struct.unpack_from("<BBHIiI", ca.data)
    if storage != 0:
        raise _fail(ca.where, _("ca_storage {storage}: only arrays stored as a CN template are accepted", storage=storage))
    if not 1 <= dims <= 8:
        raise _fail(ca.where, _("ca_ndim {dims} (1–8)", dims=dims))
    if flags & ~0x1FF:
        raise _fail(ca.where, _("ca_flags 0x{flags:x} has unknown bits", flags=flags))
    if len(ca.data) < 16 + 8 * dims:
        raise _fail(ca.where, _("block_length {length} does not hold ca_dim_size[{dims}]", length=ca.length, dims=dims))
    sizes = struct.unpack_from(f"<{dims}Q", ca.data, 16)
    elements = 1
    for s in sizes:
        elements *= s
    if not 1 <= elements <= data_bytes * 8:
        raise _fail(ca.where, _("ca_dim_size {list} ({elements} elements) do not fit a record of {data_bytes} bytes", list=list(sizes), elements=elements, data_bytes=data_bytes))
    last = byte_offset + (elements - 1) * base + (bits + 7) // 8
    if base < 0 or last > data_bytes:
        raise _fail(ca.where, _("ca_byte_offset_base {base}: the {elements} elements of the CN block at byte {offset} end at byte {last} of a record of {data_bytes} bytes", base=base, elements=elements, offset=cn.offset, last=last, data_bytes=data_bytes))
    fixed = flags & (1 << 5)
    axis = flags & (1 << 4)
    want = 1 + (3 * dims if flags & 1 else 0) + (3 * dims if flags & 2 else 0) + (3 if flags & 4 else 0)
    want += (3 if flags & 8 else 0) + (dims if axis else 0) + (3 * dims if axis and not fixed else 0)
    if len(ca.links) != want:
        raise _fail(ca.where, _("{n_links} links but ca_flags 0x{flags:x} and ca_ndim {dims} need {want}", n_links=len(ca.links), flags=flags, dims=dims, want=want))
    need = 16 + 8 * dims + (8 * sum(sizes) if fixed else 0)
    if len(ca.data) != need:
        raise _fail(ca.where, _("a data section of {n_data} bytes; ca_ndim, ca_dim_size and ca_flags need {need}", n_data=len(ca.data), need=need))
    j = 1 + (3 * dims if flags & 1 else 0) + (3 * dims if flags & 2 else 0) + (3 if flags & 4 else 0)
    j += 3 if flags & 8 else 0
    for k in range(1, j):
        w.ref(ca, k, frozenset({"DG", "CG", "CN"}))
    if axis:
        for k in range(j, j + dims):
            w.conversion(ca, k)
        for k in range(j + dims, len(ca.links)):
            w.ref(ca, k, frozenset({"DG", "CG", "CN"}))
    comp = w.link(ca, 0, {"CN", "CA"})
    if comp is not None:
        if comp.kind == "CA":
            raise _fail(ca.where, _("link ca_composition to another CA block: nested arrays are not accepted"))
        todo.append((ca, 0))


def _check_refs(w: _Walker) -> None:
    for blk, i, kinds in w.refs:
        target = w.blocks[blk.links[i]]
        if target.kind not in _TEXT | {"CC", "SI"} and target.offset not in w.owner:
            raise _fail(blk.where, _("link {link_name} refers to the {where}, which is not part of the file's {items} structure", link_name=blk.link_name(i), where=target.where, items='/'.join(sorted(kinds))))


def _check_overlaps(w: _Walker) -> None:
    spans = sorted((b.offset, b.offset + b.length, b) for b in w.blocks.values())
    for (_a0, a1, a), (b0, _b1, b) in zip(spans, spans[1:], strict=False):
        if b0 < a1:
            raise _fail(a.where, _("block_length {length} overlaps the {where}", length=a.length, where=b.where))
