"""Read access to a canonical run file."""

from __future__ import annotations

import json
import operator
from pathlib import Path

import h5py
import numpy as np

from app.core.i18n import _
from app.io._closing import Closing
from app.io.canonical import FORMAT_VERSION, check_hdf5_tree
from app.io.channels import ALL_CHANNELS, AXLES
from app.io.errors import RunFileError
from app.io.kinematics import position_from_speed, position_table, speed_from_position
from app.io.metadata import RunMetadata, parse_metadata

__all__ = ["RunFile", "open_run"]


class RunFile(Closing):
    """An open canonical run file (see :mod:`app.io.canonical`).

    Use :func:`open_run`. Opening reads only attributes; channel data are read
    slice by slice and returned as calibrated float64 arrays.

    Attributes
    ----------
    path : Path
        The file.
    fs : float
        Sample rate, Hz.
    n_samples : int
        Samples per channel.
    metadata : RunMetadata
        Run metadata.
    channels : tuple of str
        Stored channel names, canonical order.
    """

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        try:
            self._h5 = h5py.File(self.path, "r")
        except (OSError, ValueError) as exc:
            raise RunFileError("format", _("cannot open {name} as HDF5: {error}", name=self.path.name, error=exc)) from None
        self._set_up_or_close(self._init)
        self._pos_table: np.ndarray | None = None
        self._pos_origin: float | None = None

    def _init(self) -> None:
        attrs = self._h5.attrs
        version = attrs.get("trackvkf_format_version")
        if version is None:
            raise RunFileError("format", _("not a trackvkf run file (no trackvkf_format_version)"))
        if int(version) != FORMAT_VERSION:
            raise RunFileError("format", _("unsupported format version {version}", version=int(version)))
        members = check_hdf5_tree(self._h5)
        for name in members:
            if name not in ALL_CHANNELS:
                raise RunFileError(name, _("unknown channel in run file"))
        self.channels: tuple[str, ...] = tuple(c for c in ALL_CHANNELS if c in members)
        self._ds = members
        self.fs = float(attrs["sample_rate_hz"])
        raw_meta = attrs["metadata"]
        if isinstance(raw_meta, bytes):
            raw_meta = raw_meta.decode("utf-8")
        self.metadata: RunMetadata = parse_metadata(json.loads(raw_meta))
        if self.metadata.km_start is None or self.metadata.km_increasing is None:
            raise RunFileError("format", _("run file metadata lacks km_start/km_increasing"))
        lengths = {members[c].shape[0] for c in self.channels}
        if len(lengths) > 1:
            raise RunFileError("file", _("channels of unequal length in run file"))
        self.n_samples = int(attrs.get("n_samples", lengths.pop() if lengths else 0))
        self._cal = {
            c: (
                float(members[c].attrs.get("gain", 1.0)),
                float(members[c].attrs.get("offset", 0.0)),
            )
            for c in self.channels
        }

    def close(self) -> None:
        """Close the file (idempotent)."""
        if self._h5.id.valid:
            self._h5.close()

    def __repr__(self) -> str:
        return (
            f"RunFile({str(self.path)!r}, fs={self.fs:g} Hz, n_samples={self.n_samples}, "
            f"channels={list(self.channels)})"
        )

    # --- basic properties --------------------------------------------------
    @property
    def duration_s(self) -> float:
        """Duration ``n_samples / fs``, s."""
        return self.n_samples / self.fs

    @property
    def source_format(self) -> str:
        """Format of the file this run was ingested from (``""`` if unknown)."""
        return str(self._h5.attrs.get("source_format", ""))

    def has(self, name: str) -> bool:
        """Whether channel ``name`` is stored."""
        return name in self.channels

    def calibration(self, name: str) -> tuple[float, float]:
        """``(gain, offset)`` applied to the stored values of channel ``name``."""
        self._check_name(name)
        return self._cal[name]

    def _check_name(self, name: str) -> None:
        if name not in self.channels:
            raise ValueError(
                f"name: channel {name!r} is not in this run (has {', '.join(self.channels)})"
            )

    def _range(self, start: int, stop: int | None) -> tuple[int, int]:
        try:
            start = operator.index(start)
            stop = self.n_samples if stop is None else operator.index(stop)
        except TypeError:
            raise ValueError(f"start/stop must be integers, got {start!r}, {stop!r}") from None
        if not 0 <= start <= stop <= self.n_samples:
            raise ValueError(
                f"start/stop must satisfy 0 <= start <= stop <= n_samples={self.n_samples}, "
                f"got {start}, {stop}"
            )
        return start, stop

    # --- data ---------------------------------------------------------------
    def read(self, name: str, start: int = 0, stop: int | None = None) -> np.ndarray:
        """Calibrated values of a channel.

        Parameters
        ----------
        name : str
            Channel name (``"Z11"``, ``"Q41"``, ``"speed"``, ``"position"`` …).
        start, stop : int
            Sample range (``stop=None``: to the end).

        Returns
        -------
        numpy.ndarray
            ``gain * raw + offset`` as float64 (m/s², kN, m/s or m).
        """
        self._check_name(name)
        start, stop = self._range(start, stop)
        data = self._ds[name][start:stop].astype(np.float64)
        gain, offset = self._cal[name]
        if gain != 1.0:
            data *= gain
        if offset != 0.0:
            data += offset
        return data

    def time(self, start: int = 0, stop: int | None = None) -> np.ndarray:
        """Time since the first sample, s."""
        start, stop = self._range(start, stop)
        return np.arange(start, stop) / self.fs

    def speed(self, start: int = 0, stop: int | None = None) -> np.ndarray:
        """Speed, m/s.

        From the ``speed`` channel, or derived from ``position`` by a smoothed
        gradient (:func:`app.io.kinematics.speed_from_position`) when absent.
        """
        start, stop = self._range(start, stop)
        if self.has("speed"):
            return self.read("speed", start, stop)
        if not self.has("position"):
            raise RunFileError("speed", _("run has neither speed nor position"))
        return speed_from_position(
            lambda a, b: self.read("position", a, b), self.n_samples, self.fs, start, stop
        )

    def position(self, start: int = 0, stop: int | None = None) -> np.ndarray:
        """Distance travelled by the position reference since the first sample, m.

        From the ``position`` channel minus its first value, or the cumulative
        trapezoid of ``speed`` (consistent across slices) when absent.
        """
        start, stop = self._range(start, stop)
        if self.has("position"):
            if self._pos_origin is None:
                self._pos_origin = float(self.read("position", 0, 1)[0]) if self.n_samples else 0.0
            return self.read("position", start, stop) - self._pos_origin
        if not self.has("speed"):
            raise RunFileError("position", _("run has neither speed nor position"))

        def rd(a: int, b: int) -> np.ndarray:
            return self.read("speed", a, b)

        if self._pos_table is None:
            self._pos_table = position_table(rd, self.n_samples, self.fs)
        return position_from_speed(rd, self._pos_table, self.n_samples, self.fs, start, stop)

    def axle_offset(self, axle: str = "1") -> float:
        """Position of ``axle`` relative to the position reference, m (positive ahead)."""
        if axle not in AXLES:
            raise ValueError(f"axle must be one of {AXLES}, got {axle!r}")
        return self.metadata.axle_positions[axle]

    def km(self, start: int = 0, stop: int | None = None, axle: str = "1") -> np.ndarray:
        """Line km of an axle: ``km_start ± (position + axle offset) / 1000``.

        The sign is + when ``metadata.km_increasing`` is true.
        """
        offset = self.axle_offset(axle)
        sign = 1.0 if self.metadata.km_increasing else -1.0
        return self.metadata.km_start + sign * (self.position(start, stop) + offset) / 1000.0

    def track_m(self, start: int = 0, stop: int | None = None, axle: str = "1") -> np.ndarray:
        """Position of an axle on the line km axis in m (``1000 * km``).

        25 cm profile bins are ``floor(track_m / 0.25)``.
        """
        offset = self.axle_offset(axle)
        sign = 1.0 if self.metadata.km_increasing else -1.0
        return 1000.0 * self.metadata.km_start + sign * (self.position(start, stop) + offset)


def open_run(path: Path | str) -> RunFile:
    """Open a canonical run file for reading.

    Parameters
    ----------
    path : Path or str
        A file written by :func:`app.io.ingest`, :func:`app.io.write_run_hdf5`
        or the simulator.

    Returns
    -------
    RunFile
        Use as a context manager (``with open_run(p) as run: ...``).

    Raises
    ------
    RunFileError
        If the file is not a canonical run file (``field == "format"``) or is
        inconsistent.
    """
    return RunFile(Path(path))
