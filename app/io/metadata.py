"""Run metadata: the model, its defaults and its validation."""

from __future__ import annotations

import datetime as dt
import math
from collections.abc import Mapping
from typing import Any, Literal

import pydantic
from pydantic import AliasChoices, AwareDatetime, ConfigDict, Field, StrictBool, field_validator

from app.core.errors import pydantic_message
from app.core.i18n import _
from app.io.channels import ALL_CHANNELS, AXLES, WHEELS
from app.io.errors import RunFileError
from app.io.json_input import load_json

__all__ = [
    "Calibration",
    "PositionKind",
    "POSITION_KINDS",
    "RunMetadata",
    "DEFAULT_WHEEL_DIAMETER_M",
    "DEFAULT_SLEEPER_SPACING_M",
    "DEFAULT_AXLE_POSITIONS_M",
    "MAX_METADATA_DEPTH",
    "START_TIME_RANGE",
    "load_metadata_json",
    "parse_metadata",
]

#: Nominal wheel diameter, m.
DEFAULT_WHEEL_DIAMETER_M = 0.92
#: Nominal sleeper spacing, m.
DEFAULT_SLEEPER_SPACING_M = 0.6
#: Axle positions relative to the position reference, m (axle 4 runs 17.5 m behind axle 1).
DEFAULT_AXLE_POSITIONS_M: dict[str, float] = {"1": 0.0, "4": -17.5}
#: Deepest nesting of objects and arrays accepted in metadata (the top-level object is 1).
MAX_METADATA_DEPTH = 32
#: Accepted start times (UTC): [first, last).
START_TIME_RANGE: tuple[dt.datetime, dt.datetime] = (
    dt.datetime(1900, 1, 1, tzinfo=dt.UTC),
    dt.datetime(2200, 1, 1, tzinfo=dt.UTC),
)
#: What the ``position`` channel of an input file is (see :class:`RunMetadata`).
PositionKind = Literal["relative", "line_km", "gnss"]
POSITION_KINDS: tuple[str, ...] = ("relative", "line_km", "gnss")


def _finite(value: float, what: str) -> float:
    if not math.isfinite(value):
        raise ValueError(_("{what} must be finite, got {value!r}", what=what, value=value))
    return value


class Calibration(pydantic.BaseModel):
    """Linear calibration of one channel: ``physical = gain * raw + offset``.

    Attributes
    ----------
    gain : float
        Physical units per raw unit; finite and non-zero.
    offset : float
        Physical units; finite.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    gain: float = 1.0
    offset: float = 0.0

    @field_validator("gain")
    @classmethod
    def _gain(cls, v: float) -> float:
        _finite(v, "gain")
        if v == 0.0:
            raise ValueError(_("gain must be non-zero"))
        return v

    @field_validator("offset")
    @classmethod
    def _offset(cls, v: float) -> float:
        return _finite(v, "offset")

    def __getitem__(self, key: str) -> float:
        """Mapping-style access, ``cal["gain"]``, as for the JSON form."""
        if key not in ("gain", "offset"):
            raise KeyError(key)
        return float(getattr(self, key))


def _to_str(v: Any) -> Any:
    if isinstance(v, bool):
        return v
    if isinstance(v, float) and not math.isfinite(v):
        raise ValueError(_("must be text or a finite number, got {value!r}", value=v))
    if isinstance(v, int | float):
        return str(v)
    return v


class RunMetadata(pydantic.BaseModel):
    """Descriptive data of one measurement run.

    Attributes
    ----------
    vehicle_id : str
        Id of the measuring vehicle.
    start_time : datetime
        Start of the run, ISO 8601 **with** time zone (naive times are rejected).
    line_id : str
        Id of the railway line.
    track : str
        Track id on the line (e.g. ``"1"``).
    direction : str
        Direction of travel as named by the operator (free text, e.g. ``"up"``).
    position_kind : {"relative", "line_km", "gnss"} or None
        What gives the line km of the run (:mod:`app.io.positioning`):
        ``relative`` — the position channel (or the integrated speed) is the
        distance travelled since the start, and ``km_start``/``km_increasing``
        place it on the line (a channel not starting at 0 is reported);
        ``line_km`` — the position channel is the line chainage itself, m
        (line km × 1000; increasing or decreasing), ``km_start`` and
        ``km_increasing`` are taken from it; ``gnss`` — ``lat``/``lon``
        channels are matched onto the line geometry and fused with the
        odometry. ``None``: ``gnss`` when the file has GNSS channels and no
        ``km_start`` is given, else ``relative``. Canonical files always say
        ``relative``.
    km_start : float or None
        Line km of the position reference (axle 1 by default) at the first
        sample, km. Required for ``relative`` positions; derived otherwise.
    km_increasing : bool or None
        Whether the line km increases along the run. Required for
        ``relative`` positions; derived otherwise.
    wheel_diameters : dict[str, float]
        Diameter per wheel (keys ``"11"``, ``"12"``, ``"41"``, ``"42"``), m, in
        (0.3, 1.5); missing wheels get 0.92 m.
    sleeper_spacing : float
        Sleeper spacing, m, in [0.3, 1.0]; default 0.6.
    axle_positions : dict[str, float]
        Axle positions relative to the position reference (keys ``"1"``, ``"4"``),
        m, positive ahead; default ``{"1": 0.0, "4": -17.5}``; a missing axle
        gets its default.
    calibration : dict[str, Calibration]
        Per-channel calibration (``physical = gain * raw + offset``); channels
        not listed use gain 1, offset 0.
    sample_rate_hz : float or None
        Sample rate, Hz. Input files may give it here, as an HDF5 attribute or
        through a ``time`` column; ingest fills it in.
    extra : dict
        Free, JSON-serialisable information (operator, notes …); not interpreted.
    """

    model_config = ConfigDict(extra="forbid", validate_assignment=True, populate_by_name=True)

    vehicle_id: str = Field(min_length=1, max_length=200)
    start_time: AwareDatetime
    line_id: str = Field(min_length=1, max_length=200)
    track: str = Field(min_length=1, max_length=100)
    direction: str = Field(min_length=1, max_length=100)
    position_kind: PositionKind | None = None
    km_start: float | None = None
    km_increasing: StrictBool | None = None
    wheel_diameters: dict[str, float] = Field(
        default_factory=lambda: dict.fromkeys(WHEELS, DEFAULT_WHEEL_DIAMETER_M)
    )
    sleeper_spacing: float = DEFAULT_SLEEPER_SPACING_M
    axle_positions: dict[str, float] = Field(default_factory=lambda: dict(DEFAULT_AXLE_POSITIONS_M))
    calibration: dict[str, Calibration] = Field(default_factory=dict)
    sample_rate_hz: float | None = Field(
        default=None, validation_alias=AliasChoices("sample_rate_hz", "sample_rate")
    )
    extra: dict[str, Any] = Field(default_factory=dict)

    @field_validator("vehicle_id", "line_id", "track", "direction", mode="before")
    @classmethod
    def _strings(cls, v: Any) -> Any:
        v = _to_str(v)
        return v.strip() if isinstance(v, str) else v

    @field_validator("start_time")
    @classmethod
    def _start_time(cls, v: dt.datetime) -> dt.datetime:
        first, last = START_TIME_RANGE
        try:
            utc = v.astimezone(dt.UTC)
        except OverflowError:
            utc = None
        if utc is None or not first <= utc < last:
            raise ValueError(
                _("start time must lie between {first} and {last} (UTC), got {value}", first=first.strftime("%Y-%m-%d"),
                  last=last.strftime("%Y-%m-%d"), value=v.isoformat())
            )
        return v

    @field_validator("km_start")
    @classmethod
    def _km(cls, v: float | None) -> float | None:
        if v is None:
            return v
        _finite(v, "km_start")
        if abs(v) > 100_000:
            raise ValueError(_("km_start must be within ±100000 km, got {value}", value=v))
        return v

    @field_validator("wheel_diameters")
    @classmethod
    def _wheels(cls, v: dict[str, float]) -> dict[str, float]:
        out = dict.fromkeys(WHEELS, DEFAULT_WHEEL_DIAMETER_M)
        for key, d in v.items():
            if key not in WHEELS:
                raise ValueError(_("unknown wheel {key!r}; wheels are {wheels}", key=key, wheels=", ".join(WHEELS)))
            if not (math.isfinite(d) and 0.3 < d < 1.5):
                raise ValueError(_("diameter of wheel {key} must be in (0.3, 1.5) m, got {value}", key=key, value=d))
            out[key] = float(d)
        return out

    @field_validator("sleeper_spacing")
    @classmethod
    def _spacing(cls, v: float) -> float:
        if not (math.isfinite(v) and 0.3 <= v <= 1.0):
            raise ValueError(_("sleeper_spacing must be in [0.3, 1.0] m, got {value}", value=v))
        return v

    @field_validator("axle_positions")
    @classmethod
    def _axles(cls, v: dict[str, float]) -> dict[str, float]:
        out = dict(DEFAULT_AXLE_POSITIONS_M)
        for key, x in v.items():
            if key not in AXLES:
                raise ValueError(_("unknown axle {key!r}; axles are {axles}", key=key, axles=", ".join(AXLES)))
            if not (math.isfinite(x) and abs(x) <= 100.0):
                raise ValueError(_("position of axle {key} must be within ±100 m, got {value}", key=key, value=x))
            out[key] = float(x)
        return out

    @field_validator("calibration")
    @classmethod
    def _calibration(cls, v: dict[str, Calibration]) -> dict[str, Calibration]:
        for key in v:
            if key not in ALL_CHANNELS:
                raise ValueError(
                    _("calibration for unknown channel {key!r}; channels are {channels}", key=key, channels=", ".join(ALL_CHANNELS))
                )
        return v

    @field_validator("sample_rate_hz")
    @classmethod
    def _fs(cls, v: float | None) -> float | None:
        if v is not None and not (math.isfinite(v) and v > 0):
            raise ValueError(_("sample rate must be a finite number > 0 Hz, got {value}", value=v))
        return v

    def gain_offset(self, channel: str) -> tuple[float, float]:
        """Calibration ``(gain, offset)`` of a channel (``(1.0, 0.0)`` if none)."""
        cal = self.calibration.get(channel)
        return (1.0, 0.0) if cal is None else (cal.gain, cal.offset)

    def to_json(self) -> str:
        """The metadata as a JSON string (the form stored in the canonical file)."""
        return self.model_dump_json()


def _field_of(loc: tuple[Any, ...]) -> str:
    return ".".join(str(p) for p in loc) or "metadata"


def parse_metadata(data: Mapping[str, Any] | RunMetadata | None) -> RunMetadata:
    """Validate a metadata mapping into :class:`RunMetadata`.

    Parameters
    ----------
    data : mapping or RunMetadata
        Metadata fields (see :class:`RunMetadata`).

    Returns
    -------
    RunMetadata

    Raises
    ------
    RunFileError
        ``field`` is the offending metadata field (``"start_time"``,
        ``"wheel_diameters"``, …) or ``"metadata"`` if ``data`` is missing or not
        a mapping.
    """
    if isinstance(data, RunMetadata):
        return data
    if data is None:
        raise RunFileError("metadata", _("metadata is required (vehicle_id, start_time, line_id, …)"))
    if not isinstance(data, Mapping):
        raise RunFileError("metadata", _("metadata must be a JSON object, got {kind}", kind=type(data).__name__))
    _check_json_values(data, "", 1)
    try:
        return RunMetadata.model_validate(dict(data))
    except pydantic.ValidationError as exc:
        err = exc.errors()[0]
        field = _field_of(tuple(err.get("loc", ())))
        msg = pydantic_message(err)
        if err.get("type") == "timezone_aware":
            msg = _("start time must include a time zone (ISO 8601, e.g. 2024-05-01T08:00:00+02:00)")
        elif err.get("type") == "missing":
            msg = _("required field is missing")
        elif err.get("type") == "extra_forbidden":
            msg = _("unknown metadata field")
        elif err.get("type") == "bool_type":
            msg = _("must be true or false (a JSON boolean)")
        given = err.get("input")
        shown = _shown(given)
        if (
            err.get("type") != "missing"
            and given is not None
            and len(shown) < 80
            and "got" not in msg
        ):
            msg = _("{message} (got {value})", message=msg, value=shown)
        raise RunFileError(field, msg) from None


def _shown(value: Any, limit: int = 80) -> str:
    """``repr(value)`` cut to ``limit`` characters (messages never echo large inputs)."""
    text = repr(value) if not isinstance(value, dict | list) else type(value).__name__
    return text if len(text) <= limit else text[: limit - 1] + "…"


def _check_json_values(value: Any, path: str, depth: int) -> None:
    """Refuse what JSON cannot hold or a database cannot store, naming the field.

    Non-finite numbers (``NaN``, ``Infinity``, ``1e400``), NUL characters in
    strings or keys (PostgreSQL text cannot hold them) and nesting deeper than
    :data:`MAX_METADATA_DEPTH`.
    """
    field = path or "metadata"
    if isinstance(value, float):
        if not math.isfinite(value):
            raise RunFileError(field, _("must be a finite number, got {value} (out of range or not a number)", value=repr(value)))
    elif isinstance(value, str):
        if "\x00" in value:
            raise RunFileError(field, _("must not contain NUL characters (\\u0000)"))
    elif isinstance(value, Mapping | list | tuple):
        if depth > MAX_METADATA_DEPTH:
            raise RunFileError(field, _("nested deeper than {n} levels", n=MAX_METADATA_DEPTH))
        items = value.items() if isinstance(value, Mapping) else enumerate(value)
        for key, item in items:
            if isinstance(key, str) and "\x00" in key:
                raise RunFileError(field, _("keys must not contain NUL characters (\\u0000)"))
            _check_json_values(item, f"{path}.{key}" if path else str(key), depth + 1)


def load_metadata_json(text: str | bytes, *, field: str = "metadata") -> dict[str, Any]:
    """Parse a metadata JSON document (form field, query parameter, HDF5 attribute).

    Parameters
    ----------
    text : str or bytes
        The JSON text (bytes are decoded as UTF-8).
    field : str
        Name reported for problems of the document as a whole.

    Returns
    -------
    dict
        The object. Numbers too large for a float come back as ``inf`` and
        ``NaN``/``Infinity`` literals as floats: :func:`parse_metadata` refuses
        them naming their field.

    Raises
    ------
    RunFileError
        ``field`` for text that is not UTF-8, not JSON, not an object, or
        nested deeper than :data:`MAX_METADATA_DEPTH` (checked before parsing,
        so a document nested 100 000 deep costs no recursion).
    """
    value = load_json(text, field=field, max_depth=MAX_METADATA_DEPTH)
    if not isinstance(value, dict):
        raise RunFileError(field, _("must be a JSON object, got {kind}", kind=type(value).__name__))
    return value
