"""THE table of run-file formats: their names, the other names a client may give, file extensions,
content types and leading bytes.

Everything that names a format reads it from here: the upload's format from a declared value, the
file name or the content type (:mod:`app.runs.upload`), the content types the upload accepts
(:mod:`app.api.upload`), the recognition of a file from its bytes and name (:mod:`app.io.detect`),
the recorder formats that take a channel map (:mod:`app.io.sources`) and the API's schema
(:mod:`app.api.runs`). docs/run-format.md describes the formats.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = [
    "RunFormat", "RUN_FORMATS", "FORMATS", "RECORDER_FORMATS", "FORMAT_ALIASES", "EXTENSIONS",
    "CONTENT_TYPE_FORMATS", "HDF5_SIGNATURE", "format_of_alias", "format_of_name", "extensions_of",
]


@dataclass(frozen=True)
class RunFormat:
    """One accepted format of a run file.

    Attributes
    ----------
    name : str
        The format's name (``format=`` of an upload, ``source_format`` of a run).
    aliases : tuple of str
        Other names a client may declare it by (lower case).
    extensions : tuple of str
        File-name endings that name it (lower case, with the dot; ``.csv.gz``: gzip-compressed).
    content_types : tuple of str
        Content types that name it.
    magic : bytes
        Leading bytes of every such file (empty: none; HDF5's signature may also sit after a user
        block, :data:`HDF5_SIGNATURE`).
    recorder : bool
        A recorder file whose channels a channel map names (MDF4, TDMS).
    """

    name: str
    aliases: tuple[str, ...] = ()
    extensions: tuple[str, ...] = ()
    content_types: tuple[str, ...] = ()
    magic: bytes = b""
    recorder: bool = False


#: The HDF5 superblock signature (at byte 0, 512, 1024, 2048 … of the file).
HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"

#: Every accepted format, in the order they are listed to clients.
RUN_FORMATS: tuple[RunFormat, ...] = (
    RunFormat("hdf5", aliases=("h5", "hdf"), extensions=(".h5", ".hdf5", ".hdf", ".he5", ".mat"),
              content_types=("application/x-hdf5", "application/x-hdf", "application/hdf5"), magic=HDF5_SIGNATURE),
    RunFormat("csv", extensions=(".csv", ".tsv", ".txt", ".csv.gz", ".tsv.gz", ".txt.gz"),
              content_types=("text/csv", "application/csv")),
    RunFormat("parquet", aliases=("pq",), extensions=(".parquet", ".pq"),
              content_types=("application/vnd.apache.parquet", "application/x-parquet", "application/parquet"),
              magic=b"PAR1"),
    RunFormat("mdf4", aliases=("mf4", "mdf"), extensions=(".mf4", ".mdf"), magic=b"MDF     ", recorder=True),
    RunFormat("tdms", extensions=(".tdms",), magic=b"TDSm", recorder=True),
)

#: Names of the accepted formats.
FORMATS: tuple[str, ...] = tuple(f.name for f in RUN_FORMATS)
#: Names of the recorder formats (a channel map applies to them).
RECORDER_FORMATS: tuple[str, ...] = tuple(f.name for f in RUN_FORMATS if f.recorder)
#: Every name a format may be declared by → the format.
FORMAT_ALIASES: dict[str, str] = {a: f.name for f in RUN_FORMATS for a in (f.name, *f.aliases)}
#: File-name ending → format.
EXTENSIONS: dict[str, str] = {e: f.name for f in RUN_FORMATS for e in f.extensions}
#: Content type → format.
CONTENT_TYPE_FORMATS: dict[str, str] = {c: f.name for f in RUN_FORMATS for c in f.content_types}
_BY_NAME = {f.name: f for f in RUN_FORMATS}


def format_of_alias(value: str) -> str | None:
    """The format a declared name means (any case, surrounding blanks ignored); None: none."""
    return FORMAT_ALIASES.get(value.strip().lower())


def format_of_name(filename: str | None) -> tuple[str, str] | None:
    """``(format, extension)`` a file name's ending names (the longest match), or None."""
    if not filename:
        return None
    name = filename.lower()
    for ext in sorted(EXTENSIONS, key=len, reverse=True):
        if name.endswith(ext):
            return EXTENSIONS[ext], ext
    return None


def extensions_of(*names: str) -> tuple[str, ...]:
    """The file-name endings of the formats ``names``."""
    return tuple(e for n in names for e in _BY_NAME[n].extensions)
