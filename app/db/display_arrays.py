"""Display queries answered from memory: a published job's profile columns as numpy arrays.

A published job's profile rows never change, so an API process may keep the
columns a display query reads (``bin``, ``km``, ``display_level`` and the asked
indicator columns of one wheel) as immutable arrays and answer every zoom of
that wheel by slicing them (``searchsorted`` on km), instead of reading ~10⁴
rows from the database per answer. :class:`DisplayArrays` is that per-process
cache: bounded by bytes (least recently used wheels dropped), each wheel read
once (concurrent queries of a wheel being read wait for that read), columns
added to a wheel's entry as queries ask for them.

The rows chosen and the answer are exactly those of
:func:`app.db.display.display_rows` (the same level, the same rows, the same
:func:`~app.db.display.display_frame`); a wheel too large for the budget, or
whose km does not grow strictly with the bin, is answered by SQL.
"""

from __future__ import annotations

import logging
import threading
from collections import OrderedDict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd
from sqlalchemy import select
from sqlalchemy.orm import Session

from app.analysis.aggregate import DISPLAY_LEVEL_BASE
from app.core.bytecache import ByteLRU
from app.db.display import display_frame, display_level_of
from app.db.models import ProfileBin
from app.db.numeric import fetch_numeric
from app.db.results_reader import (
    job_bin_length,
    profile_where,
    stored_profile_wheels,
)
from app.db.session import Database

__all__ = ["WheelArrays", "DisplayArrays"]

_log = logging.getLogger(__name__)

#: bytes per row of a wheel's entry besides its indicator columns: bin (int64), km (float64),
#: display level (int16) and the positions of the levels >= 1 (int64, at most half the rows
#: and a quarter of that per further level: < 2/3 of a position per row)
_BASE_ROW_BYTES = 8 + 8 + 2 + 6
#: what the marker of a wheel not served from memory counts in the budget, bytes
_MARKER_BYTES = 64
#: bins read per query when a wheel is read (bounds the memory of the Python rows: ~10 MB)
_PAGE_BINS = 50_000
#: published jobs whose bin length and wheels are kept (:meth:`DisplayArrays.job_layout`)
_MAX_LAYOUTS = 4096


@dataclass(frozen=True)
class WheelArrays:
    """One wheel's stored profile of one job, in bin order (immutable arrays).

    Attributes
    ----------
    bins : numpy.ndarray of int64
        (n,) bin indices, strictly increasing.
    km : numpy.ndarray of float64
        (n,) bin centres, km, strictly increasing.
    levels : numpy.ndarray of int16
        (n,) display level of every bin (:func:`~app.analysis.aggregate.display_levels`).
    at_level : tuple of numpy.ndarray
        ``at_level[k - 1]``: positions (into the arrays) of the bins of level >= k, k >= 1.
    columns : mapping of str to numpy.ndarray
        (n,) float64 indicator columns (NULL -> NaN), as the database cursor gives them.
    """

    bins: np.ndarray
    km: np.ndarray
    levels: np.ndarray
    at_level: tuple[np.ndarray, ...]
    columns: Mapping[str, np.ndarray]

    @classmethod
    def build(cls, bins: np.ndarray, km: np.ndarray, levels: np.ndarray,
              columns: Mapping[str, np.ndarray]) -> WheelArrays:
        """The entry of arrays read in bin order (made read-only; positions per level computed)."""
        top = int(levels.max()) if len(levels) else 0
        at_level = tuple(np.flatnonzero(levels >= k) for k in range(1, top + 1))
        for array in (bins, km, levels, *at_level, *columns.values()):
            array.setflags(write=False)
        return cls(bins, km, levels, at_level, dict(columns))

    @property
    def nbytes(self) -> int:
        """Memory held, bytes."""
        arrays = (self.bins, self.km, self.levels, *self.at_level, *self.columns.values())
        return sum(a.nbytes for a in arrays)

    def with_columns(self, columns: Mapping[str, np.ndarray]) -> WheelArrays:
        """This entry and more columns (the arrays are shared, not copied)."""
        for array in columns.values():
            array.setflags(write=False)
        return WheelArrays(self.bins, self.km, self.levels, self.at_level, {**self.columns, **columns})

    def positions(self, level: int, km_from: float | None, km_to: float | None) -> np.ndarray:
        """Positions of the rows :func:`~app.db.display.display_rows` reads at ``level``, in bin order.

        The rows of the km range (inclusive) of level >= ``level`` and every row
        of the range in the (partial) buckets of ``DISPLAY_LEVEL_BASE**level``
        bins cut by its two ends; all rows of the range at level 0.
        """
        i0 = 0 if km_from is None else int(np.searchsorted(self.km, km_from, side="left"))
        i1 = len(self.km) if km_to is None else int(np.searchsorted(self.km, km_to, side="right"))
        if i1 <= i0:
            return np.empty(0, dtype=np.int64)
        if level == 0:
            return np.arange(i0, i1)
        at = self.at_level[level - 1] if level <= len(self.at_level) else np.empty(0, dtype=np.int64)
        inside = at[np.searchsorted(at, i0):np.searchsorted(at, i1)]
        span = DISPLAY_LEVEL_BASE**level
        first = (int(self.bins[i0]) // span) * span
        last = (int(self.bins[i1 - 1]) // span) * span
        head = np.arange(i0, min(int(np.searchsorted(self.bins, first + span)), i1))
        tail = np.arange(max(int(np.searchsorted(self.bins, last)), i0), i1)
        return np.union1d(inside, np.concatenate([head, tail]))

    def values(self, positions: np.ndarray, numeric: Sequence[str]) -> np.ndarray:
        """(len(positions), len(numeric)) float rows, as :func:`~app.db.results_reader.fetch_numeric` reads them."""
        out = np.empty((len(positions), len(numeric)), dtype=np.float64)
        for j, name in enumerate(numeric):
            source = self.bins if name == "bin" else self.km if name == "km" else self.columns[name]
            out[:, j] = source[positions]
        return out


class DisplayArrays:
    """Per-process cache of :class:`WheelArrays` of published jobs, bounded by bytes (LRU).

    Parameters
    ----------
    max_bytes : int
        Budget, bytes (0 turns it off: every display query reads the
        database). A wheel whose entry would take more than a quarter of it is
        not kept (its queries read the database).
    background : bool, optional
        Read a wheel's arrays in a background thread and answer from the
        database meanwhile (default; no query waits for a read of ~10⁶ rows),
        or read them in the asking thread (queries of a wheel being read wait).

    Notes
    -----
    Only for jobs whose rows never change (published results): the entries
    are keyed by job and wheel and never refreshed. Thread-safe: the worker
    threads of the API compute answers at once; a wheel is read by one of
    them while the others asking for it wait.
    """

    def __init__(self, max_bytes: int, *, background: bool = True) -> None:
        self._background = background
        # False: a wheel known not to be served from memory (see display_rows)
        self._lru: ByteLRU[WheelArrays | bool] = ByteLRU(max_bytes)
        self._guard = threading.Lock()
        self._reading: dict[str, threading.Event] = {}
        self._one_read = threading.Lock()
        self._layouts: OrderedDict[int, tuple[float, tuple[str, ...]]] = OrderedDict()

    @property
    def max_bytes(self) -> int:
        """The budget, bytes."""
        return self._lru.max_bytes

    @property
    def size(self) -> int:
        """Bytes held now."""
        return self._lru.size

    def display_rows(
        self,
        db: Database,
        job_id: int,
        wheel: str,
        max_points: int,
        bin_length_m: float,
        *,
        km_from: float | None = None,
        km_to: float | None = None,
        columns: Sequence[str],
    ) -> tuple[pd.DataFrame, tuple[float, float]] | None:
        """:func:`app.db.display.display_rows` and the :func:`~app.db.display.km_extent`, from memory.

        Parameters are those of :func:`~app.db.display.display_rows` (``columns``
        must hold ``bin``, ``km`` and ``sleeper_amp``). The wheel's arrays are
        read on first use (in their own read transaction of ``db``).

        Returns
        -------
        (pandas.DataFrame, (float, float)) or None
            The rows and the wheel's km extent; None where the wheel cannot be
            answered from memory (not read yet, no rows, too large for the
            budget, km not strictly increasing with the bin, cache off): ask
            the database.
        """
        numeric = [c for c in columns if c != "wheel"]
        wanted = [c for c in numeric if c not in ("bin", "km")]
        arrays = self._arrays(db, job_id, wheel, wanted)
        if arrays is None:
            return None
        extent = (float(arrays.km[0]), float(arrays.km[-1]))
        level = display_level_of(extent, km_from, km_to, max_points, bin_length_m)
        values = arrays.values(arrays.positions(level, km_from, km_to), numeric)
        return display_frame(values, numeric, columns, wheel, max_points), extent

    def job_layout(self, session: Session, job_id: int) -> tuple[float, tuple[str, ...]]:
        """Bin length (m) and wheels of a published job's profile, read once per process.

        They never change once the job is published (its rows are stored
        before it is marked done); the last :data:`_MAX_LAYOUTS` jobs asked are kept.
        """
        with self._guard:
            layout = self._layouts.get(job_id)
            if layout is not None:
                self._layouts.move_to_end(job_id)
                return layout
        layout = (job_bin_length(session, job_id), tuple(stored_profile_wheels(session, job_id)))
        with self._guard:
            self._layouts[job_id] = layout
            while len(self._layouts) > _MAX_LAYOUTS:
                self._layouts.popitem(last=False)
        return layout

    def wait(self, timeout: float | None = None) -> bool:
        """Wait until no wheel is being read (tests, benchmarks); whether none is."""
        with self._guard:
            pending = list(self._reading.values())
        return all(event.wait(timeout) for event in pending)

    def _arrays(self, db: Database, job_id: int, wheel: str, wanted: Sequence[str]) -> WheelArrays | None:
        """The wheel's entry holding ``wanted`` columns, or None (then being read, or not to be).

        A wheel is read once at a time (single flight). In the background
        (the default) a query never waits for it: until the arrays are there
        the database answers, as fast as without them.
        """
        if self.max_bytes == 0:
            return None
        key = f"{job_id}:{wheel}"
        while True:
            with self._guard:
                held = self._lru.get(key)
                if held is False:  # known not to be served from memory
                    return None
                entry = held if isinstance(held, WheelArrays) else None
                if entry is not None and all(c in entry.columns for c in wanted):
                    return entry
                reading = self._reading.get(key)
                if reading is None:
                    reading = self._reading[key] = threading.Event()
                    break
            if self._background:
                return None
            reading.wait()  # another thread reads this wheel: then look again
        args = (key, db, job_id, wheel, entry, wanted, reading)
        if self._background:
            threading.Thread(target=self._fill, args=args, name=f"display-arrays-{key}", daemon=True).start()
            return None
        return self._fill(*args)

    def _fill(self, key: str, db: Database, job_id: int, wheel: str, entry: WheelArrays | None,
              wanted: Sequence[str], reading: threading.Event) -> WheelArrays | None:
        """Read and keep the wheel's entry (or the columns ``entry`` lacks); then wake the waiters."""
        try:
            with self._one_read:  # one wheel at a time: bounded memory and CPU taken from answers
                read = self._read(db, job_id, wheel, entry, wanted)
            if read is not None:
                self._lru.put(key, read, read.nbytes)
            elif entry is None:  # remembered (a small marker): not read again
                self._lru.put(key, False, _MARKER_BYTES)
            return read
        except Exception:  # the database answers meanwhile; a later query tries again
            if not self._background:
                raise
            _log.warning("reading display arrays of job %s wheel %s failed", job_id, wheel, exc_info=True)
            return None
        finally:
            with self._guard:
                del self._reading[key]
            reading.set()

    def _read(self, db: Database, job_id: int, wheel: str, entry: WheelArrays | None,
              wanted: Sequence[str]) -> WheelArrays | None:
        """Read the wheel (or the columns ``entry`` lacks) from the database; None if not to be kept."""
        where = profile_where(job_id, wheel, None, None)
        held = entry.columns if entry is not None else {}
        missing = list(dict.fromkeys(c for c in wanted if c not in held))
        with db.read() as session:
            lo = session.scalar(select(ProfileBin.bin).where(where).order_by(ProfileBin.bin).limit(1))
            if lo is None:
                return None
            hi = session.scalar(select(ProfileBin.bin).where(where).order_by(ProfileBin.bin.desc()).limit(1))
            n_columns = len(held) + len(missing)
            if (int(hi) - int(lo) + 1) * (_BASE_ROW_BYTES + 8 * n_columns) > self.max_bytes // 4:
                return None
            if entry is None:
                names = ["bin", "km", "display_level", *missing]
            else:
                names = ["bin", *missing]
            stmt = select(*(getattr(ProfileBin, c) for c in names)).where(where).order_by(ProfileBin.bin)
            pages = []  # in pages of bins: the DBAPI rows of a page are Python objects (~200 B each)
            for start in range(int(lo), int(hi) + 1, _PAGE_BINS):
                page = stmt.where(ProfileBin.bin.between(start, start + _PAGE_BINS - 1))
                pages.append(fetch_numeric(session, page, len(names)))
        rows = np.concatenate(pages)
        read = {name: np.ascontiguousarray(rows[:, j]) for j, name in enumerate(names)}
        bins = read.pop("bin").astype(np.int64)
        if entry is not None:
            if not np.array_equal(bins, entry.bins):  # cannot happen for a published job: do not mix
                return None
            return entry.with_columns(read)
        km = read.pop("km")
        levels = read.pop("display_level").astype(np.int16)
        if len(bins) == 0 or not (np.all(np.diff(bins) > 0) and np.all(np.diff(km) > 0)):
            return None  # km must grow strictly with the bin for slicing by km (NaN fails too)
        return WheelArrays.build(bins, km, levels, read)
