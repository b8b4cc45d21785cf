"""CSV input: a header row, one column per channel, optional ``time`` column.

The text after the header is read in pieces of about
``IngestLimits.csv_block_bytes`` cut at line ends, each checked (no NUL byte,
valid UTF-8, no line longer than ``IngestLimits.max_line_bytes``) before
pandas parses it: the parser's memory is bounded by the piece, whatever the
file holds (a 200 MB single-line file is refused after reading 8 MiB of it).
"""

from __future__ import annotations

import gzip
import io
import re
from collections.abc import Iterator
from pathlib import Path
from typing import IO

import numpy as np
import pandas as pd

from app.core.i18n import _
from app.io.channels import TIME_COLUMN
from app.io.errors import RunFileError
from app.io.limits import DEFAULT_LIMITS, IngestLimits
from app.io.sources.base import Source, SourceInfo, map_channel_names

__all__ = ["CsvSource", "BoundedGzipReader", "text_pieces"]


class BoundedGzipReader(io.RawIOBase):
    """A gzip file read as a binary stream that stops at a decompressed-size limit.

    Parameters
    ----------
    path : Path
        gzip-compressed file.
    limit : int
        Largest number of decompressed bytes; reading past it raises
        :class:`RunFileError` (``field == "file"``): a decompression bomb.
    """

    def __init__(self, path: Path, limit: int) -> None:
        super().__init__()
        self._gz = gzip.open(path, "rb")
        self._limit = int(limit)
        self.count = 0

    def readable(self) -> bool:
        return True

    def readinto(self, buffer) -> int:  # noqa: ANN001 - a writable buffer
        view = memoryview(buffer)
        n = self._gz.readinto(view)
        self.count += n
        if self.count > self._limit:
            raise RunFileError(
                "file",
                _("the gzip file decompresses to more than {limit} bytes (decompression bomb limit, TRACKVKF ingest max_expansion_ratio)", limit=self._limit),
            )
        return n

    def close(self) -> None:
        self._gz.close()
        super().close()


def _open(path: Path, compression: str | None, limits: IngestLimits):
    if compression == "gzip":
        limit = limits.max_decoded_bytes(path.stat().st_size)
        return io.BufferedReader(BoundedGzipReader(path, limit), buffer_size=1 << 20)
    return open(path, "rb")  # noqa: SIM115 - closed by the caller


def _scan_gzip(path: Path, limits: IngestLimits) -> None:
    """Decompress once without parsing: a bomb is refused before pandas sees a byte."""
    try:
        with BoundedGzipReader(path, limits.max_decoded_bytes(path.stat().st_size)) as raw:
            buffer = bytearray(1 << 20)
            while raw.readinto(buffer):
                pass
    except (OSError, EOFError, gzip.BadGzipFile) as exc:
        raise RunFileError("file", _("cannot read gzip file: {error}", error=exc)) from None


def _first_line(path: Path, compression: str | None, limits: IngestLimits) -> str:
    try:
        with _open(path, compression, limits) as fh:
            raw = fh.readline(limits.max_header_bytes + 1)
    except (OSError, EOFError, gzip.BadGzipFile) as exc:
        raise RunFileError("file", _("cannot read CSV file: {error}", error=exc)) from None
    if len(raw) > limits.max_header_bytes or (
        len(raw) == limits.max_header_bytes and not raw.endswith(b"\n")
    ):
        raise RunFileError(
            "file",
            _("the header row is longer than {max_header_bytes} bytes (at most {max_columns} columns are accepted)", max_header_bytes=limits.max_header_bytes, max_columns=limits.max_columns),
        )
    return raw.decode("utf-8", errors="replace").lstrip("\ufeff")


class CsvSource(Source):
    """Read a delimited text file in chunks (pandas ``chunksize``).

    The delimiter (``,``, ``;`` or tab) is taken from the header line. Empty
    cells and ``NaN``/``NA``/``null`` read as NaN.

    Parameters
    ----------
    path : Path
        Input file.
    compression : str or None
        ``"gzip"`` for a gzip-compressed file (decompressed size bounded by
        ``limits.max_decoded_bytes``).
    limits : IngestLimits
        Header length and column count limits.
    """

    def __init__(
        self, path: Path, compression: str | None = None, limits: IngestLimits = DEFAULT_LIMITS
    ) -> None:
        self._path = path
        self._compression = compression
        self._limits = limits
        if compression == "gzip":
            _scan_gzip(path, limits)
        header = _first_line(path, compression, limits)
        if not header.strip():
            raise RunFileError("file", _("CSV file has no header row"))
        self._sep = next((s for s in (",", ";", "\t") if s in header), ",")
        n_columns = header.count(self._sep) + 1
        if n_columns > limits.max_columns:
            raise RunFileError(
                "file", _("{n_columns} columns exceed the limit of {max_columns}", n_columns=n_columns, max_columns=limits.max_columns)
            )
        columns = [c.strip().strip('"').strip("'") for c in header.rstrip("\r\n").split(self._sep)]
        self._names = map_channel_names(columns)
        self._columns = columns
        canon = list(self._names.values())
        self.info = SourceInfo(
            channels=[c for c in canon if c != TIME_COLUMN],
            has_time=TIME_COLUMN in canon,
        )

    def blocks(self, size: int) -> Iterator[dict[str, np.ndarray]]:
        try:
            handle = _open(self._path, self._compression, self._limits)
        except (OSError, gzip.BadGzipFile) as exc:
            raise RunFileError("file", _("cannot read CSV file: {error}", error=exc)) from None
        row = 0
        try:
            for text, first_line in text_pieces(handle, self._limits):
                frame = self._parse(text, first_line)
                for a in range(0, len(frame), size):
                    part = frame.iloc[a : a + size]
                    yield {canon: _numeric(part[orig], orig, row) for orig, canon in self._names.items()}
                    row += len(part)
        except RunFileError:
            raise
        except (OSError, EOFError, gzip.BadGzipFile) as exc:
            raise RunFileError("file", _("cannot read CSV file: {error}", error=_cut(str(exc)))) from None
        finally:
            handle.close()

    def _parse(self, text: bytes, first_line: int) -> pd.DataFrame:
        """Parse one piece of complete lines (numbered from ``first_line``) into a frame."""
        try:
            return pd.read_csv(
                io.BytesIO(text),
                sep=self._sep,
                header=None,
                names=self._columns,
                skipinitialspace=True,
                engine="c",
            )
        except pd.errors.EmptyDataError:
            return pd.DataFrame(columns=self._columns)
        except (pd.errors.ParserError, ValueError) as exc:
            message = _LINE_IN_MESSAGE.sub(
                lambda m: f"line {int(m.group(1)) + first_line - 1}", str(exc)
            )
            raise RunFileError("file", _("cannot parse CSV: {error}", error=_cut(message))) from None


_NEWLINE = b"\n"
#: "line N" in pandas' parser errors (N counted from the start of a piece)
_LINE_IN_MESSAGE = re.compile(r"line (\d+)")


def _cut(text: str, limit: int = 200) -> str:
    return text if len(text) <= limit else text[: limit - 1] + "…"


def text_pieces(handle: IO[bytes], limits: IngestLimits) -> Iterator[tuple[bytes, int]]:
    """The text after a CSV's header line in checked pieces of complete lines.

    Parameters
    ----------
    handle : binary file
        The CSV text from its first byte (the header line).
    limits : IngestLimits
        ``csv_block_bytes`` (size of a piece) and ``max_line_bytes``.

    Yields
    ------
    text : bytes
        At most ``csv_block_bytes`` bytes ending at a line end (or the end of
        the file).
    first_line : int
        Number of the piece's first line (the header is line 1).

    Raises
    ------
    RunFileError
        ``field == "file"``, naming the byte offset and line: a NUL byte, bytes
        that are not UTF-8, or a line longer than ``max_line_bytes``.
    """
    pending = b""  # the unfinished last line of what was read
    pos = 0  # offset of pending[0] in the text
    line = 1  # number of pending's first line
    header = True
    eof = False
    while not eof:
        data = handle.read(limits.csv_block_bytes - len(pending))
        eof = not data
        buf = pending + data
        _check_text(buf, pos, line, eof)
        codes = np.frombuffer(buf, dtype=np.uint8)
        ends = np.flatnonzero(codes == 0x0A)
        starts = np.concatenate(([0], ends + 1))
        lengths = np.concatenate((ends, [len(buf)])) - starts  # the last: unfinished unless eof
        long = np.flatnonzero(lengths > limits.max_line_bytes)
        if long.size:
            i = int(long[0])
            raise RunFileError(
                "file",
                _("line {line} (from byte {byte}) is longer than {max_line_bytes} bytes; a run has at most 64 numeric columns", line=line + i, byte=pos + int(starts[i]), max_line_bytes=limits.max_line_bytes),
            )
        cut = len(buf) if eof else (int(ends[-1]) + 1 if ends.size else 0)
        piece, pending = buf[:cut], buf[cut:]
        first_line = line
        if header and ends.size:  # the header line was read by CsvSource itself
            skip = int(ends[0]) + 1
            piece, first_line, header = piece[skip:], line + 1, False
        elif header:
            piece = b""
        if piece.strip():
            yield piece, first_line
        line += int(ends.size)  # every line end lies before the cut
        pos += cut


def _check_text(buf: bytes, pos: int, line: int, eof: bool) -> None:
    """No NUL byte and valid UTF-8 in ``buf`` (text offset ``pos``, first line ``line``).

    A multi-byte character cut by the end of ``buf`` is left for the next
    piece unless ``eof``.
    """
    nul = buf.find(b"\x00")
    if nul >= 0:
        where = line + buf.count(_NEWLINE, 0, nul)
        raise RunFileError(
            "file", _("NUL byte at byte {byte} (line {where}): a CSV file must be UTF-8 text", byte=pos + nul, where=where)
        )
    try:
        buf.decode("utf-8")
    except UnicodeDecodeError as exc:
        if not eof and exc.reason == "unexpected end of data":
            return
        where = line + buf.count(_NEWLINE, 0, exc.start)
        raise RunFileError(
            "file",
            _("not UTF-8 text: byte 0x{code:02x} at byte {byte} (line {where}); save the file as UTF-8", code=buf[exc.start], byte=pos + exc.start, where=where),
        ) from None


def _numeric(col: pd.Series, name: str, row0: int) -> np.ndarray:
    if pd.api.types.is_bool_dtype(col.dtype):
        raise RunFileError(name, _("wrong dtype bool: channels must be numeric"))
    if pd.api.types.is_numeric_dtype(col.dtype):
        return col.to_numpy(dtype=np.float64, na_value=np.nan)
    values = pd.to_numeric(col, errors="coerce")
    bad = values.isna() & col.notna()
    if bad.any():
        i = int(np.flatnonzero(bad.to_numpy())[0])
        raise RunFileError(
            name, _("wrong dtype: non-numeric value {value} in data row {row}", value=_cut(repr(col.iloc[i]), 60), row=row0 + i + 1)
        )
    return values.to_numpy(dtype=np.float64, na_value=np.nan)
