"""Channel maps: which recorder channel is which trackvkf channel, and in what unit.

Measurement systems (Vector, IPETRONIK, HBK, imc, NI) name their channels as
their users configure them (``AccZ_Axle1_R``, ``v_train``, ``GPS_Lat``). A
channel map names, for each trackvkf channel (``Z11`` … ``Z42``, ``Q11`` …
``Q42``, ``speed``, ``position``, ``lat``, ``lon``), the recorder channel that
holds it, optionally the group it sits in (when a name occurs in several
groups) and its unit (when the file does not say, or says it wrongly)::

    {"name": "ICE-1 IPETRONIK",
     "channels": {"Z11": {"source": "AccZ_1R", "unit": "g"},
                  "Z12": "AccZ_1L",
                  "speed": {"source": "v_train", "group": "CAN1", "unit": "km/h"},
                  "lat": "GPS_Lat", "lon": "GPS_Lon"}}

A plain string is short for ``{"source": <string>}``. Values are converted to
trackvkf's units (:data:`app.io.channels.UNITS`) with :func:`unit_factor`:
g → m/s², km/h → m/s, N → kN, km → m, rad → deg.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import pydantic
from pydantic import ConfigDict, Field, field_validator, model_validator

from app.analysis.units import KMH_PER_MPS
from app.core.errors import pydantic_message
from app.core.i18n import _
from app.io.channels import (
    ACCEL_CHANNELS,
    INPUT_CHANNELS,
    UNIT_SYNONYMS,
    UNITS,
    canonical_name,
)
from app.io.errors import RunFileError

__all__ = [
    "STANDARD_GRAVITY",
    "UNIT_FACTORS",
    "ChannelSource",
    "ChannelMap",
    "RecorderChannel",
    "MappedChannel",
    "parse_channel_map",
    "unit_factor",
    "resolve_channels",
]

#: Standard acceleration of gravity, m/s² (1 g).
STANDARD_GRAVITY = 9.80665

#: Unit spelling (lower case) → factor to trackvkf's unit, per trackvkf unit.
UNIT_FACTORS: dict[str, dict[str, float]] = {
    "m/s^2": {
        **{u.lower(): 1.0 for u in UNIT_SYNONYMS["m/s^2"]},
        "g": STANDARD_GRAVITY,
        "gn": STANDARD_GRAVITY,
        "g0": STANDARD_GRAVITY,
        "mg": STANDARD_GRAVITY / 1000.0,
        "mm/s^2": 1e-3,
        "mm/s²": 1e-3,
    },
    "kN": {"kn": 1.0, "n": 1e-3, "dan": 1e-2},
    "m/s": {
        **{u.lower(): 1.0 for u in UNIT_SYNONYMS["m/s"]},
        "km/h": 1.0 / KMH_PER_MPS,
        "kmh": 1.0 / KMH_PER_MPS,
        "kph": 1.0 / KMH_PER_MPS,
        "km/hr": 1.0 / KMH_PER_MPS,
        "km h-1": 1.0 / KMH_PER_MPS,
        "mph": 0.44704,
    },
    "m": {"m": 1.0, "km": 1000.0, "mm": 1e-3, "cm": 1e-2},
    "deg": {**{u.lower(): 1.0 for u in UNIT_SYNONYMS["deg"]}, "rad": 180.0 / math.pi},
    "s": {"s": 1.0, "ms": 1e-3},
}


def unit_factor(channel: str, unit: str | None) -> float:
    """Factor from ``unit`` to trackvkf's unit of ``channel``.

    Parameters
    ----------
    channel : str
        trackvkf channel name (``"Z11"``, ``"speed"``, ``"lat"`` …).
    unit : str or None
        Unit of the recorder values; ``None`` or empty means trackvkf's unit.

    Returns
    -------
    float
        Multiply recorder values by it (``g`` → 9.80665 for ``Z11``).

    Raises
    ------
    RunFileError
        ``field`` is ``channel`` when the unit cannot be converted.
    """
    want = UNITS[channel]
    if unit is None or not str(unit).strip():
        return 1.0
    key = str(unit).strip().lower()
    table = UNIT_FACTORS[want]
    if key not in table:
        raise RunFileError(
            channel,
            _("unit {unit} cannot be converted to {want}; accepted: {accepted}", unit=repr(str(unit)[:40]), want=want,
              accepted=", ".join(sorted(table))),
        )
    return table[key]


def _without_nul(value: str | None) -> str | None:
    """Text a database can store: NUL characters are refused (PostgreSQL text cannot hold them)."""
    if value is not None and "\x00" in value:
        raise ValueError(_("must not contain NUL characters (\\u0000)"))
    return value


class ChannelSource(pydantic.BaseModel):
    """The recorder channel behind one trackvkf channel.

    Attributes
    ----------
    source : str
        Recorder channel name, as in the file (case-sensitive).
    group : str or None
        Group (MDF4 channel group acquisition name or comment, or its index;
        TDMS group name) when the name occurs in several groups.
    unit : str or None
        Unit of the recorder values; overrides the unit stored in the file.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    source: str = Field(min_length=1, max_length=200)
    group: str | None = Field(default=None, max_length=200)
    unit: str | None = Field(default=None, max_length=40)

    @field_validator("source", "group", "unit")
    @classmethod
    def _no_nul(cls, value: str | None) -> str | None:
        return _without_nul(value)


class ChannelMap(pydantic.BaseModel):
    """A channel map (see the module docstring).

    Attributes
    ----------
    name : str
        Free label (e.g. the recorder configuration).
    channels : dict[str, ChannelSource]
        trackvkf channel → recorder channel; at least one ABA channel (``Z..``).
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    name: str = Field(default="", max_length=200)
    channels: dict[str, ChannelSource]

    @field_validator("name")
    @classmethod
    def _no_nul(cls, value: str) -> str:
        return _without_nul(value)

    @field_validator("channels", mode="before")
    @classmethod
    def _short_form(cls, value: Any) -> Any:
        if isinstance(value, Mapping):
            return {k: {"source": v} if isinstance(v, str) else v for k, v in value.items()}
        return value

    @field_validator("channels")
    @classmethod
    def _targets(cls, value: dict[str, ChannelSource]) -> dict[str, ChannelSource]:
        out: dict[str, ChannelSource] = {}
        for key, spec in value.items():
            canon = canonical_name(key)
            if canon not in INPUT_CHANNELS:
                raise ValueError(
                    _("unknown trackvkf channel {key!r}; channels are {channels}", key=key, channels=", ".join(INPUT_CHANNELS))
                )
            if canon in out:
                raise ValueError(_("channel {channel} given twice", channel=canon))
            unit_factor(canon, spec.unit)
            out[canon] = spec
        return out

    @model_validator(mode="after")
    def _check(self) -> ChannelMap:
        if not any(c in self.channels for c in ACCEL_CHANNELS):
            raise ValueError(_("maps no ABA channel; map at least one of {channels}", channels=", ".join(ACCEL_CHANNELS)))
        seen: dict[tuple[str, str | None], str] = {}
        for canon, spec in self.channels.items():
            key = (spec.source, spec.group)
            if key in seen:
                raise ValueError(
                    _("recorder channel {source!r} is mapped to both {first} and {second}", source=spec.source, first=seen[key],
                      second=canon)
                )
            seen[key] = canon
        if ("lat" in self.channels) != ("lon" in self.channels):
            raise ValueError(_("map both lat and lon, or neither"))
        return self


def parse_channel_map(data: Mapping[str, Any] | ChannelMap) -> ChannelMap:
    """Validate a channel map given as a mapping (JSON object).

    Raises
    ------
    RunFileError
        ``field`` is ``channel_map`` or ``channel_map.<path>`` of the bad entry.
    """
    if isinstance(data, ChannelMap):
        return data
    if not isinstance(data, Mapping):
        raise RunFileError("channel_map", _("must be a JSON object, got {kind}", kind=type(data).__name__))
    try:
        return ChannelMap.model_validate(dict(data))
    except pydantic.ValidationError as exc:
        err = exc.errors()[0]
        loc = ".".join(str(p) for p in err.get("loc", ()))
        msg = pydantic_message(err)
        if err.get("type") == "missing":
            msg = _("required field is missing")
        elif err.get("type") == "extra_forbidden":
            msg = _("unknown field")
        raise RunFileError(f"channel_map.{loc}" if loc else "channel_map", msg) from None


@dataclass(frozen=True)
class RecorderChannel:
    """A channel of a recorder file as its reader lists it.

    Attributes
    ----------
    name : str
        Channel name in the file.
    group : str
        Group name (MDF4: acquisition name or comment of the channel group,
        else ``"group <i>"``; TDMS: group name).
    group_index : int
        Position of the group in the file.
    unit : str
        Unit stored in the file (``""`` if none).
    key : Any
        Reader's handle of the channel.
    """

    name: str
    group: str
    group_index: int
    unit: str
    key: Any


@dataclass(frozen=True)
class MappedChannel:
    """A recorder channel chosen for a trackvkf channel, with its unit factor."""

    channel: RecorderChannel
    unit: str
    factor: float

    def describe(self) -> dict[str, Any]:
        """JSON form kept with the run (where each stored channel came from)."""
        return {
            "source": self.channel.name,
            "group": self.channel.group,
            "unit": self.unit,
            "factor": self.factor,
        }


def _in_group(ch: RecorderChannel, group: str) -> bool:
    return ch.group == group or str(ch.group_index) == group


def _list(names: Sequence[str], limit: int = 12) -> str:
    shown = ", ".join(repr(n) for n in names[:limit])
    return shown + (f" … ({len(names)} in all)" if len(names) > limit else "")


def resolve_channels(
    available: Sequence[RecorderChannel], channel_map: ChannelMap | None
) -> dict[str, MappedChannel]:
    """Choose the recorder channel of every trackvkf channel.

    Without a map, recorder channels named like trackvkf channels (``Z11``,
    ``speed``, ``lat`` …, case-insensitive) are taken; other channels are
    ignored. With a map, exactly the mapped channels are taken.

    Parameters
    ----------
    available : sequence of RecorderChannel
        Numeric data channels of the file (no time/master channels).
    channel_map : ChannelMap or None
        The map to apply.

    Returns
    -------
    dict[str, MappedChannel]
        trackvkf channel → recorder channel and unit factor.

    Raises
    ------
    RunFileError
        Naming the recorder channel for a mapped channel missing from the file,
        a name found in several groups (ambiguous; give ``group``) or a unit
        that cannot be converted; ``channel_map`` when no ABA channel can be
        mapped (the message lists the file's unmapped channels).
    """
    out: dict[str, MappedChannel] = {}
    if channel_map is None:
        for ch in available:
            canon = canonical_name(ch.name)
            if canon is None or canon not in INPUT_CHANNELS:
                continue
            if canon in out:
                other = out[canon].channel
                raise RunFileError(
                    ch.name,
                    _("ambiguous channel: found in groups {first} and {second}; give a channel map naming the group",
                      first=repr(other.group), second=repr(ch.group)),
                )
            out[canon] = MappedChannel(ch, ch.unit, unit_factor(canon, ch.unit))
    else:
        for canon, spec in channel_map.channels.items():
            found = [
                ch
                for ch in available
                if ch.name == spec.source and (spec.group is None or _in_group(ch, spec.group))
            ]
            if not found:
                raise RunFileError(
                    spec.source,
                    _("channel of the channel map ({channel}) not found in the file", channel=canon)
                    if spec.group is None else
                    _("channel of the channel map ({channel}) not found in the file in group {group}", channel=canon,
                      group=repr(spec.group)),
                )
            if len(found) > 1:
                groups = ", ".join(repr(ch.group) for ch in found)
                raise RunFileError(
                    spec.source,
                    _("ambiguous channel ({channel}): found in groups {groups}; give 'group' in the channel map",
                      channel=canon, groups=groups),
                )
            ch = found[0]
            unit = spec.unit if spec.unit is not None else ch.unit
            try:
                factor = unit_factor(canon, unit)
            except RunFileError as exc:
                raise RunFileError(spec.source, _("{problem} (channel {channel})", problem=exc.message, channel=canon)) from None
            out[canon] = MappedChannel(ch, unit or UNITS[canon], factor)
    if not any(c in out for c in ACCEL_CHANNELS):
        used = {id(m.channel) for m in out.values()}
        unmapped = [ch.name for ch in available if id(ch) not in used]
        raise RunFileError(
            "channel_map",
            _("no ABA channel ({channels}) is mapped; unmapped channels of the file: {unmapped}",
              channels=", ".join(ACCEL_CHANNELS), unmapped=_list(unmapped) or _("none"))
            if channel_map is not None else
            _("no ABA channel ({channels}) is mapped; unmapped channels of the file: {unmapped}; give a channel map",
              channels=", ".join(ACCEL_CHANNELS), unmapped=_list(unmapped) or _("none")),
        )
    if ("lat" in out) != ("lon" in out):
        missing = "lon" if "lat" in out else "lat"
        raise RunFileError(missing, _("GNSS needs both lat and lon channels"))
    return {c: out[c] for c in (*INPUT_CHANNELS,) if c in out}

