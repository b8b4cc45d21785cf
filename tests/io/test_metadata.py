"""RunMetadata validation: defaults, errors that name the field."""

from __future__ import annotations

import pytest

from app.io import RunFileError, RunMetadata, parse_metadata
from tests.io.conftest import base_meta


def test_defaults_are_filled() -> None:
    meta = parse_metadata(base_meta())
    assert meta.wheel_diameters == {"11": 0.92, "12": 0.92, "41": 0.92, "42": 0.92}
    assert meta.sleeper_spacing == 0.6
    assert meta.axle_positions == {"1": 0.0, "4": -17.5}
    assert meta.calibration == {}
    assert meta.start_time.utcoffset().total_seconds() == 7200


def test_partial_dicts_keep_other_defaults_and_numbers_become_strings() -> None:
    meta = parse_metadata(
        base_meta(wheel_diameters={"41": 0.87}, axle_positions={"4": -15.0}, track=2, line_id=4711)
    )
    assert meta.wheel_diameters == {"11": 0.92, "12": 0.92, "41": 0.87, "42": 0.92}
    assert meta.axle_positions == {"1": 0.0, "4": -15.0}
    assert meta.track == "2" and meta.line_id == "4711"


def test_sample_rate_alias() -> None:
    assert parse_metadata(base_meta(sample_rate=24000)).sample_rate_hz == 24000.0


def test_json_round_trip() -> None:
    meta = parse_metadata(base_meta(calibration={"Z11": {"gain": 0.01, "offset": -0.5}}))
    again = RunMetadata.model_validate_json(meta.to_json())
    assert again == meta
    assert again.gain_offset("Z11") == (0.01, -0.5)
    assert again.gain_offset("Z12") == (1.0, 0.0)


@pytest.mark.parametrize(
    ("change", "field", "words"),
    [
        ({"start_time": "2024-05-01T08:00:00"}, "start_time", "time zone"),
        ({"start_time": "yesterday"}, "start_time", ""),
        ({"vehicle_id": ""}, "vehicle_id", ""),
        ({"km_start": float("nan")}, "km_start", "finite"),
        ({"km_increasing": "sideways"}, "km_increasing", ""),
        ({"wheel_diameters": {"11": 9.2}}, "wheel_diameters", "0.3, 1.5"),
        ({"wheel_diameters": {"13": 0.9}}, "wheel_diameters", "unknown wheel"),
        ({"sleeper_spacing": 6.0}, "sleeper_spacing", "0.3, 1.0"),
        ({"axle_positions": {"2": 3.0}}, "axle_positions", "unknown axle"),
        ({"calibration": {"Z99": {"gain": 1.0}}}, "calibration", "unknown channel"),
        ({"calibration": {"Z11": {"gain": 0.0}}}, "calibration.Z11.gain", "non-zero"),
        ({"calibration": {"Z11": {"gain": 1.0, "scale": 2}}}, "calibration.Z11.scale", "unknown"),
        ({"sample_rate_hz": -5}, "sample_rate_hz", "> 0"),
        ({"colour": "red"}, "colour", "unknown metadata field"),
    ],
)
def test_bad_fields_are_named(change: dict, field: str, words: str) -> None:
    with pytest.raises(RunFileError) as info:
        parse_metadata(base_meta(**change))
    assert info.value.field == field
    assert words in info.value.message
    assert str(info.value) == f"{field}: {info.value.message}"


def test_missing_field_is_named() -> None:
    meta = base_meta()
    del meta["line_id"]
    with pytest.raises(RunFileError) as info:
        parse_metadata(meta)
    assert info.value.field == "line_id"
    assert "missing" in info.value.message


def test_missing_metadata() -> None:
    with pytest.raises(RunFileError) as info:
        parse_metadata(None)
    assert info.value.field == "metadata"
    with pytest.raises(RunFileError):
        parse_metadata(["not", "a", "dict"])  # type: ignore[arg-type]
