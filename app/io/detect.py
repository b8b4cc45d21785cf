"""Recognise the format of an input run file from its bytes and name (the formats: :mod:`app.io.formats`)."""

from __future__ import annotations

from pathlib import Path

from app.core.i18n import _
from app.io.errors import RunFileError
from app.io.formats import FORMATS, HDF5_SIGNATURE, RUN_FORMATS, extensions_of

__all__ = ["detect_format", "resolve_format"]

#: Leading bytes of recorder files: ASAM MDF identification block, NI TDMS lead-in.
_RECORDER_MAGIC = {f.name: f.magic for f in RUN_FORMATS if f.recorder}
_PARQUET_MAGIC = next(f.magic for f in RUN_FORMATS if f.name == "parquet")
_GZIP_MAGIC = b"\x1f\x8b"
_CSV_SUFFIXES = extensions_of("csv")
_BINARY_SUFFIXES = extensions_of("hdf5", "parquet")


def _has_hdf5_signature(path: Path, size: int) -> bool:
    # the superblock sits at 0, 512, 1024, 2048 … (after a user block, e.g. MATLAB v7.3)
    with open(path, "rb") as fh:
        offset = 0
        while offset + len(HDF5_SIGNATURE) <= size:
            fh.seek(offset)
            if fh.read(len(HDF5_SIGNATURE)) == HDF5_SIGNATURE:
                return True
            offset = 512 if offset == 0 else offset * 2
    return False


def _is_parquet(path: Path, size: int) -> bool:
    if size < 12:
        return False
    with open(path, "rb") as fh:
        head = fh.read(4)
        fh.seek(size - 4)
        tail = fh.read(4)
    return head == _PARQUET_MAGIC and tail == _PARQUET_MAGIC


def _recorder_format(path: Path) -> str | None:
    with open(path, "rb") as fh:
        head = fh.read(8)
    return next((fmt for fmt, magic in _RECORDER_MAGIC.items() if head.startswith(magic)), None)


def _text_problem(path: Path) -> str | None:
    """Why the file does not start with a delimited-text header line (None: it does).

    Only the first line is judged here: a NUL byte or bytes that are not UTF-8
    further on are reported, with their offset, by the CSV reader.
    """
    with open(path, "rb") as fh:
        head = fh.read(4096)
    first, newline, _rest = head.partition(b"\n")
    nul = first.find(b"\x00")
    if nul >= 0:
        return f"NUL byte at byte {nul} of the first line (binary data?)"
    try:
        text = first.decode("utf-8")
    except UnicodeDecodeError as exc:
        if newline or exc.start < len(first) - 4:  # a multi-byte character cut at the end is fine
            return f"not UTF-8 text: byte 0x{first[exc.start]:02x} at byte {exc.start} of the first line"
        text = first[: exc.start].decode("utf-8")
    if not any(sep in text for sep in (",", ";", "\t")):
        return "no delimiter (comma, semicolon or tab) in the first line"
    return None


def _is_gzip(path: Path) -> bool:
    with open(path, "rb") as fh:
        return fh.read(2) == _GZIP_MAGIC


def detect_format(path: Path) -> tuple[str, str | None]:
    """Detect the format of a non-empty file.

    Parameters
    ----------
    path : Path
        Input file.

    Returns
    -------
    fmt : str
        ``"hdf5"``, ``"csv"``, ``"parquet"``, ``"mdf4"`` (ASAM MDF) or ``"tdms"``.
    compression : str or None
        ``"gzip"`` for gzip-compressed CSV, else ``None``.

    Raises
    ------
    RunFileError
        ``field == "format"`` if the format is not recognised.
    """
    size = path.stat().st_size
    if _has_hdf5_signature(path, size):
        return "hdf5", None
    if _is_parquet(path, size):
        return "parquet", None
    recorder = _recorder_format(path)
    if recorder is not None:
        return recorder, None
    name = path.name.lower()
    if _is_gzip(path):
        if name.endswith(_CSV_SUFFIXES) or not name.endswith(_BINARY_SUFFIXES):
            return "csv", "gzip"
    elif name.endswith(_CSV_SUFFIXES):
        return "csv", None
    problem = _text_problem(path)
    if problem is None and not name.endswith(_BINARY_SUFFIXES):
        return "csv", None
    raise RunFileError(
        "format",
        _("unknown format of {name!r}: not HDF5 (no signature), not Parquet (no PAR1 magic), not MDF4 or TDMS (no identification) and not delimited text (CSV: {problem})", name=path.name, problem=problem)
        if problem else
        _("unknown format of {name!r}: not HDF5 (no signature), not Parquet (no PAR1 magic), not MDF4 or TDMS (no identification) and not delimited text (CSV)", name=path.name),
    )


def resolve_format(path: Path, fmt: str | None) -> tuple[str, str | None]:
    """Check a declared format against the file, or detect it when ``fmt`` is None.

    Returns ``(fmt, compression)`` as :func:`detect_format`.

    Raises
    ------
    RunFileError
        ``field == "format"`` for an unknown declared format or a file whose
        bytes do not match it.
    """
    if fmt is None:
        return detect_format(path)
    if not isinstance(fmt, str) or fmt.lower() not in FORMATS:
        raise RunFileError(
            "format", _("unknown format {format}; expected one of {choices}", format=repr(fmt), choices=", ".join(FORMATS))
        )
    fmt = fmt.lower()
    size = path.stat().st_size
    if fmt == "hdf5":
        if not _has_hdf5_signature(path, size):
            raise RunFileError("format", _("declared format {format} but the file has no HDF5 signature", format="'hdf5'"))
        return fmt, None
    if fmt in _RECORDER_MAGIC:
        if _recorder_format(path) != fmt:
            raise RunFileError("format", _("declared format {format} but the file does not start like one", format=repr(fmt)))
        return fmt, None
    if fmt == "parquet":
        if not _is_parquet(path, size):
            raise RunFileError("format", _("declared format {format} but the file has no PAR1 magic", format="'parquet'"))
        return fmt, None
    if _is_gzip(path):
        return fmt, "gzip"
    if _has_hdf5_signature(path, size) or _is_parquet(path, size) or _recorder_format(path) is not None:
        raise RunFileError("format", _("declared format {format} but the file is HDF5, Parquet, MDF4 or TDMS", format="'csv'"))
    problem = _text_problem(path)
    if problem is not None:
        raise RunFileError("format", _("declared format {format} but the file is not delimited text: {problem}", format="'csv'",
                                       problem=problem))
    return fmt, None
