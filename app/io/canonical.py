"""The canonical HDF5 layout of a run and its writer.

Layout (format version 1)::

    /                         root group
      attrs  trackvkf_format_version = 1
             sample_rate_hz          float, Hz
             n_samples               int
             metadata                JSON string of RunMetadata
             source_format           "hdf5" | "csv" | "parquet" | "simulated" | ""
             software                "trackvkf <version>"
    /Z11 /Z12 /Z41 /Z42       float32 (n,), raw values; physical = gain * raw + offset
    /Q11 … /Q42               float32 (n,), optional, kN after calibration
    /speed                    float64 (n,), m/s after calibration
    /position                 float64 (n,), m after calibration
      every dataset: attrs units, gain, offset, derived ("" or how it was derived)

Datasets are chunked (``CHUNK_SAMPLES``) and compressed with LZF + shuffle by
default. Files written by :func:`app.io.ingest` always hold both ``speed`` and
``position``.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator, Mapping
from importlib import metadata as _pkg_metadata
from pathlib import Path
from typing import Any, Literal

import h5py
import numpy as np

from app.core.atomic import atomic_path
from app.core.diskspace import require_free
from app.core.i18n import _
from app.io._guarded_file import GuardedFile
from app.io.channels import ALL_CHANNELS, UNITS, storage_dtype
from app.io.errors import RunFileError
from app.io.metadata import Calibration, RunMetadata, parse_metadata

__all__ = [
    "FORMAT_VERSION",
    "CHUNK_SAMPLES",
    "Compression",
    "atomic_output",
    "canonical_output",
    "CanonicalWriter",
    "write_run_hdf5",
    "check_hdf5_tree",
    "software_version",
]

FORMAT_VERSION = 1
CHUNK_SAMPLES = 65_536
Compression = Literal["auto", "lzf", "gzip"] | None


def software_version() -> str:
    """``"trackvkf <version>"`` of the installed package."""
    try:
        return f"trackvkf {_pkg_metadata.version('trackvkf')}"
    except _pkg_metadata.PackageNotFoundError:  # pragma: no cover - source tree without install
        return "trackvkf (unknown version)"


@contextlib.contextmanager
def atomic_output(dest: Path) -> Iterator[Path]:
    """Yield a temporary path beside ``dest``; move it onto ``dest`` on success.

    Parameters
    ----------
    dest : Path
        Final location; its directory must exist.

    Notes
    -----
    :func:`app.core.atomic.atomic_path` with the ``.part`` ending: the temporary
    file must be written; it is fsynced and renamed with :func:`os.replace`.
    When the ``with`` block raises, the temporary file is removed and ``dest``
    is not touched.
    """
    dest = Path(dest)
    if not dest.parent.is_dir():
        raise FileNotFoundError(f"dest: directory {str(dest.parent)!r} does not exist")
    with atomic_path(dest, suffix=".part", must_write=True) as tmp:
        yield tmp


@contextlib.contextmanager
def canonical_output(
    dest: Path, *, reserve_bytes: int = 0, expected_bytes: int = 0
) -> Iterator[tuple[h5py.File, Callable[[], None]]]:
    """An HDF5 file open for writing that becomes ``dest`` atomically, safe on a full disk.

    Parameters
    ----------
    dest : Path
        Final location; its directory must exist.
    reserve_bytes : int
        Free space that must remain on the file system (``TRACKVKF_MIN_FREE_BYTES``);
        checked before writing (with ``expected_bytes``) and every few MiB while writing.
    expected_bytes : int
        Size the file is expected to reach, if known (0: not checked up front).

    Yields
    ------
    h5 : h5py.File
        The file (h5py's file-object driver over a :class:`GuardedFile`, so
        libhdf5 never sees a failed write).
    check : callable
        Raises the first write failure (:class:`~app.core.diskspace.DiskFullError`
        for a full disk); call it between blocks to stop early.

    Raises
    ------
    DiskFullError
        Not enough space (before writing, or found while writing; then this
        replaces whatever error the dropped writes caused). Nothing is left
        at ``dest`` and no temporary file remains.
    """
    with atomic_output(dest) as tmp:
        if expected_bytes > 0 or reserve_bytes > 0:
            require_free(tmp.parent, max(int(expected_bytes), 0), reserve_bytes, _("the canonical run file"))
        guard = GuardedFile(tmp, reserve_bytes)
        try:
            h5 = h5py.File(guard, "w")
            try:
                yield h5, guard.raise_if_failed
            except BaseException:
                with contextlib.suppress(Exception):
                    h5.close()
                guard.raise_if_failed()  # a failed write explains what followed it
                raise
            h5.close()
            guard.raise_if_failed()
        finally:
            guard.close()


def check_hdf5_tree(f: h5py.File) -> dict[str, h5py.Dataset]:
    """Inspect the root of an HDF5 file without reading data.

    Every root member must be a hard link (or a soft link that resolves through
    hard links inside the file) to a dataset with contiguous or chunked storage
    in the file itself.

    Parameters
    ----------
    f : h5py.File
        Open file.

    Returns
    -------
    dict[str, h5py.Dataset]
        Root member name → dataset (names as stored).

    Raises
    ------
    RunFileError
        On an external link, a dangling soft link or one that leaves the file, a
        group, a virtual dataset or a dataset with external storage; ``field`` is
        the member name.
    """
    out: dict[str, h5py.Dataset] = {}
    for name in f:
        link = f.get(name, getlink=True)
        if isinstance(link, h5py.ExternalLink):
            raise RunFileError(name, _("external link to {filename}:{path} is not allowed", filename=link.filename, path=link.path))
        if isinstance(link, h5py.SoftLink):
            _check_soft_link(f, name, link.path)
        elif not isinstance(link, h5py.HardLink):
            raise RunFileError(name, _("unsupported link type"))
        obj = f.get(name)
        if not isinstance(obj, h5py.Dataset):
            raise RunFileError(name, _("must be a 1-D dataset at the file root (found a group)"))
        if obj.is_virtual:
            raise RunFileError(name, _("virtual datasets are not allowed"))
        if obj.external:
            raise RunFileError(name, _("datasets with external storage are not allowed"))
        out[name] = obj
    return out


def _check_soft_link(f: h5py.File, name: str, target: str) -> None:
    if not target.startswith("/"):
        target = "/" + target
    group: h5py.Group = f
    parts = [p for p in target.split("/") if p and p != "."]
    if not parts or ".." in parts:
        raise RunFileError(
            name, _("soft link to {target!r} does not point to a dataset in this file", target=target)
        )
    for i, part in enumerate(parts):
        link = group.get(part, getlink=True)
        if not isinstance(link, h5py.HardLink):
            raise RunFileError(
                name, _("soft link to {target!r} does not resolve to a dataset inside this file", target=target)
            )
        obj = group.get(part)
        if i < len(parts) - 1:
            if not isinstance(obj, h5py.Group):
                raise RunFileError(name, _("soft link to {target!r} does not point to a dataset", target=target))
            group = obj
        elif not isinstance(obj, h5py.Dataset):
            raise RunFileError(name, _("soft link to {target!r} does not point to a dataset", target=target))


#: channels stored compressed under ``compression="auto"``: smooth signals that
#: LZF with byte shuffle shrinks 2-3x. Accelerations and forces are noise-like:
#: LZF saves 10-30 % on them but makes every read ~5x slower, so "auto" stores
#: them plain.
_SMOOTH_CHANNELS = frozenset({"speed", "position"})


def _compression_kwargs(compression: Compression, name: str) -> dict[str, Any]:
    if compression == "auto":
        compression = "lzf" if name in _SMOOTH_CHANNELS else None
    if compression is None:
        return {}
    if compression == "lzf":
        return {"compression": "lzf", "shuffle": True}
    if compression == "gzip":
        return {"compression": "gzip", "compression_opts": 1, "shuffle": True}
    raise ValueError(f"compression must be 'auto', 'lzf', 'gzip' or None, got {compression!r}")


class CanonicalWriter:
    """Write a canonical run file block by block.

    Parameters
    ----------
    h5 : h5py.File
        File open for writing (usually a temporary file from :func:`atomic_output`).
    fs : float
        Sample rate, Hz.
    metadata : RunMetadata
        Metadata; ``sample_rate_hz`` is set to ``fs`` and its ``calibration``
        gives the gain/offset attributes of the datasets.
    channels : sequence of str
        Channels to create now (more can be added with :meth:`add_channel`).
    n_samples : int or None
        Length of every channel if known; ``None`` grows datasets while writing.
    compression : {"auto", "lzf", "gzip", None}
        Dataset compression. ``"auto"`` (default): LZF with byte shuffle for
        speed and position, none for the measurement channels (fast reads).
    source_format : str
        Recorded in the ``source_format`` attribute.
    """

    def __init__(
        self,
        h5: h5py.File,
        *,
        fs: float,
        metadata: RunMetadata,
        channels: list[str] | tuple[str, ...],
        n_samples: int | None,
        compression: Compression = "auto",
        source_format: str = "",
    ) -> None:
        self.h5 = h5
        self.fs = float(fs)
        self.metadata = metadata.model_copy(update={"sample_rate_hz": self.fs})
        self.n_samples = n_samples
        _compression_kwargs(compression, "")  # validate now
        self._compression = compression
        self._source_format = source_format
        for name in channels:
            self.add_channel(name)

    def add_channel(self, name: str, *, derived: str = "", calibrated: bool = True) -> h5py.Dataset:
        """Create the dataset of a channel.

        Parameters
        ----------
        name : str
            Channel name (one of :data:`app.io.ALL_CHANNELS`).
        derived : str
            How the channel was derived (empty for measured channels).
        calibrated : bool
            If False the dataset holds physical values (gain 1, offset 0) even if
            the metadata has a calibration for it.
        """
        if name not in ALL_CHANNELS:
            raise ValueError(f"name: unknown channel {name!r}")
        n = self.n_samples
        shape = (n,) if n is not None else (0,)
        chunks = (min(CHUNK_SAMPLES, max(n or CHUNK_SAMPLES, 1)),)
        ds = self.h5.create_dataset(
            name,
            shape=shape,
            maxshape=(None,),
            dtype=storage_dtype(name),
            chunks=chunks,
            **_compression_kwargs(self._compression, name),
        )
        gain, offset = self.metadata.gain_offset(name) if calibrated and not derived else (1.0, 0.0)
        ds.attrs["units"] = UNITS[name]
        ds.attrs["gain"] = float(gain)
        ds.attrs["offset"] = float(offset)
        ds.attrs["derived"] = derived
        return ds

    def write(self, name: str, start: int, data: np.ndarray) -> None:
        """Write ``data`` (raw values) to samples ``start:start+len(data)`` of a channel."""
        ds = self.h5[name]
        stop = start + len(data)
        if stop > ds.shape[0]:
            ds.resize((stop,))
        ds[start:stop] = data

    def finish(self, n_samples: int) -> None:
        """Check the lengths and write the root attributes."""
        for name in ("km_start", "km_increasing"):
            if getattr(self.metadata, name) is None:
                raise RunFileError(
                    name, _("required field is missing (the km of the run's first sample)")
                )
        for name in self.h5:
            if self.h5[name].shape[0] != n_samples:
                raise RuntimeError(
                    f"{name}: wrote {self.h5[name].shape[0]} samples, expected {n_samples}"
                )
        meta = self.metadata
        if meta.calibration:
            # keep only calibrations of channels stored with them
            cal = {
                k: v
                for k, v in meta.calibration.items()
                if k in self.h5 and not self.h5[k].attrs["derived"]
            }
            meta = meta.model_copy(update={"calibration": cal})
        attrs = self.h5.attrs
        attrs["trackvkf_format_version"] = FORMAT_VERSION
        attrs["sample_rate_hz"] = self.fs
        attrs["n_samples"] = int(n_samples)
        attrs["metadata"] = meta.to_json()
        attrs["source_format"] = self._source_format
        attrs["software"] = software_version()
        self.n_samples = n_samples


def write_run_hdf5(
    path: Path,
    channels: Mapping[str, np.ndarray],
    fs: float,
    metadata: RunMetadata | Mapping[str, Any],
    calibration: Mapping[str, Calibration | Mapping[str, float]] | None = None,
    *,
    compression: Compression = "auto",
    source_format: str = "",
) -> Path:
    """Write whole arrays as a canonical run file (atomically).

    Parameters
    ----------
    path : Path
        Output file.
    channels : mapping of str to array_like
        Channel name → 1-D values as stored (raw values if ``calibration`` is
        given for the channel). Any subset of :data:`app.io.ALL_CHANNELS`; the
        file is written as given (no speed/position is derived here).
    fs : float
        Sample rate, Hz.
    metadata : RunMetadata or mapping
        Run metadata.
    calibration : mapping, optional
        Channel → ``{"gain": g, "offset": o}``; merged over ``metadata.calibration``.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    RunFileError
        On unknown channel names, unequal lengths, non-1-D or non-numeric arrays,
        or invalid metadata.
    """
    meta = parse_metadata(metadata)
    if calibration:
        merged = dict(meta.calibration)
        for k, v in calibration.items():
            merged[k] = v if isinstance(v, Calibration) else Calibration.model_validate(dict(v))
        meta = parse_metadata({**meta.model_dump(), "calibration": merged})
    try:
        fs = float(fs)
    except (TypeError, ValueError):
        raise RunFileError("sample_rate_hz", _("sample rate must be a number, got {fs!r}", fs=fs)) from None
    if not (np.isfinite(fs) and fs > 0):
        raise RunFileError("sample_rate_hz", _("sample rate must be > 0 Hz, got {fs!r}", fs=fs))
    arrays: dict[str, np.ndarray] = {}
    for name, values in channels.items():
        if name not in ALL_CHANNELS:
            raise RunFileError(name, _("unknown channel; channels are {items}", items=', '.join(ALL_CHANNELS)))
        arr = np.asarray(values)
        if arr.ndim != 1:
            raise RunFileError(name, _("must be 1-D, got shape {shape}", shape=arr.shape))
        if arr.dtype.kind not in "iuf":
            raise RunFileError(name, _("must be numeric, got dtype {dtype}", dtype=arr.dtype))
        arrays[name] = arr
    if not arrays:
        raise RunFileError("file", _("no channels given"))
    n = {len(a) for a in arrays.values()}
    if len(n) != 1:
        lengths = ", ".join(f"{k}={len(a)}" for k, a in arrays.items())
        raise RunFileError(next(iter(arrays)), _("channels of unequal length ({lengths})", lengths=lengths))
    n_samples = n.pop()
    order = [c for c in ALL_CHANNELS if c in arrays]
    with canonical_output(Path(path)) as (h5, _tmp):
        writer = CanonicalWriter(
            h5,
            fs=fs,
            metadata=meta,
            channels=order,
            n_samples=n_samples,
            compression=compression,
            source_format=source_format,
        )
        for name in order:
            writer.write(name, 0, arrays[name])
        writer.finish(n_samples)
    return Path(path)
