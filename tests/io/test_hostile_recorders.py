"""Issue 24, defects 1, 2 and 4: hostile MDF4 and TDMS files are refused, quickly, naming the block.

Every ingest runs in a forked child with a hard time limit (:func:`call_with_deadline`):
a parser that loops fails the test instead of hanging CI.
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np
import pytest

from app.io import RunFileError, ingest, open_run
from tests.io import recorder_bytes as rb
from tests.io.conftest import base_meta
from tests.io.deadline import call_with_deadline

LIMIT_S = 15.0


def _ingest(src: Path, dest: Path):
    return ingest(src, None, base_meta(), dest, channel_map=rb.CHANNEL_MAP)


def _refused(src: Path, tmp_path: Path, *words: str) -> RunFileError:
    with pytest.raises(RunFileError) as exc:
        call_with_deadline(_ingest, src, tmp_path / "out.h5", seconds=LIMIT_S)
    err = exc.value
    assert err.field == "file", err
    for w in words:
        assert w in err.message, err.message
    assert not (tmp_path / "out.h5").exists()
    return err


def _mutated(src: Path, tmp_path: Path, mutate) -> Path:  # noqa: ANN001
    data = bytearray(src.read_bytes())
    mutate(data, rb.mdf4_blocks(bytes(data)))
    out = tmp_path / "bad.mf4"
    out.write_bytes(bytes(data))
    return out


def test_valid_files_are_accepted(tmp_path: Path) -> None:
    """The base files of these tests (and of the fuzz corpus) ingest, with the samples written."""
    s = rb.signals()
    for name, path in (
        ("plain", rb.write_mdf4(tmp_path / "plain.mf4")),
        ("deflate-dl", rb.write_mdf4(tmp_path / "dl.mf4", compression=1, fragment=4096)),
        ("transposed", rb.write_mdf4(tmp_path / "tr.mf4", compression=2)),
        ("rich", rb.write_mdf4(tmp_path / "rich.mf4", rich=True)),
        ("tdms", rb.write_tdms(tmp_path / "run.tdms")),
    ):
        summary = _ingest(path, tmp_path / f"{name}.h5")
        assert summary.n_samples == rb.N, name
        with open_run(tmp_path / f"{name}.h5") as run:
            np.testing.assert_allclose(run.read("Z12"), s["AccZ_1L"], rtol=1e-6, err_msg=name)


# --- defect 1: loops and spins -------------------------------------------------------------


def test_mdf4_dg_next_link_to_itself_is_refused(tmp_path: Path) -> None:
    src = rb.write_mdf4(tmp_path / "run.mf4")

    def mutate(data, blocks):  # noqa: ANN001
        dg = rb.first(blocks, "DG")
        rb.set_link(data, dg, 0, dg.offset)

    err = _refused(_mutated(src, tmp_path, mutate), tmp_path, "DG block at byte", "cycle")
    assert "dg_dg_next" in err.message


def test_mdf4_cn_next_link_to_itself_is_refused(tmp_path: Path) -> None:
    src = rb.write_mdf4(tmp_path / "run.mf4")

    def mutate(data, blocks):  # noqa: ANN001
        cn = rb.first(blocks, "CN", 1)
        rb.set_link(data, cn, 0, cn.offset)

    err = _refused(_mutated(src, tmp_path, mutate), tmp_path, "CN block at byte", "cycle")
    assert "cn_cn_next" in err.message


def test_mdf4_cn_chain_back_to_an_earlier_channel_is_refused(tmp_path: Path) -> None:
    src = rb.write_mdf4(tmp_path / "run.mf4")

    def mutate(data, blocks):  # noqa: ANN001
        cns = [b for b in blocks if b.kind == "CN"]
        rb.set_link(data, cns[2], 0, cns[0].offset)  # the last channel of ABA links back to its first

    _refused(_mutated(src, tmp_path, mutate), tmp_path, "cn_cn_next", "cycle")


def test_mdf4_dz_declared_compressed_size_beyond_its_stream_is_refused(tmp_path: Path) -> None:
    src = rb.write_mdf4(tmp_path / "run.mf4", compression=2)

    def mutate(data, blocks):  # noqa: ANN001
        dz = rb.first(blocks, "DZ")
        struct.pack_into("<Q", data, dz.data_at + 16, 10**9)  # dz_data_length

    _refused(_mutated(src, tmp_path, mutate), tmp_path, "DZ block at byte", "dz_data_length")


def test_mdf4_dz_declared_compressed_size_2_62_is_refused(tmp_path: Path) -> None:
    src = rb.write_mdf4(tmp_path / "run.mf4", compression=1, fragment=4096)

    def mutate(data, blocks):  # noqa: ANN001
        dz = rb.first(blocks, "DZ", 2)
        struct.pack_into("<Q", data, dz.data_at + 16, 2**62)

    _refused(_mutated(src, tmp_path, mutate), tmp_path, "DZ block at byte")


# --- defect 2: a corrupt deflate stream was a 500 (zlib.error) ------------------------------


def test_mdf4_flipped_deflate_bytes_are_a_4xx(tmp_path: Path) -> None:
    src = rb.write_mdf4(tmp_path / "run.mf4", compression=1)

    def mutate(data, blocks):  # noqa: ANN001
        dz = rb.first(blocks, "DZ")
        start = dz.data_at + 24
        for k in range(start + 2, start + 40):
            data[k] ^= 0x5A

    _refused(_mutated(src, tmp_path, mutate), tmp_path, "DZ block at byte", "deflate")


def test_check_deflate_refuses_a_corrupt_stream_without_zlib_error(tmp_path: Path) -> None:
    from app.io.sources.mdf4_blocks import inflate_exactly

    payload = bytearray(zlib.compress(np.arange(20_000, dtype=np.float64).tobytes()))
    payload[10:30] = bytes(20)
    path = tmp_path / "blob"
    path.write_bytes(bytes(payload))
    with open(path, "rb") as fh, pytest.raises(RunFileError, match="deflate"):
        inflate_exactly(fh, 0, len(payload), 160_000, "the DZ block at byte 0")


# --- defect 4: corrupt files processed to "done" --------------------------------------------


@pytest.mark.parametrize(
    ("kind", "index", "delta"),
    [("DT", 0, -8), ("DT", 0, 8), ("CN", 0, 8), ("CG", 0, -16), ("DG", 1, 8), ("TX", 0, 4096),
     ("HD", 0, -8), ("FH", 0, 8), ("MD", 0, 16)],
)
def test_mdf4_wrong_block_lengths_are_refused(tmp_path: Path, kind: str, index: int, delta: int) -> None:
    src = rb.write_mdf4(tmp_path / "run.mf4")

    def mutate(data, blocks):  # noqa: ANN001
        b = rb.first(blocks, kind, index)
        struct.pack_into("<Q", data, b.offset + 8, b.length + delta)

    # a data block's length is caught where its bytes are counted: at its channel group
    _refused(_mutated(src, tmp_path, mutate), tmp_path, "CG block at byte" if kind == "DT" else f"{kind} block at byte")


def test_mdf4_cycle_count_beyond_the_data_is_refused(tmp_path: Path) -> None:
    src = rb.write_mdf4(tmp_path / "run.mf4")

    def mutate(data, blocks):  # noqa: ANN001
        cg = rb.first(blocks, "CG")
        cycles = struct.unpack_from("<Q", data, cg.data_at + 8)[0]
        struct.pack_into("<Q", data, cg.data_at + 8, cycles + 1)

    _refused(_mutated(src, tmp_path, mutate), tmp_path, "CG block at byte", "bytes of data")


def test_mdf4_channel_beyond_its_record_is_refused(tmp_path: Path) -> None:
    src = rb.write_mdf4(tmp_path / "run.mf4")

    def mutate(data, blocks):  # noqa: ANN001
        cn = rb.first(blocks, "CN", 1)
        struct.pack_into("<I", data, cn.data_at + 4, 1000)  # cn_byte_offset

    _refused(_mutated(src, tmp_path, mutate), tmp_path, "CN block at byte", "record")


def test_tdms_next_segment_offset_2_62_is_refused(tmp_path: Path) -> None:
    src = rb.write_tdms(tmp_path / "run.tdms")
    data = bytearray(src.read_bytes())
    seg = rb.tdms_segments(bytes(data))[1]
    struct.pack_into("<Q", data, seg.offset + 12, 2**62)
    bad = tmp_path / "bad.tdms"
    bad.write_bytes(bytes(data))
    _refused(bad, tmp_path, f"TDMS segment at byte {seg.offset}", "next_segment_offset")


def test_tdms_last_segment_offset_beyond_the_file_is_refused(tmp_path: Path) -> None:
    src = rb.write_tdms(tmp_path / "run.tdms")
    data = bytearray(src.read_bytes())
    seg = rb.tdms_segments(bytes(data))[-1]
    struct.pack_into("<Q", data, seg.offset + 12, seg.next_offset + 4096)
    bad = tmp_path / "bad.tdms"
    bad.write_bytes(bytes(data))
    _refused(bad, tmp_path, "next_segment_offset")


def test_tdms_daqmx_table_of_contents_flag_is_refused(tmp_path: Path) -> None:
    src = rb.write_tdms(tmp_path / "run.tdms")
    data = bytearray(src.read_bytes())
    seg = rb.tdms_segments(bytes(data))[0]
    struct.pack_into("<I", data, seg.offset + 4, seg.toc | (1 << 7))
    bad = tmp_path / "bad.tdms"
    bad.write_bytes(bytes(data))
    _refused(bad, tmp_path, "DAQmx")


def test_tdms_daqmx_raw_data_index_is_refused(tmp_path: Path) -> None:
    src = rb.write_tdms(tmp_path / "run.tdms")
    data = bytearray(src.read_bytes())
    seg = rb.tdms_segments(bytes(data))[0]
    # the first channel's raw data index (length 20) follows its path; make it a DAQmx marker
    path = b"/'ABA'/'AccZ_1R'"
    at = data.index(path, seg.meta_at) + len(path)
    assert struct.unpack_from("<I", data, at)[0] == 20
    struct.pack_into("<I", data, at, 0x69120000)
    bad = tmp_path / "bad.tdms"
    bad.write_bytes(bytes(data))
    _refused(bad, tmp_path, "DAQmx")


def test_tdms_raw_data_offset_beyond_the_segment_is_refused(tmp_path: Path) -> None:
    src = rb.write_tdms(tmp_path / "run.tdms")
    data = bytearray(src.read_bytes())
    seg = rb.tdms_segments(bytes(data))[0]
    struct.pack_into("<Q", data, seg.offset + 20, seg.next_offset + 8)
    bad = tmp_path / "bad.tdms"
    bad.write_bytes(bytes(data))
    _refused(bad, tmp_path, "raw_data_offset")


def test_tdms_value_count_beyond_the_segment_is_refused(tmp_path: Path) -> None:
    src = rb.write_tdms(tmp_path / "run.tdms")
    data = bytearray(src.read_bytes())
    seg = rb.tdms_segments(bytes(data))[0]
    path = b"/'ABA'/'AccZ_1L'"
    at = data.index(path, seg.meta_at) + len(path) + 4 + 8  # index length, type, dimension
    n = struct.unpack_from("<Q", data, at)[0]
    struct.pack_into("<Q", data, at, n + 1)
    bad = tmp_path / "bad.tdms"
    bad.write_bytes(bytes(data))
    _refused(bad, tmp_path, "TDMS segment at byte")


def test_two_hundred_random_byte_flips_are_refused(tmp_path: Path) -> None:
    """200 flips anywhere in a file hit its structure: refused (the issue's variant was accepted)."""
    rng = np.random.default_rng(24)
    for name, src in (("mf4", rb.write_mdf4(tmp_path / "run.mf4", compression=1, fragment=4096)),
                      ("tdms", rb.write_tdms(tmp_path / "run.tdms", segments=8))):
        for trial in range(3):
            data = bytearray(src.read_bytes())
            for pos in rng.choice(len(data), size=200, replace=False):
                data[pos] ^= int(rng.integers(1, 256))
            bad = tmp_path / f"flipped{trial}.{name}"
            bad.write_bytes(bytes(data))
            with pytest.raises(RunFileError):
                call_with_deadline(_ingest, bad, tmp_path / "out.h5", seconds=LIMIT_S)


def test_hdf5_corrupt_metadata_is_a_4xx_not_a_runtime_error(tmp_path: Path) -> None:
    """Found by the fuzz corpus: flipped bytes in an HDF5 file's metadata made h5py raise
    RuntimeError (a 500): "bad coordinate offset", "ran off end of input buffer", "bad heap free list"."""
    from tests.fuzz import corpus

    mutants, _, files, _ = corpus.build("hdf5", tmp_path)
    names = {"hdf5-contiguous/flip-struct@1981", "hdf5-contiguous/flip-struct@1072",
             "hdf5-contiguous/storm1", "hdf5-gzip/flip-struct@1501"}
    chosen = [f for m, f in zip(mutants, files, strict=True) if m.name in names]
    assert len(chosen) == len(names)
    for path in chosen:
        with pytest.raises(RunFileError) as exc:
            call_with_deadline(ingest, path, None, base_meta(), tmp_path / "out.h5", seconds=LIMIT_S)
        assert exc.value.field in ("file", "Z11", "Z12", "speed"), exc.value
