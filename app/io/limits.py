"""Acceptance limits applied when a run file is ingested."""

from __future__ import annotations

import math
from dataclasses import dataclass

from app.core.i18n import _

__all__ = ["IngestLimits", "DEFAULT_LIMITS"]


@dataclass(frozen=True)
class IngestLimits:
    """What ingest accepts.

    Attributes
    ----------
    max_nan_fraction : float
        Largest fraction of NaN samples per channel, in [0, 1) (default 0.01 = 1 %).
        Fewer NaN are filled by linear interpolation in sample index (leading and
        trailing gaps by the nearest valid value).
    min_sample_rate_hz, max_sample_rate_hz : float
        Accepted sample-rate range, Hz (default 1 kHz … 100 kHz).
    max_samples : int
        Largest number of samples per channel (default 400 M, 4.6 h at 24 kHz).
    max_speed_mps : float
        Largest plausible speed, m/s (default 100 m/s = 360 km/h); larger values
        usually mean the speed was given in km/h.
    speed_tolerance_mps : float
        Negative speeds down to ``-speed_tolerance_mps`` (sensor noise at
        standstill) are accepted and treated as 0 when integrating position;
        default 0.1 m/s.
    speed_position_tolerance : float
        When both ``speed`` and ``position`` are given and the run covers more
        than 20 m, the integrated speed must match the distance covered by
        ``position`` within this relative tolerance (default 0.1).
    block_samples : int
        Samples per block when streaming the input (memory bound), default 2**19.
    max_columns : int
        Largest number of columns (CSV, Parquet) or root members (HDF5) of an
        input file, default 64 (a run has at most 15 channels and a time column).
    max_header_bytes : int
        Longest accepted CSV header line, bytes (default 64 KiB).
    max_expansion_ratio : float
        Decompression-bomb guard: the decoded size of the data (samples ×
        channels × bytes per value for HDF5 and Parquet, decompressed text for
        gzip CSV) may exceed the file size at most this many times (default
        100; measured run files expand 1–3 times) ...
    expansion_floor_bytes : int
        ... plus this many bytes (default 64 MiB), so small files are never refused.
    max_parquet_footer_bytes : int
        Largest Parquet footer (file metadata), bytes (default 16 MiB); read
        from the file's last 8 bytes before the footer is parsed.
    min_duration_s : float
        Shortest accepted run, s (default 1 s): shorter runs cannot be
        processed (the order filters need more samples).
    max_abs_accel_mps2 : float
        Largest accepted magnitude of a calibrated acceleration, m/s² (default
        1e5, about 10 000 g): larger values mean a wrong calibration.
    max_abs_force_kn : float
        Largest accepted magnitude of a calibrated wheel–rail force, kN (default 1e4).
    max_abs_position_m : float
        Largest accepted magnitude of a calibrated position, m (default 1e8).
    max_metadata_bytes : int
        Largest HDF5 ``metadata`` attribute, bytes (default 1 MiB, as the
        metadata form field of an upload).
    max_attribute_bytes : int
        Largest other HDF5 attribute (``units``, ``gain``, ``sample_rate_hz`` …),
        bytes (default 64 KiB).
    max_attribute_read_bytes : int
        Variable-length HDF5 attributes (strings) are read only when the file
        holds at most this many bytes outside its datasets' data (default
        64 MiB): their length is not known before they are read.
    max_line_bytes : int
        Longest accepted CSV line, bytes (default 64 KiB; a run's line has at
        most 64 numbers).
    csv_block_bytes : int
        CSV text is parsed in pieces of about this many bytes (default 8 MiB),
        cut at line ends: the parser's memory is bounded by it whatever the
        file holds.
    max_recorder_channels : int
        Largest number of channels in an MDF4 or TDMS recorder file (default
        2048: recorders log many signals besides the ones a run reads; the
        channels read are at most :attr:`max_columns`).
    max_recorder_blocks : int
        Largest number of blocks of an MDF4 file (default 262 144; a recorder
        file has a few per channel and one per data block), or metadata objects
        of a TDMS file, walked before the third-party reader opens the file.
    max_recorder_text_bytes : int
        Largest total size of the texts and comments (MDF4 TX/MD blocks,
        counted at every reference) of a recorder file, bytes (default 16 MiB).
    max_gnss_rate_hz : float
        GNSS fixes are kept at most at this rate, Hz (default 10): fixes
        resampled onto the ABA time base are thinned to it before map matching.
    """

    max_nan_fraction: float = 0.01
    min_sample_rate_hz: float = 1_000.0
    max_sample_rate_hz: float = 100_000.0
    max_samples: int = 400_000_000
    max_speed_mps: float = 100.0
    speed_tolerance_mps: float = 0.1
    speed_position_tolerance: float = 0.1
    block_samples: int = 2**19
    max_columns: int = 64
    max_header_bytes: int = 65_536
    max_expansion_ratio: float = 100.0
    expansion_floor_bytes: int = 64 * 1024 * 1024
    max_parquet_footer_bytes: int = 16 * 1024 * 1024
    min_duration_s: float = 1.0
    max_abs_accel_mps2: float = 1e5
    max_abs_force_kn: float = 1e4
    max_abs_position_m: float = 1e8
    max_metadata_bytes: int = 1024 * 1024
    max_attribute_bytes: int = 64 * 1024
    max_attribute_read_bytes: int = 64 * 1024 * 1024
    max_line_bytes: int = 64 * 1024
    csv_block_bytes: int = 8 * 1024 * 1024
    max_recorder_channels: int = 2048
    max_recorder_blocks: int = 262_144
    max_recorder_text_bytes: int = 16 * 1024 * 1024
    max_gnss_rate_hz: float = 10.0

    def max_decoded_bytes(self, file_bytes: int) -> int:
        """Largest decoded size accepted for a file of ``file_bytes`` bytes."""
        return int(self.max_expansion_ratio * max(int(file_bytes), 0)) + self.expansion_floor_bytes

    def check_decoded(self, decoded: int, file_bytes: int, what: str) -> None:
        """Refuse ``what`` (``"the MDF data"``) decoding to more than :meth:`max_decoded_bytes`.

        Raises
        ------
        RunFileError
            ``field == "file"``: a decompression bomb.
        """
        from app.io.errors import RunFileError

        allowed = self.max_decoded_bytes(file_bytes)
        if decoded > allowed:
            raise RunFileError(
                "file",
                _("{what} decode to {decoded} bytes, more than {allowed} bytes allowed for a {file_bytes}-byte file (decompression bomb limit)", what=what, decoded=decoded, allowed=allowed, file_bytes=file_bytes),
            )

    def __post_init__(self) -> None:
        if not (0.0 <= self.max_nan_fraction < 1.0):
            raise ValueError(f"max_nan_fraction must be in [0, 1), got {self.max_nan_fraction!r}")
        lo, hi = self.min_sample_rate_hz, self.max_sample_rate_hz
        if not (math.isfinite(lo) and math.isfinite(hi) and 0 < lo <= hi):
            raise ValueError(
                f"min_sample_rate_hz/max_sample_rate_hz must satisfy 0 < min <= max, got {lo!r}, {hi!r}"
            )
        if int(self.max_samples) != self.max_samples or self.max_samples < 1:
            raise ValueError(f"max_samples must be a positive integer, got {self.max_samples!r}")
        if not (math.isfinite(self.max_speed_mps) and self.max_speed_mps > 0):
            raise ValueError(f"max_speed_mps must be > 0 m/s, got {self.max_speed_mps!r}")
        if not (math.isfinite(self.speed_tolerance_mps) and self.speed_tolerance_mps >= 0):
            raise ValueError(
                f"speed_tolerance_mps must be >= 0 m/s, got {self.speed_tolerance_mps!r}"
            )
        if not (math.isfinite(self.speed_position_tolerance) and self.speed_position_tolerance > 0):
            raise ValueError(
                f"speed_position_tolerance must be > 0, got {self.speed_position_tolerance!r}"
            )
        for name in (
            "max_columns",
            "max_header_bytes",
            "expansion_floor_bytes",
            "max_parquet_footer_bytes",
            "max_recorder_channels",
            "max_recorder_blocks",
            "max_recorder_text_bytes",
            "max_metadata_bytes",
            "max_attribute_bytes",
            "max_attribute_read_bytes",
            "max_line_bytes",
            "csv_block_bytes",
        ):
            value = getattr(self, name)
            if int(value) != value or value < 1:
                raise ValueError(f"{name} must be a positive integer, got {value!r}")
        for name in ("max_abs_accel_mps2", "max_abs_force_kn", "max_abs_position_m"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
        if not (math.isfinite(self.min_duration_s) and self.min_duration_s >= 0):
            raise ValueError(f"min_duration_s must be >= 0 s, got {self.min_duration_s!r}")
        if self.csv_block_bytes < 2 * self.max_line_bytes:
            raise ValueError(
                f"csv_block_bytes ({self.csv_block_bytes}) must be at least twice max_line_bytes "
                f"({self.max_line_bytes})"
            )
        if not (math.isfinite(self.max_expansion_ratio) and self.max_expansion_ratio >= 1):
            raise ValueError(f"max_expansion_ratio must be >= 1, got {self.max_expansion_ratio!r}")
        if not (math.isfinite(self.max_gnss_rate_hz) and self.max_gnss_rate_hz > 0):
            raise ValueError(f"max_gnss_rate_hz must be > 0 Hz, got {self.max_gnss_rate_hz!r}")
        if int(self.block_samples) != self.block_samples or not 1024 <= self.block_samples <= 2**24:
            raise ValueError(
                f"block_samples must be an integer in [1024, 2**24], got {self.block_samples!r}"
            )


#: The default limits.
DEFAULT_LIMITS = IngestLimits()
