"""Structure-aware mutations of valid recorder and run files (deterministic: seeded).

Each mutant says whether every byte it changed lies in a **value region** of
its base file: bytes that hold a value the format cannot check (samples, the
compressed stream of a DZ block, texts, time stamps, value ranges, property
values). The oracle (``test_fuzz_parsers.py``) demands of every other mutant
that it is refused or gives exactly the base file's data; value-only mutants
may be accepted with other data. The value regions are found here from what
the tests wrote, independently of the readers in ``app.io.sources``.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from tests.io import recorder_bytes as rb

__all__ = ["Mutant", "mdf4_mutants", "tdms_mutants", "hdf5_mutants", "byte_mutants"]


@dataclass(frozen=True)
class Mutant:
    """A corrupted file: its bytes and whether only value bytes changed."""

    name: str
    data: bytes
    value_only: bool


def _pick(rng: np.random.Generator, seq: list):  # noqa: ANN202 - any element type
    """One element of a list (Python ints stay exact, unlike ``rng.choice``)."""
    return seq[int(rng.integers(len(seq)))]


def _value_only(base: bytes, data: bytes, values: np.ndarray) -> bool:
    if len(base) != len(data):
        return False
    diff = np.frombuffer(base, np.uint8) != np.frombuffer(data, np.uint8)
    return bool(diff.any()) and bool(values[diff].all())


def _mutant(name: str, base: bytes, data: bytes | bytearray, values: np.ndarray) -> Mutant:
    data = bytes(data)
    return Mutant(name, data, _value_only(base, data, values))


def byte_mutants(tag: str, base: bytes, values: np.ndarray, rng: np.random.Generator,
                 n_structure: int, n_value: int, n_storms: int) -> Iterator[Mutant]:
    """Single-byte flips in structure and in value bytes, 200-flip storms, cuts and a tail."""
    structure = np.flatnonzero(~values)
    value = np.flatnonzero(values)
    for pool, n, what in ((structure, n_structure, "struct"), (value, n_value, "value")):
        for pos in rng.choice(pool, size=min(n, pool.size), replace=False):
            data = bytearray(base)
            data[pos] ^= int(rng.integers(1, 256))
            yield _mutant(f"{tag}/flip-{what}@{pos}", base, data, values)
    for k in range(n_storms):
        data = bytearray(base)
        for pos in rng.choice(len(base), size=200, replace=False):
            data[pos] ^= int(rng.integers(1, 256))
        yield _mutant(f"{tag}/storm{k}", base, data, values)
    for cut in sorted(rng.choice(np.arange(1, len(base)), size=4, replace=False)):
        yield _mutant(f"{tag}/cut@{cut}", base, base[:cut], values)
    yield _mutant(f"{tag}/tail", base, base + bytes(rng.integers(0, 256, 64, dtype=np.uint8)), values)


# --- MDF4 ---------------------------------------------------------------------------------


def mdf4_values(base: bytes) -> np.ndarray:
    """Value bytes of an MDF4 file written by asammdf."""
    values = np.zeros(len(base), dtype=bool)
    for b in rb.mdf4_blocks(base):
        if b.kind in ("DT", "TX", "MD", "HD", "FH"):
            values[b.data_at:b.end] = True  # samples, texts, start time / history time
        elif b.kind == "DZ":
            values[b.data_at + 24:b.end] = True  # the deflate stream
        elif b.kind == "CN":
            # how the record's bytes are read: any in-range data type, bit/byte offset and bit
            # count is another valid layout (out-of-range ones are refused: not value bytes)
            values[b.data_at + 2:b.data_at + 12] = True
            values[b.data_at + 20] = True  # cn_precision
            values[b.data_at + 24:b.data_at + 72] = True  # value range, limits, extended limits
        elif b.kind == "CC":
            values[b.data_at + 24:b.end] = True  # conversion coefficients
    return values


#: Links to shareable blocks (texts, conversions, sources): pointing them at another block
#: of a kind they may reference, or at nothing where optional, is another valid file.
_REFERENCE_LINKS = {
    ("HD", 5): {"TX", "MD"}, ("FH", 1): {"TX", "MD"}, ("DG", 3): {"TX", "MD"},
    ("CG", 2): {"TX"}, ("CG", 3): {"SI"}, ("CG", 5): {"TX", "MD"},
    ("CN", 2): {"TX"}, ("CN", 3): {"SI"}, ("CN", 4): {"CC"}, ("CN", 6): {"TX", "MD"},
    ("CN", 7): {"TX", "MD"}, ("SI", 0): {"TX"}, ("SI", 1): {"TX"}, ("SI", 2): {"TX", "MD"},
}
_REQUIRED_LINKS = {("CN", 2)}


def mdf4_mutants(tag: str, base: bytes, rng: np.random.Generator) -> Iterator[Mutant]:
    """Byte flips plus link, length, link-count and field rewrites of an MDF4 file."""
    values = mdf4_values(base)
    blocks = rb.mdf4_blocks(base)
    yield from byte_mutants(tag, base, values, rng, n_structure=25, n_value=10, n_storms=3)
    with_links = [b for b in blocks if b.n_links]
    offsets = [b.offset for b in blocks]
    for _ in range(60):
        b = with_links[int(rng.integers(len(with_links)))]
        i = int(rng.integers(b.n_links))
        old = struct.unpack_from("<q", base, b.links_at + 8 * i)[0]
        choices = [b.offset, 0, _pick(rng, offsets), old + 8, old - 8, len(base), 2**62, -8,
                   _pick(rng, offsets) + 4]
        new = choices[int(rng.integers(len(choices)))]
        if new == old:
            continue
        data = bytearray(base)
        struct.pack_into("<q", data, b.links_at + 8 * i, new)
        mutant = _mutant(f"{tag}/link-{b.kind}@{b.offset}[{i}]={new}", base, data, values)
        kinds = _REFERENCE_LINKS.get((b.kind, i), set())
        target = next((t for t in blocks if t.offset == new), None)
        if (new == 0 and kinds and (b.kind, i) not in _REQUIRED_LINKS) or (target and target.kind in kinds):
            mutant = Mutant(mutant.name + " (valid reference)", mutant.data, True)
        yield mutant
    for _ in range(30):
        b = blocks[int(rng.integers(len(blocks)))]
        data = bytearray(base)
        if rng.random() < 0.7:
            new = b.length + _pick(rng, [8, -8, 1, -1, 16]) if rng.random() < 0.8 else 2**40
            struct.pack_into("<Q", data, b.offset + 8, max(new, 0))
            what = f"length={new}"
        else:
            new = b.n_links + _pick(rng, [1, -1, 2**32])
            struct.pack_into("<Q", data, b.offset + 16, max(new, 0))
            what = f"links={new}"
        yield _mutant(f"{tag}/{b.kind}@{b.offset}-{what}", base, data, values)
    fielded = [b for b in blocks if b.kind in ("CN", "CG", "DG", "DL", "HL", "DZ", "SI", "CC", "AT", "EV")]
    for _ in range(60):
        b = fielded[int(rng.integers(len(fielded)))]
        candidates = [p for p in range(b.data_at, min(b.end, b.data_at + 72)) if not values[p]]
        if not candidates:
            continue
        pos = int(rng.choice(candidates))
        width = _pick(rng, [1, 2, 4, 8])
        width = min(width, b.end - pos)
        old = int.from_bytes(base[pos:pos + width], "little")
        new = _pick(rng, [0, 1, (1 << (8 * width)) - 1, old + 1, old ^ 0x80, old * 2])
        new &= (1 << (8 * width)) - 1
        if new == old:
            continue
        data = bytearray(base)
        data[pos:pos + width] = new.to_bytes(width, "little")
        yield _mutant(f"{tag}/field-{b.kind}@{b.offset}+{pos - b.offset}:{width}={new}", base, data, values)


# --- TDMS ---------------------------------------------------------------------------------


def tdms_values(base: bytes) -> np.ndarray:
    """Value bytes of a TDMS file written by :func:`tests.io.recorder_bytes.write_tdms`."""
    values = np.zeros(len(base), dtype=bool)
    for seg in rb.tdms_segments(base):
        values[seg.data_at:seg.end] = True  # raw data
        meta = base[seg.meta_at:seg.data_at]
        # texts: object paths, property names and string values (the bytes after their length)
        for text in (b"/'ABA'", b"/'CAN'", b"'AccZ_1R'", b"'AccZ_1L'", b"'Time'", b"'v_train'",
                     b"unit_string", b"wf_increment", b"wf_start_offset", b"m/s^2", b"km/h", b"g", b"s"):
            start = 0
            while (k := meta.find(text, start)) >= 0:
                values[seg.meta_at + k:seg.meta_at + k + len(text)] = True
                start = k + 1
        for path in (b"'AccZ_1R'", b"'AccZ_1L'", b"'Time'", b"'v_train'"):
            # a channel's data type: another type of the same size is another valid layout
            k = meta.find(path)
            if k >= 0 and struct.unpack_from("<I", meta, k + len(path))[0] == 20:
                values[seg.meta_at + k + len(path) + 4:seg.meta_at + k + len(path) + 8] = True
        for name in (b"wf_increment", b"wf_start_offset"):  # their float64 values
            start = 0
            while (k := meta.find(name, start)) >= 0:
                at = seg.meta_at + k + len(name) + 4
                values[at:at + 8] = True
                start = k + 1
    return values


def tdms_mutants(tag: str, base: bytes, rng: np.random.Generator) -> Iterator[Mutant]:
    """Byte flips plus lead-in and metadata field rewrites of a TDMS file."""
    values = tdms_values(base)
    yield from byte_mutants(tag, base, values, rng, n_structure=25, n_value=10, n_storms=3)
    segments = rb.tdms_segments(base)
    for _ in range(20):
        seg = segments[int(rng.integers(len(segments)))]
        data = bytearray(base)
        field = int(rng.integers(4))
        if field == 0:
            bit = int(rng.integers(32))
            struct.pack_into("<I", data, seg.offset + 4, seg.toc ^ (1 << bit))
            what = f"toc^bit{bit}"
            if bit == 5:  # interleaved or not: both are valid layouts of equal-count channels
                yield Mutant(f"{tag}/lead-in@{seg.offset}-{what} (layout)", bytes(data), True)
                continue
        elif field == 1:
            struct.pack_into("<I", data, seg.offset + 8, _pick(rng, [4711, 4714, 0]))
            what = "version"
        elif field == 2:
            new = _pick(rng, [seg.next_offset + 1, seg.next_offset - 8, seg.next_offset + 8, 2**62,
                                  2**64 - 1, 0])
            struct.pack_into("<Q", data, seg.offset + 12, max(new, 0))
            what = f"next={new}"
        else:
            new = _pick(rng, [seg.raw_offset + 1, seg.raw_offset - 4, 0, seg.next_offset, 2**40])
            struct.pack_into("<Q", data, seg.offset + 20, max(new, 0))
            what = f"raw={new}"
        yield _mutant(f"{tag}/lead-in@{seg.offset}-{what}", base, data, values)
    for _ in range(20):
        seg = segments[int(rng.integers(len(segments)))]
        candidates = [p for p in range(seg.meta_at, seg.data_at - 3) if not values[p]]
        if not candidates:
            continue
        pos = int(rng.choice(candidates))
        old = struct.unpack_from("<I", base, pos)[0]
        new = _pick(rng, [0, 1, 0xFFFFFFFF, 0x69120000, old + 1, old + 1000, 20, 28])
        if new == old:
            continue
        data = bytearray(base)
        struct.pack_into("<I", data, pos, new)
        yield _mutant(f"{tag}/meta-u32@{pos}={new}", base, data, values)


# --- HDF5 ---------------------------------------------------------------------------------


def hdf5_values(base: bytes, raw: list[tuple[int, int]], texts: list[bytes]) -> np.ndarray:
    """Value bytes of an HDF5 file: the datasets' raw data and the attribute values given."""
    values = np.zeros(len(base), dtype=bool)
    for offset, size in raw:
        values[offset:offset + size] = True
    for text in texts:
        start = 0
        while (k := base.find(text, start)) >= 0:
            values[k:k + len(text)] = True
            start = k + 1
    return values


def hdf5_mutants(tag: str, base: bytes, values: np.ndarray, rng: np.random.Generator) -> Iterator[Mutant]:
    """Byte flips (structure and data), storms, cuts and a tail of an HDF5 file."""
    yield from byte_mutants(tag, base, values, rng, n_structure=70, n_value=10, n_storms=3)


# --- GeoJSON ------------------------------------------------------------------------------

#: Hostile values put in place of a node of a valid document (JSON text).
HOSTILE_JSON = [
    "null", "true", '""', '"\\u0000"', '"40\\u000010"', "1e400", "-1e400", "NaN", "Infinity", "-0.0",
    "7" * 5000, "-" + "9" * 400, "0." + "0" * 5000 + "1", "[]", "{}", "[[[[[[[[[[[[[[[[[[[[1]]]]]]]]]]]]]]]]]]]",
    "[" * 100_000 + "]" * 100_000, '"' + "x" * 200_000 + '"', "[" + ",".join(["0"] * 100_000) + "]",
    '{"type": "Feature"}', "[1e308, 1e308]", "[null, null]", '["9", "48"]', "[true, false]",
]
#: CRS names no line geometry can use (another body, geocentric, vertical, compound, nonsense).
HOSTILE_CRS = [
    "IAU_2015:49900", "IAU_2015:30100", "ESRI:104971", "EPSG:4978", "EPSG:5714", "EPSG:4326+5714",
    "EPSG:4979", "EPSG:99999999", "+proj=longlat +a=1 +b=1", "+proj=pipeline +step +proj=axisswap +order=2,1",
    "+proj=geos +h=35785831 +lon_0=0", "LOCAL_CS[\"x\",LOCAL_DATUM[\"y\",0],UNIT[\"m\",1]]",
    'GEOGCS["' + "A" * 100_000 + '"]', "", "EPSG:", "urn:ogc:def:crs:EPSG::0", "EPSG:3857",
    "urn:ogc:def:crs:OGC:1.3:CRS84",
]


def geojson_base() -> dict:
    """A valid collection in ETRS89/UTM 32N: tracks 1 and 2 of a line, km stations along them."""
    x = 512_340.0 + np.arange(6) * 200.0
    y = 5_401_200.0 + np.arange(6) * 50.0
    km = 12.0 + np.concatenate(([0.0], np.cumsum(np.hypot(np.diff(x), np.diff(y))))) / 1000
    return {
        "type": "FeatureCollection",
        "crs": {"type": "name", "properties": {"name": "EPSG:25832"}},
        "features": [
            {"type": "Feature", "properties": {"line_id": "4010", "track": track, "km": km.tolist()},
             "geometry": {"type": "LineString", "coordinates": np.column_stack((x, y + dy)).tolist()}}
            for track, dy in (("1", 0.0), ("2", 4.0))
        ],
    }


def _paths(node, path=()):  # noqa: ANN001, ANN202 - any JSON value
    yield path
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _paths(v, (*path, k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _paths(v, (*path, i))


_MARK = "\u241fHOSTILE\u241f"


def _set(doc, path, value):  # noqa: ANN001, ANN202
    if not path:
        return value
    node = doc
    for p in path[:-1]:
        node = node[p]
    node[path[-1]] = value
    return doc


def geojson_mutants(rng: np.random.Generator) -> Iterator[tuple[str, bytes]]:
    """Valid GeoJSON with one node replaced, removed or duplicated, hostile CRS, text flips."""
    import copy
    import json

    base = geojson_base()
    yield "geojson/base", json.dumps(base).encode()
    paths = list(_paths(base))
    for k in range(60):
        path = _pick(rng, paths)
        doc = _set(copy.deepcopy(base), path, _MARK)
        text = json.dumps(doc).replace(json.dumps(_MARK), _pick(rng, HOSTILE_JSON))
        yield f"geojson/replace{k}@{'/'.join(map(str, path))}", text.encode()
    for k in range(20):
        path = _pick(rng, [p for p in paths if p])
        doc = copy.deepcopy(base)
        parent = doc
        for p in path[:-1]:
            parent = parent[p]
        if isinstance(parent, dict):
            del parent[path[-1]]
        else:
            parent.insert(path[-1], copy.deepcopy(parent[path[-1]]))  # a duplicated element
        yield f"geojson/drop-or-dup{k}@{'/'.join(map(str, path))}", json.dumps(doc).encode()
    for crs in HOSTILE_CRS:
        doc = copy.deepcopy(base)
        doc["crs"]["properties"]["name"] = crs
        yield f"geojson/crs={crs[:40]}", json.dumps(doc).encode()
    text = json.dumps(base).encode()
    for k in range(30):
        data = bytearray(text)
        for pos in rng.choice(len(data), size=int(rng.integers(1, 4)), replace=False):
            data[pos] = int(rng.integers(0, 256))
        yield f"geojson/flip{k}", bytes(data)
    yield "geojson/features-dup", json.dumps({**base, "features": base["features"] * 2}).encode()
    yield "geojson/many-features", json.dumps({**base, "features": base["features"][:1] * 1001}).encode()
    yield "geojson/not-utf8", b"\xff\xfe" + text
