"""Channel names, units and storage types of a run.

Names follow the field convention *direction letter + axle + side*:
``Z11`` is the vertical axle-box acceleration of axle 1, side 1 (right);
``Z42`` is axle 4, side 2 (left). ``Q..`` are the vertical wheel–rail forces of
the same wheels.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "WHEELS",
    "AXLES",
    "ACCEL_CHANNELS",
    "FORCE_CHANNELS",
    "KINEMATIC_CHANNELS",
    "ALL_CHANNELS",
    "TIME_COLUMN",
    "GNSS_CHANNELS",
    "INPUT_CHANNELS",
    "UNITS",
    "UNIT_SYNONYMS",
    "canonical_name",
    "storage_dtype",
    "wheel_axle",
]

#: Wheel ids: axle digit + side digit (side 1 = right, side 2 = left).
WHEELS: tuple[str, ...] = ("11", "12", "41", "42")
#: Axle ids used by the wheels.
AXLES: tuple[str, ...] = ("1", "4")
#: Vertical axle-box accelerations, m/s².
ACCEL_CHANNELS: tuple[str, ...] = tuple(f"Z{w}" for w in WHEELS)
#: Vertical wheel–rail forces, kN.
FORCE_CHANNELS: tuple[str, ...] = tuple(f"Q{w}" for w in WHEELS)
#: Vehicle speed (m/s) and position along the run (m).
KINEMATIC_CHANNELS: tuple[str, ...] = ("speed", "position")
#: Every channel name a run may hold, in canonical order.
ALL_CHANNELS: tuple[str, ...] = ACCEL_CHANNELS + FORCE_CHANNELS + KINEMATIC_CHANNELS
#: Optional time column of CSV/Parquet/HDF5 input (s); used to check or derive
#: the sample rate, never stored.
TIME_COLUMN = "time"

#: Optional GNSS fix of the vehicle, WGS84 latitude and longitude (degrees); read to
#: place the run on the line geometry (:mod:`app.io.positioning`), never stored. Samples
#: without a fix are NaN.
GNSS_CHANNELS: tuple[str, ...] = ("lat", "lon")
#: Every channel an input file may hold besides ``time``: the stored ones and GNSS.
INPUT_CHANNELS: tuple[str, ...] = ALL_CHANNELS + GNSS_CHANNELS

#: Physical unit of every channel (stored as the ``units`` attribute).
UNITS: dict[str, str] = {
    **{c: "m/s^2" for c in ACCEL_CHANNELS},
    **{c: "kN" for c in FORCE_CHANNELS},
    "speed": "m/s",
    "position": "m",
    "lat": "deg",
    "lon": "deg",
    TIME_COLUMN: "s",
}

#: Unit spellings accepted in the ``units`` attribute of HDF5 input datasets.
UNIT_SYNONYMS: dict[str, frozenset[str]] = {
    "m/s^2": frozenset({"m/s^2", "m/s²", "m/s**2", "m s-2", "m*s^-2", "m/s/s", "ms-2", "m/s2"}),
    "kN": frozenset({"kn"}),
    "m/s": frozenset({"m/s", "m s-1", "m*s^-1", "ms-1"}),
    "m": frozenset({"m"}),
    "s": frozenset({"s"}),
    "deg": frozenset({"deg", "°", "degree", "degrees"}),
}

_LOOKUP: dict[str, str] = {name.lower(): name for name in (*INPUT_CHANNELS, TIME_COLUMN)}


def canonical_name(name: str) -> str | None:
    """Canonical spelling of a channel name, matched case-insensitively.

    Parameters
    ----------
    name : str
        A column or dataset name from an input file.

    Returns
    -------
    str or None
        ``"Z11"``, ``"speed"``, ``"time"`` …, or ``None`` if the name is unknown.
    """
    return _LOOKUP.get(str(name).strip().lower())


def storage_dtype(name: str) -> np.dtype:
    """HDF5 storage type of a channel: float32 for Z/Q, float64 for speed/position."""
    if name in KINEMATIC_CHANNELS:
        return np.dtype(np.float64)
    if name in ACCEL_CHANNELS or name in FORCE_CHANNELS:
        return np.dtype(np.float32)
    raise ValueError(f"name: unknown channel {name!r}")


def wheel_axle(wheel: str) -> str:
    """Axle id (``"1"`` or ``"4"``) of a wheel id such as ``"41"``."""
    if wheel not in WHEELS:
        raise ValueError(f"wheel must be one of {WHEELS}, got {wheel!r}")
    return wheel[0]
