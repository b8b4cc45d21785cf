"""Small valid recorder files (MDF4 by asammdf, TDMS by npTDMS) and where their bytes are.

The block and segment walkers here are the tests' own, independent of
``app.io.sources``: they only list where blocks, links, data and text sit in
files these helpers wrote (asammdf writes its blocks one after another, 8-byte
aligned), so that tests can corrupt chosen fields and the fuzz oracle can tell
structure from sample bytes.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

FS = 2000.0
SECONDS = 2.0
N = int(FS * SECONDS)
SLOW_HZ = 100.0
#: Channel map of the files written here: recorder names → trackvkf channels.
CHANNEL_MAP = {"name": "fuzz", "channels": {"Z11": "AccZ_1R", "Z12": "AccZ_1L", "speed": "v_train"}}


def signals() -> dict[str, np.ndarray]:
    """The samples the files hold (ABA at ``FS``, speed at ``SLOW_HZ``)."""
    t = np.arange(N) / FS
    t2 = np.arange(0.0, SECONDS + 0.5 / SLOW_HZ, 1.0 / SLOW_HZ)
    return {
        "t": t,
        "AccZ_1R": (np.sin(2 * np.pi * 37.0 * t) / 9.80665).astype(np.float32),
        "AccZ_1L": np.cos(2 * np.pi * 11.0 * t).astype(np.float32),
        "t2": t2,
        "v_train": (20.0 + 0.5 * t2) * 3.6,
    }


def write_mdf4(path: Path, *, compression: int = 0, fragment: int | None = None, rich: bool = False) -> Path:
    """A small MDF4 run: group ABA (two float32 channels, 2 kHz), group CAN (speed, 100 Hz).

    ``compression`` as asammdf's ``save`` (0 plain, 1 deflate, 2 transposed
    deflate); ``fragment`` splits the data into blocks of that many bytes (DL lists);
    ``rich`` adds what recorders add: a linear conversion (factor 1), a string channel
    (variable-length signal data), a value-to-text channel, a group comment and an attachment.
    """
    from asammdf import MDF, Signal

    s = signals()
    mdf = MDF(version="4.10")
    if fragment is not None:
        mdf.configure(write_fragment_size=fragment)
    extra = []
    if rich:
        extra = [
            Signal(np.array([b"ok"] * N), s["t"], name="status", encoding="utf-8"),
            Signal(np.arange(N) % 3, s["t"], name="mode",
                   conversion={"val_0": 0, "text_0": "a", "val_1": 1, "text_1": "b", "default": "c"}),
        ]
    conversion = {"a": 1.0, "b": 0.0} if rich else None
    mdf.append([Signal(s["AccZ_1R"], s["t"], name="AccZ_1R", unit="g", conversion=conversion),
                Signal(s["AccZ_1L"], s["t"], name="AccZ_1L", unit="m/s^2"), *extra], acq_name="ABA",
               comment="<CGcomment><TX>axle box</TX></CGcomment>" if rich else "")
    if rich:
        mdf.attach(b"recorder notes\n" * 64, file_name="notes.txt", embedded=True)
    mdf.append([Signal(s["v_train"], s["t2"], name="v_train", unit="km/h")], acq_name="CAN")
    mdf.save(path, overwrite=True, compression=compression)
    mdf.close()
    return Path(path)


def write_tdms(path: Path, *, segments: int = 2) -> Path:
    """A small TDMS run: group ABA (waveform channels, ``segments`` segments), group CAN (time + speed)."""
    from nptdms import ChannelObject, GroupObject, TdmsWriter

    s = signals()
    with TdmsWriter(path) as w:
        for k in range(segments):
            part = slice(k * N // segments, (k + 1) * N // segments)
            w.write_segment([
                GroupObject("ABA"),
                ChannelObject("ABA", "AccZ_1R", s["AccZ_1R"][part],
                              {"unit_string": "g", "wf_increment": 1 / FS, "wf_start_offset": 0.0}),
                ChannelObject("ABA", "AccZ_1L", s["AccZ_1L"][part],
                              {"unit_string": "m/s^2", "wf_increment": 1 / FS, "wf_start_offset": 0.0}),
            ])
        w.write_segment([GroupObject("CAN"), ChannelObject("CAN", "Time", s["t2"], {"unit_string": "s"}),
                         ChannelObject("CAN", "v_train", s["v_train"], {"unit_string": "km/h"})])
    return Path(path)


@dataclass(frozen=True)
class Block:
    """An MDF4 block as laid out in the file."""

    offset: int
    kind: str
    length: int
    n_links: int

    @property
    def links_at(self) -> int:
        return self.offset + 24

    @property
    def data_at(self) -> int:
        return self.offset + 24 + 8 * self.n_links

    @property
    def end(self) -> int:
        return self.offset + self.length


def mdf4_blocks(data: bytes) -> list[Block]:
    """Every block of an MDF4 file written by asammdf (a linear walk from byte 64)."""
    out: list[Block] = []
    pos = 64
    while pos + 24 <= len(data):
        if data[pos:pos + 2] != b"##":
            pos += 8  # alignment padding
            continue
        length, n_links = struct.unpack_from("<QQ", data, pos + 8)
        out.append(Block(pos, data[pos + 2:pos + 4].decode("ascii"), length, n_links))
        pos = (pos + length + 7) // 8 * 8
    return out


def first(blocks: list[Block], kind: str, k: int = 0) -> Block:
    """The ``k``-th block of a kind, in file order."""
    return [b for b in blocks if b.kind == kind][k]


def link(data: bytes, block: Block, i: int) -> int:
    return struct.unpack_from("<q", data, block.links_at + 8 * i)[0]


def set_link(data: bytearray, block: Block, i: int, value: int) -> None:
    struct.pack_into("<q", data, block.links_at + 8 * i, value)


@dataclass(frozen=True)
class Segment:
    """A TDMS segment as laid out in the file."""

    offset: int
    toc: int
    next_offset: int
    raw_offset: int

    @property
    def meta_at(self) -> int:
        return self.offset + 28

    @property
    def data_at(self) -> int:
        return self.offset + 28 + self.raw_offset

    @property
    def end(self) -> int:
        return self.offset + 28 + self.next_offset


def tdms_segments(data: bytes) -> list[Segment]:
    """The segments of a (little-endian) TDMS file, from their lead-ins."""
    out: list[Segment] = []
    pos = 0
    while pos + 28 <= len(data):
        toc, _version, nxt, raw = struct.unpack_from("<IIQQ", data, pos + 4)
        out.append(Segment(pos, toc, nxt, raw))
        pos += 28 + nxt
    return out
