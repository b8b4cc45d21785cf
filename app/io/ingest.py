"""Validate an input run file and write it in the canonical HDF5 form: the plan (metadata,
channels, sample rate), every block checked (:mod:`app.io.plausibility`) and written, then what
follows from the whole run (line km, the missing one of speed and position:
:func:`app.io.kinematics.derive_kinematics`; GNSS positions)."""

from __future__ import annotations

import itertools
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pydantic
from pydantic import ConfigDict, SkipValidation

from app.core.i18n import _
from app.io.canonical import CanonicalWriter, Compression, canonical_output
from app.io.channel_map import ChannelMap, parse_channel_map
from app.io.channels import (
    ALL_CHANNELS,
    TIME_COLUMN,
    storage_dtype,
)
from app.io.detect import resolve_format
from app.io.errors import RunFileError
from app.io.gapfill import GapFiller
from app.io.geometry import LineGeometry
from app.io.kinematics import derive_kinematics
from app.io.limits import DEFAULT_LIMITS, IngestLimits
from app.io.metadata import DEFAULT_AXLE_POSITIONS_M, RunMetadata, parse_metadata
from app.io.plausibility import (
    SampleChecks,
    check_channels,
    check_duration,
    check_sample_rate,
    resolve_sample_rate,
    too_many_nan,
)
from app.io.positioning import (
    GeometryLookup,
    GnssFixes,
    apply_gnss,
    finish_line_km,
    resolve_position_kind,
)
from app.io.sources import Source, open_source
from app.io.sources.recorder import RecorderSource

__all__ = ["RunSummary", "ingest"]

#: A relative position channel starting farther than this from 0 m is reported.
_ZERO_TOLERANCE_M = 1e-3


class RunSummary(pydantic.BaseModel):
    """What ingest learned about a run.

    Attributes
    ----------
    fs : float
        Sample rate, Hz.
    n_samples : int
        Samples per channel.
    duration_s : float
        ``n_samples / fs``, s.
    channels : list of str
        Stored channels, canonical order (always includes speed and position).
    metadata : RunMetadata
        Validated metadata as stored.
    distance_m : float
        Distance covered by the position reference, m.
    speed_min, speed_max : float
        Range of the speed, m/s.
    source_format : str
        ``"hdf5"``, ``"csv"``, ``"parquet"``, ``"mdf4"`` or ``"tdms"``.
    nan_filled : dict[str, int]
        Interpolated samples per channel (channels without NaN omitted).
    warnings : list of str
        What ingest assumed or did that the uploader should know (a relative
        position channel not starting at 0, the default axle layout, the start
        time taken from the recorder, GNSS outages bridged …), each
        ``"<field>: <message>"``.
    report : dict
        Provenance kept with the run: ``position_kind`` (as given),
        ``km_source`` (``metadata``, ``line_km`` or ``gnss``), ``channels``
        (recorder channel, group, unit and factor of each channel of a
        recorder file), ``positioning`` (GNSS matching and fusion summary).
    """

    model_config = ConfigDict(frozen=True)

    fs: float
    n_samples: int
    duration_s: float
    channels: list[str]
    metadata: RunMetadata
    distance_m: float
    speed_min: float
    speed_max: float
    source_format: str = ""
    nan_filled: dict[str, int] = {}
    #: kept as given (a marked message stays one: the run's page shows it in the reader's language)
    warnings: SkipValidation[list[str]] = []
    report: dict[str, Any] = {}


def ingest(
    src: Path,
    fmt: str | None,
    metadata: Mapping[str, Any] | None,
    dest: Path,
    limits: IngestLimits = DEFAULT_LIMITS,
    *,
    compression: Compression = "auto",
    channel_map: ChannelMap | Mapping[str, Any] | None = None,
    geometry: GeometryLookup | LineGeometry | None = None,
    reserve_bytes: int = 0,
) -> RunSummary:
    """Validate a run file and write it as a canonical HDF5 file.

    Parameters
    ----------
    src : Path
        Input file (HDF5, CSV, Parquet, MDF4 or TDMS).
    fmt : {"hdf5", "csv", "parquet", "mdf4", "tdms"} or None
        Declared format; ``None`` detects it from the magic bytes (and the file
        suffix for CSV).
    metadata : mapping or None
        Run metadata (see :class:`app.io.RunMetadata`). Required for CSV and
        Parquet; for HDF5 it is merged over the file's ``metadata`` attribute
        (given keys win; ``calibration`` is merged per channel).
    dest : Path
        Output file; written atomically (temporary file beside it, then
        :func:`os.replace`). Its directory must exist.
    limits : IngestLimits
        Acceptance limits.
    compression : {"auto", "lzf", "gzip", None}
        Compression of the output datasets (see :class:`~app.io.canonical.CanonicalWriter`).
    channel_map : ChannelMap or mapping, optional
        Recorder channel → trackvkf channel and unit (MDF4 and TDMS files;
        see :mod:`app.io.channel_map`).
    geometry : callable or LineGeometry, optional
        Line geometry for GNSS positions: the geometry itself, or
        ``lookup(line_id, track)`` returning the geometry of the run's line
        and track (or None). See :mod:`app.io.positioning`.
    reserve_bytes : int
        Free space that must remain on the file system of ``dest``
        (``TRACKVKF_MIN_FREE_BYTES``): checked against the expected size before
        writing when the sample count is known, and while writing.

    Returns
    -------
    RunSummary

    Raises
    ------
    RunFileError
        On any problem with the file or the metadata; nothing is left at
        ``dest`` (an existing file there is not touched) and no temporary file
        remains.
    DiskFullError
        When ``dest``'s file system has not enough space (before or while
        writing); nothing is left behind either, and libhdf5 never saw a
        failed write (:func:`app.io.canonical.canonical_output`).
    """
    src, dest = Path(src), Path(dest)
    if not isinstance(limits, IngestLimits):
        raise TypeError(f"limits must be an IngestLimits, got {type(limits).__name__}")
    if not src.is_file():
        raise RunFileError("file", _("{name!r} does not exist or is not a regular file", name=src.name))
    if src.stat().st_size == 0:
        raise RunFileError("file", _("file is empty"))
    if metadata is not None and not isinstance(metadata, Mapping):
        raise RunFileError(
            "metadata", _("metadata must be a JSON object, got {kind}", kind=type(metadata).__name__)
        )
    cmap = parse_channel_map(channel_map) if channel_map is not None else None
    fmt_name, comp = resolve_format(src, fmt)
    with open_source(src, fmt_name, comp, limits, cmap) as source:
        return _ingest(source, fmt_name, metadata, dest, limits, compression, geometry, reserve_bytes)


def _merge_metadata(
    source: Source, given: Mapping[str, Any] | None, warnings: list[str]
) -> RunMetadata:
    info = source.info
    if given is None and not info.file_metadata:
        return parse_metadata(None)
    merged: dict[str, Any] = {**info.file_metadata, **(given or {})}
    if "start_time" in info.file_metadata and "start_time" not in (given or {}):
        if isinstance(source, RecorderSource):
            warnings.append(_("start_time: taken from the recorder file header ({value})",
                              value=info.file_metadata["start_time"]))
    axles = merged.get("axle_positions")
    missing = [a for a in DEFAULT_AXLE_POSITIONS_M if not isinstance(axles, Mapping) or a not in axles]
    if missing:
        layout = ", ".join(f"{a} = {DEFAULT_AXLE_POSITIONS_M[a]:g} m" for a in missing)
        warnings.append(_("axle_positions: not given; the default layout was used (axles {layout} from the "
                          "position reference)", layout=layout))
    calibration: dict[str, Any] = dict(info.calibration)
    for part in (info.file_metadata.get("calibration"), (given or {}).get("calibration")):
        if part is not None:
            if not isinstance(part, Mapping):
                raise RunFileError(
                    "calibration", _("calibration must map channel names to {gain, offset}")
                )
            calibration.update(part)
    merged["calibration"] = calibration
    return parse_metadata(merged)


@dataclass
class _Plan:
    """What is settled before any sample is written: metadata, channels, length, sample rate."""

    meta: RunMetadata
    kind: str
    stored: list[str]
    n_known: int | None
    fs: float
    from_time: bool
    blocks: Iterator[dict[str, np.ndarray]]


def _ingest(
    source: Source,
    fmt: str,
    given: Mapping[str, Any] | None,
    dest: Path,
    limits: IngestLimits,
    compression: Compression,
    geometry: GeometryLookup | LineGeometry | None,
    reserve_bytes: int,
) -> RunSummary:
    """Three stages: plan (:func:`_plan`), check and write every block (:class:`_BlockWriter`),
    derive what follows from the whole run (:func:`_finish`)."""
    warnings: list[str] = []
    plan = _plan(source, given, limits, warnings)
    expected = 0 if plan.n_known is None else plan.n_known * _canonical_bytes_per_sample(plan.stored)
    with canonical_output(dest, reserve_bytes=reserve_bytes, expected_bytes=expected) as (h5, check_io):
        writer = CanonicalWriter(
            h5,
            fs=plan.fs,
            metadata=plan.meta,
            channels=plan.stored,
            n_samples=plan.n_known,
            compression=compression,
            source_format=fmt,
        )
        blocks = _BlockWriter(writer, plan, limits)
        n = blocks.write_all(check_io)
        report, stats = _finish(writer, blocks, plan, n, limits, geometry, warnings)
        if isinstance(source, RecorderSource):
            report["channels"] = source.channel_sources()
        writer.finish(n)
        channels = [c for c in ALL_CHANNELS if c in h5]
        final_meta = writer.metadata
    return RunSummary(
        fs=plan.fs,
        n_samples=n,
        duration_s=n / plan.fs,
        channels=channels,
        metadata=final_meta,
        distance_m=stats["distance"],
        speed_min=stats["vmin"],
        speed_max=stats["vmax"],
        source_format=fmt,
        nan_filled={c: f.n_nan for c, f in blocks.fillers.items() if f.n_nan},
        warnings=warnings,
        report=report,
    )


def _plan(
    source: Source, given: Mapping[str, Any] | None, limits: IngestLimits, warnings: list[str]
) -> _Plan:
    """Metadata, position kind, stored channels, declared length and sample rate (first block)."""
    info = source.info
    meta = _merge_metadata(source, given, warnings)
    kind = resolve_position_kind(meta, info.channels, warnings)
    stored = check_channels(info.channels)
    n_known = info.n_samples
    if n_known is not None:
        if n_known == 0:
            raise RunFileError("file", _("no samples"))
        if n_known > limits.max_samples:
            raise RunFileError(
                "file", _("{n_known} samples exceed the limit of {max_samples}", n_known=n_known, max_samples=limits.max_samples)
            )
    blocks: Iterator[dict[str, np.ndarray]] = source.blocks(limits.block_samples)
    first = next(blocks, None)
    if first is None or len(next(iter(first.values()))) == 0:
        raise RunFileError("file", _("no samples"))
    fs, from_time = resolve_sample_rate(meta, source, first)
    check_sample_rate(fs, limits)
    if n_known is not None:
        check_duration(n_known, fs, limits)
    return _Plan(
        meta=meta.model_copy(update={"sample_rate_hz": fs}),
        kind=kind,
        stored=stored,
        n_known=n_known,
        fs=fs,
        from_time=from_time,
        blocks=itertools.chain([first], blocks),
    )


class _BlockWriter:
    """Checks every block of the source (values, time grid, position, speed, NaN) and writes it."""

    def __init__(self, writer: CanonicalWriter, plan: _Plan, limits: IngestLimits) -> None:
        self.writer, self.plan, self.limits = writer, plan, limits
        self.checks = SampleChecks(plan.meta, plan.fs, limits, plan.from_time, 0 if plan.kind == "line_km" else 1)
        self.fixes = GnssFixes(plan.fs, limits) if plan.kind == "gnss" else None
        self.fillers = {
            c: GapFiller(lambda a, v, c=c: writer.write(c, a, v), chunk=limits.block_samples)
            for c in plan.stored
        }

    def write_all(self, check_io: Callable[[], None]) -> int:
        """Write every block; return the number of samples (checked against the declared one)."""
        limits, n_known = self.limits, self.plan.n_known
        offset = 0
        for block in self.plan.blocks:
            m = len(next(iter(block.values())))
            if offset + m > limits.max_samples:
                raise RunFileError("file", _("more than {max_samples} samples (limit)", max_samples=limits.max_samples))
            if TIME_COLUMN in block:
                self.checks.time(offset, block[TIME_COLUMN])
            if self.fixes is not None:
                self.fixes.add(offset, block["lat"], block["lon"])
            for c in self.plan.stored:
                self._channel(c, offset, block[c])
            check_io()
            offset += m
        if n_known is not None and offset != n_known:
            raise RunFileError("file", _("read {n_read} samples but the file declares {n_known}", n_read=offset, n_known=n_known))
        check_duration(offset, self.plan.fs, limits)
        for c, filler in self.fillers.items():
            if filler.n_nan > limits.max_nan_fraction * offset:
                too_many_nan(c, filler.n_nan, offset, limits)
            filler.finish(offset)
        return offset

    def _channel(self, c: str, offset: int, x: np.ndarray) -> None:
        limits, n_known = self.limits, self.plan.n_known
        if not x.flags.writeable:
            x = x.copy()
        if np.isinf(x).any():
            i = int(np.flatnonzero(np.isinf(x))[0])
            raise RunFileError(c, _("infinite value at sample {sample}", sample=offset + i))
        self.checks.magnitude(c, offset, x)
        filler = self.fillers[c]
        filler.process(offset, x)
        if n_known is not None and filler.n_nan > limits.max_nan_fraction * n_known:
            too_many_nan(c, filler.n_nan, n_known, limits)
        if c == "position":
            self.checks.position(offset, x)
        elif c == "speed":
            self.checks.speed(offset, x)
        self.writer.write(c, offset, x)


def _finish(
    writer: CanonicalWriter,
    blocks: _BlockWriter,
    plan: _Plan,
    n: int,
    limits: IngestLimits,
    geometry: GeometryLookup | LineGeometry | None,
    warnings: list[str],
) -> tuple[dict[str, Any], dict[str, float]]:
    """Line km, the missing one of speed/position, GNSS positions: ``(report, kinematic stats)``."""
    writer.n_samples = n
    checks = blocks.checks
    report: dict[str, Any] = {"position_kind": plan.kind, "km_source": "metadata"}
    if plan.kind == "line_km":
        finish_line_km(writer, checks.first_pos, checks.direction)
        report["km_source"] = "line_km"
    elif checks.first_pos is not None and abs(checks.first_pos) > _ZERO_TOLERANCE_M:
        warnings.append(_(
            "position: the relative position channel starts at {first:.6g} m, "
            "not 0 m; it was taken as distance travelled (its first sample subtracted). "
            "If it is the line chainage, upload with position_kind line_km", first=checks.first_pos))
    stats = derive_kinematics(writer, plan.stored, n, plan.fs, limits)
    if blocks.fixes is not None:
        meta = plan.meta
        lookup = geometry(meta.line_id, meta.track) if callable(geometry) else geometry
        if lookup is not None and (lookup.line_id, lookup.track) != (meta.line_id, meta.track):
            lookup = None
        report.update(apply_gnss(writer, blocks.fixes, lookup, n, limits, warnings))
    return report, stats


def _canonical_bytes_per_sample(stored: list[str]) -> int:
    """Bytes per sample of the canonical file: the stored channels plus speed and position."""
    names = set(stored) | {"speed", "position"}
    return sum(storage_dtype(c).itemsize for c in names)
