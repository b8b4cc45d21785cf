"""MDF4 and TDMS recorder files (written here by asammdf and npTDMS), channel maps, positions."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from asammdf import MDF, Signal
from nptdms import ChannelObject, GroupObject, TdmsWriter

from app.io import RunFileError, ingest, open_run
from app.io.channel_map import parse_channel_map, unit_factor
from app.io.limits import IngestLimits
from tests.io.conftest import base_meta, listing

FS = 2000.0
N = int(FS * 20)


def _meta(**over):
    meta = base_meta(**over)
    return meta


def _mdf(path: Path, *, slow_rate: float = 100.0, z_group2: bool = False, compression: int = 0,
         speed_from: float = 0.0) -> Path:
    t = np.arange(N) / FS
    z = np.sin(2 * np.pi * 37.0 * t)
    mdf = MDF(version="4.10")
    sigs = [Signal((z / 9.80665).astype(np.float32), t, name="AccZ_1R", unit="g")]
    if not z_group2:
        sigs.append(Signal(np.cos(2 * np.pi * 11 * t).astype(np.float32), t, name="AccZ_4L", unit="m/s^2"))
    sigs.append(Signal(np.full(N, 20.0, np.float32), t, name="Temp", unit="degC"))
    mdf.append(sigs, acq_name="ABA")
    if z_group2:
        t3 = np.arange(N // 2) / (FS / 2)
        mdf.append([Signal(np.cos(t3).astype(np.float32), t3, name="AccZ_4L", unit="m/s^2")],
                   acq_name="ABA2")
    t2 = np.arange(speed_from, 20.0 + 0.5 / slow_rate, 1.0 / slow_rate)
    mdf.append([Signal((20.0 + 0.5 * t2) * 3.6, t2, name="v_train", unit="km/h"),
                Signal(5000.0 + 20.0 * t2 + 0.25 * t2**2, t2, name="odo", unit="m")], acq_name="CAN")
    mdf.save(path, overwrite=True, compression=compression)
    mdf.close()
    return path


CMAP = {"name": "test", "channels": {"Z11": "AccZ_1R", "Z42": "AccZ_4L", "speed": "v_train",
                                      "position": "odo"}}


def test_mdf4_mapped_resampled_and_converted(tmp_path: Path) -> None:
    src = _mdf(tmp_path / "run.mf4", compression=2)
    out = tmp_path / "run.h5"
    s = ingest(src, None, _meta(), out, channel_map=CMAP)
    assert s.source_format == "mdf4" and s.n_samples == N and s.fs == FS
    assert s.report["channels"]["Z11"] == {"source": "AccZ_1R", "group": "ABA", "unit": "g",
                                           "factor": pytest.approx(9.80665)}
    assert any(w.startswith("position: the relative position channel starts at 5000") for w in s.warnings)
    with open_run(out) as run:
        t = np.arange(N) / FS
        np.testing.assert_allclose(run.read("Z11"), np.sin(2 * np.pi * 37 * t), atol=1e-5)
        np.testing.assert_allclose(run.read("speed"), 20 + 0.5 * t, rtol=1e-9)  # km/h → m/s
        np.testing.assert_allclose(run.position(), 20 * t + 0.25 * t**2, atol=1e-5)  # linear interp. of 100 Hz
        assert "Temp" not in run.channels


def test_mdf4_line_km_decreasing(tmp_path: Path) -> None:
    t = np.arange(N) / FS
    mdf = MDF(version="4.10")
    mdf.append([Signal(np.sin(t).astype(np.float32), t, name="Z11")], acq_name="ABA")
    t2 = np.arange(0, 20.005, 0.01)
    mdf.append([Signal(30000.0 - 25.0 * t2, t2, name="position", unit="m")], acq_name="ODO")
    mdf.save(tmp_path / "km.mf4", overwrite=True)
    meta = _meta(position_kind="line_km", axle_positions={"1": 0.0, "4": -17.5})
    del meta["km_start"], meta["km_increasing"]
    s = ingest(tmp_path / "km.mf4", None, meta, tmp_path / "km.h5")
    assert s.metadata.km_start == pytest.approx(30.0) and s.metadata.km_increasing is False
    assert s.warnings == [] and s.report["km_source"] == "line_km"
    with open_run(tmp_path / "km.h5") as run:
        np.testing.assert_allclose(run.km(N - 1, N), [30.0 - 0.025 * (N - 1) / FS], atol=1e-9)
        assert run.metadata.position_kind == "relative"


def test_line_km_conflicts_and_relative_requirements(tmp_path: Path) -> None:
    src = _mdf(tmp_path / "run.mf4")
    with pytest.raises(RunFileError) as exc:
        ingest(src, None, _meta(position_kind="line_km"), tmp_path / "a.h5", channel_map=CMAP)
    assert exc.value.field == "km_start"
    meta = _meta()
    del meta["km_start"]
    with pytest.raises(RunFileError) as exc:
        ingest(src, None, meta, tmp_path / "b.h5", channel_map=CMAP)
    assert exc.value.field == "km_start" and "required" in exc.value.message


def test_tdms_waveform_and_time_channel(tmp_path: Path) -> None:
    t = np.arange(N) / FS
    path = tmp_path / "run.tdms"
    with TdmsWriter(path) as w:
        for k in range(4):
            sl = slice(k * N // 4, (k + 1) * N // 4)
            w.write_segment([GroupObject("ABA"), ChannelObject(
                "ABA", "AccZ_1R", (np.sin(2 * np.pi * 5 * t[sl]) / 9.80665).astype(np.float32),
                {"unit_string": "g", "wf_increment": 1 / FS, "wf_start_offset": 0.0})])
        t2 = np.arange(0, 20.05, 0.05)
        w.write_segment([GroupObject("ODO"), ChannelObject("ODO", "Time", t2, {"unit_string": "s"}),
                         ChannelObject("ODO", "v", 20.0 + 0 * t2, {"unit_string": "m/s"})])
    cmap = {"channels": {"Z11": "AccZ_1R", "speed": {"source": "v", "group": "ODO"}}}
    s = ingest(path, None, _meta(), tmp_path / "t.h5", channel_map=cmap)
    assert s.source_format == "tdms" and s.n_samples == N
    with open_run(tmp_path / "t.h5") as run:
        np.testing.assert_allclose(run.read("Z11"), np.sin(2 * np.pi * 5 * t), atol=1e-5)
        assert run.position(N - 1, N)[0] == pytest.approx(20.0 * (N - 1) / FS)


@pytest.mark.parametrize(
    ("kwargs", "cmap", "field", "text"),
    [
        ({}, None, "channel_map", "unmapped channels of the file: 'AccZ_1R'"),
        ({}, {"channels": {"Z11": "AccZ_9X"}}, "AccZ_9X", "not found in the file"),
        ({"z_group2": True}, CMAP, "AccZ_4L", "another time base"),
        ({"speed_from": 5.0}, CMAP, "v_train", "cannot be resampled onto the ABA time base"),
        ({}, {"channels": {"Z11": "Temp"}}, "Temp", "unit 'degC' cannot be converted"),
    ],
)
def test_recorder_rejections_name_the_channel(tmp_path: Path, kwargs, cmap, field, text) -> None:
    src = _mdf(tmp_path / "run.mf4", **kwargs)
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    with pytest.raises(RunFileError) as exc:
        ingest(src, None, _meta(), out_dir / "run.h5", channel_map=cmap)
    assert exc.value.field == field and text in exc.value.message
    assert listing(out_dir) == []


@pytest.mark.parametrize(
    ("cmap", "field", "german"),
    [
        (None, "channel_map", "kein Achslagerbeschleunigungs-Kanal (Z11, Z12, Z41, Z42) zugeordnet; nicht zugeordnete "
                              "Kanäle der Datei: 'AccZ_1R'"),
        ({"channels": {"Z11": "AccZ_9X"}}, "AccZ_9X", "Kanal der Kanalzuordnung (Z11) nicht in der Datei gefunden"),
        ({"channels": {"Z11": "Temp"}}, "Temp", "Einheit 'degC' lässt sich nicht in m/s^2 umrechnen; zulässig: "),
    ],
)
def test_recorder_rejections_in_german_name_the_channel(tmp_path: Path, cmap, field, german) -> None:
    """The message is kept for translation: the API answers it in the user's language (a German
    user reads German with the channel named; the field stays the API's)."""
    src = _mdf(tmp_path / "run.mf4")
    with pytest.raises(RunFileError) as exc:
        ingest(src, None, _meta(), tmp_path / "run.h5", channel_map=cmap)
    assert exc.value.field == field
    assert exc.value.message.in_language("de").startswith(german), exc.value.message.in_language("de")


def test_ambiguous_channel_needs_group(tmp_path: Path) -> None:
    t = np.arange(4000) / FS
    mdf = MDF(version="4.10")
    mdf.append([Signal(np.sin(t), t, name="acc")], acq_name="A")
    mdf.append([Signal(np.cos(t), t, name="acc")], acq_name="B")
    mdf.append([Signal(20 + 0 * t, t, name="speed")], acq_name="C")
    mdf.save(tmp_path / "amb.mf4", overwrite=True)
    with pytest.raises(RunFileError) as exc:
        ingest(tmp_path / "amb.mf4", None, _meta(), tmp_path / "x.h5", channel_map={"channels": {"Z11": "acc"}})
    assert exc.value.field == "acc" and "ambiguous" in exc.value.message
    s = ingest(tmp_path / "amb.mf4", None, _meta(), tmp_path / "x.h5",
               channel_map={"channels": {"Z11": {"source": "acc", "group": "B"}, "speed": "speed"}})
    assert s.report["channels"]["Z11"]["group"] == "B"


def test_mdf4_deflate_bomb_and_channel_limit(tmp_path: Path) -> None:
    t = np.arange(200_000) / FS
    mdf = MDF(version="4.10")
    mdf.append([Signal(np.zeros(t.size), t, name="Z11"), Signal(np.full(t.size, 20.0), t, name="speed")])
    mdf.save(tmp_path / "zeros.mf4", overwrite=True, compression=1)
    size = (tmp_path / "zeros.mf4").stat().st_size
    tight = IngestLimits(max_expansion_ratio=1.0, expansion_floor_bytes=1)
    assert size < 200_000 * 24 / 4  # compressed well below the decoded size
    with pytest.raises(RunFileError) as exc:
        ingest(tmp_path / "zeros.mf4", None, _meta(), tmp_path / "z.h5", tight)
    assert exc.value.field == "file" and "decompression bomb" in exc.value.message
    with pytest.raises(RunFileError) as exc:
        ingest(tmp_path / "zeros.mf4", None, _meta(), tmp_path / "z.h5",
               IngestLimits(max_recorder_channels=2))
    assert exc.value.field == "file" and "channels" in exc.value.message


def test_mdf4_lying_dz_block_is_refused(tmp_path: Path) -> None:
    """A DZ stream that inflates to more than it declares is refused before asammdf reads it."""
    import zlib

    from app.io.sources.mdf4_blocks import inflate_exactly

    payload = zlib.compress(b"\0" * 100_000)
    path = tmp_path / "blob"
    path.write_bytes(b"xx" + payload)
    with open(path, "rb") as fh:
        inflate_exactly(fh, 2, len(payload), 100_000, "DZ")
        with pytest.raises(RunFileError, match="decompression bomb"):
            inflate_exactly(fh, 2, len(payload), 1000, "DZ")
        with pytest.raises(RunFileError, match="inflates to 100000 bytes but declares"):
            inflate_exactly(fh, 2, len(payload), 200_000, "DZ")


def test_channel_map_validation_and_units() -> None:
    assert unit_factor("speed", "km/h") == pytest.approx(1 / 3.6)
    assert unit_factor("Z11", "g") == pytest.approx(9.80665)
    assert unit_factor("Q11", "N") == pytest.approx(1e-3)
    assert unit_factor("position", "km") == 1000.0
    for bad, field in (
        ({"channels": {"X1": "a"}}, "channel_map.channels"),
        ({"channels": {"speed": "v"}}, "channel_map"),
        ({"channels": {"Z11": "a", "Z12": "a"}}, "channel_map"),
        ({"channels": {"Z11": "a", "lat": "b"}}, "channel_map"),
        ({"channels": {"Z11": {"source": "a", "unit": "furlong"}}}, "channel_map.channels"),
    ):
        with pytest.raises(RunFileError) as exc:
            parse_channel_map(bad)
        assert exc.value.field == field, (bad, exc.value)
    cmap = parse_channel_map({"channels": {"z11": "a"}})
    assert list(cmap.channels) == ["Z11"]


def test_channel_map_is_refused_for_run_file_formats(tmp_path: Path) -> None:
    csv = tmp_path / "run.csv"
    csv.write_text("Z11,speed\n0.1,20\n0.2,20\n")
    with pytest.raises(RunFileError) as exc:
        ingest(csv, None, _meta(sample_rate_hz=FS), tmp_path / "c.h5", channel_map=CMAP)
    assert exc.value.field == "channel_map"


def test_default_axle_layout_is_reported(tmp_path: Path) -> None:
    src = _mdf(tmp_path / "run.mf4")
    s = ingest(src, None, _meta(), tmp_path / "a.h5", channel_map=CMAP)
    assert any(w.startswith("axle_positions: not given") for w in s.warnings)
    s = ingest(src, None, _meta(axle_positions={"1": 0.0, "4": -17.5}), tmp_path / "b.h5",
               channel_map=CMAP)
    assert not any(w.startswith("axle_positions") for w in s.warnings)
    json.dumps(s.report)



def test_tdms_object_limit(tmp_path: Path) -> None:
    path = tmp_path / "big.tdms"
    with TdmsWriter(path) as w:
        w.write_segment([GroupObject("ABA"), ChannelObject(
            "ABA", "Z11", np.zeros(1000), {"wf_increment": 1 / FS})])
    with pytest.raises(RunFileError) as exc:
        ingest(path, None, _meta(), tmp_path / "t.h5", IngestLimits(max_recorder_channels=1))
    assert exc.value.field == "file" and "exceed the limit" in exc.value.message
