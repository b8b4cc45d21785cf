"""Reads for display: the rows of a km range that a plot of a few thousand points needs.

:func:`display_rows` reads one display level of the stored min–max pyramid
(``profile_bins.display_level``, ranked when the rows are stored): for any km
range and zoom a few thousand rows, never the 400 000 rows per wheel of a 100 km
run: coarse levels through the partial index on (job, wheel, km, level) with the
level filtered inside it, short ranges as bin ranges of the primary key.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd
from sqlalchemy import literal_column, select
from sqlalchemy.orm import Session

from app.analysis.aggregate import DISPLAY_LEVEL_BASE, display_indices
from app.db.models import COARSE_DISPLAY_LEVEL, ProfileBin
from app.db.numeric import fetch_numeric
from app.db.results_reader import (
    PROFILE_COLUMNS,
    numeric_frame,
    profile_frame,
    profile_where,
)

__all__ = ["display_rows", "km_extent", "display_level_of", "display_frame"]

#: a level is read when it holds at most this many times ``max_points`` rows in the range;
#: the final decimation to ``max_points`` then chooses among the peaks of buckets
#: ``DISPLAY_LEVEL_BASE`` times finer than the plot's
_OVERSAMPLE = DISPLAY_LEVEL_BASE


def km_extent(session: Session, job_id: int, wheel: str) -> tuple[float, float] | None:
    """(smallest, largest) km of one wheel's profile by job ``job_id``, or None.

    Two primary-key lookups: the first and the last bin (km grows with the bin).
    """
    where = profile_where(job_id, wheel, None, None)
    lo = session.scalar(select(ProfileBin.km).where(where).order_by(ProfileBin.bin).limit(1))
    if lo is None:
        return None
    hi = session.scalar(select(ProfileBin.km).where(where).order_by(ProfileBin.bin.desc()).limit(1))
    return float(lo), float(hi)


def _display_level(n_bins: float, max_points: int) -> int:
    """Coarsest-needed level: at most ``_OVERSAMPLE × max_points`` rows for ``n_bins`` bins."""
    k = 0
    # level k holds <= 2 rows per bucket of BASE**k bins (+ the partial buckets at both ends)
    while min(n_bins, 2 * (n_bins / DISPLAY_LEVEL_BASE**k + 2)) > _OVERSAMPLE * max_points and k < 30:
        k += 1
    return k


def display_level_of(
    extent: tuple[float, float],
    km_from: float | None,
    km_to: float | None,
    max_points: int,
    bin_length_m: float,
) -> int:
    """The pyramid level a display query reads: from the bins of the range (km span / bin length).

    Parameters
    ----------
    extent : (float, float)
        The profile's :func:`km_extent`, km.
    km_from, km_to : float or None
        The asked range, km (None: the profile's end).
    max_points : int
        Rows wanted.
    bin_length_m : float
        Bin length of the stored profile, m.
    """
    lo = extent[0] if km_from is None else max(extent[0], km_from)
    hi = extent[1] if km_to is None else min(extent[1], km_to)
    n_bins = max(hi - lo, 0.0) * 1000.0 / bin_length_m + 1.0
    return _display_level(n_bins, max_points)


def display_frame(
    values: np.ndarray, numeric: Sequence[str], columns: Sequence[str], wheel: str, max_points: int
) -> pd.DataFrame:
    """The answer of a display query from the rows read for it (one rule for SQL and memory).

    Parameters
    ----------
    values : numpy.ndarray
        (n, len(numeric)) float rows read for the query (a bin may come twice).
    numeric : sequence of str
        Names of ``values``' columns (must hold ``bin``, ``km`` and ``sleeper_amp``).
    columns : sequence of str
        Columns of the answer (``numeric``, with ``wheel`` if asked).
    wheel : str
        The wheel (the same on every row).
    max_points : int
        Rows wanted: each bin once, ordered by km, decimated keeping the peaks
        of ``sleeper_amp`` (:func:`~app.analysis.aggregate.display_indices`).
    """
    i_bin, i_km = numeric.index("bin"), numeric.index("km")
    _, first = np.unique(values[:, i_bin], return_index=True)  # each bin once
    values = values[first]
    values = values[np.argsort(values[:, i_km], kind="stable")]
    if len(values) > max_points:
        keep = display_indices(values[:, i_km], values[:, numeric.index("sleeper_amp")], max_points)
        values = values[keep]
    df = numeric_frame(values, numeric)
    if "wheel" in columns:
        df.insert(0, "wheel", np.full(len(df), wheel, dtype=object))
    return df if list(df.columns) == list(columns) else df[list(columns)]


def display_rows(
    session: Session,
    job_id: int,
    wheel: str,
    max_points: int,
    bin_length_m: float,
    *,
    km_from: float | None = None,
    km_to: float | None = None,
    columns: Sequence[str] = PROFILE_COLUMNS,
    extent: tuple[float, float] | None = None,
) -> pd.DataFrame:
    """At most ``max_points`` whole rows of one wheel's profile in a km range, peaks kept.

    Parameters
    ----------
    job_id : int
        Job whose rows are read (the run's :func:`~app.db.results_reader.results_job_id`).
    max_points : int
        Rows wanted (>= 4).
    bin_length_m : float
        Bin length of the stored profile, m (to count the bins of the range).
    km_from, km_to : float, optional
        Range, km (default: the whole profile).
    columns : sequence of str, optional
        Columns to read (:func:`~app.db.results_reader.profile_columns`; must hold
        ``sleeper_amp``, which chooses the rows). Default: all.
    extent : (float, float), optional
        The profile's :func:`km_extent` if the caller already read it in the
        same transaction (default: read here).

    Returns
    -------
    pandas.DataFrame
        :data:`~app.db.results_reader.PROFILE_COLUMNS`, ordered by km.

    Notes
    -----
    The level is chosen from the number of bins in the range (km span /
    bin length). Its rows in the range (at most ``4 × max_points``) and all rows
    of the two buckets cut by the range's ends are read, then decimated to
    ``max_points`` by :func:`~app.analysis.aggregate.display_indices`: the first
    and last row of the range and its extremes are always kept.
    """
    if extent is None:
        extent = km_extent(session, job_id, wheel)
    if extent is None:
        return profile_frame([], columns)
    level = display_level_of(extent, km_from, km_to, max_points, bin_length_m)
    # numbers only, straight from the cursor into one array (the wheel is the same on every row)
    numeric = [c for c in columns if c != "wheel"]
    cols = [getattr(ProfileBin, c) for c in numeric]
    by_bin = profile_where(job_id, wheel, km_from, km_to, bin_length_m)  # primary key
    parts = []
    if level == 0:
        parts.append(fetch_numeric(session, select(*cols).where(by_bin), len(cols)))
    else:
        if level < COARSE_DISPLAY_LEVEL:  # a range of a few 4 × max_points bins: primary key
            stmt = select(*cols).where(by_bin, ProfileBin.display_level >= level)
        else:
            # the partial index over the coarse levels; its predicate written out
            # literally (SQLite uses a partial index only for a query repeating it)
            coarse = ProfileBin.display_level >= literal_column(str(int(COARSE_DISPLAY_LEVEL)))
            where = profile_where(job_id, wheel, km_from, km_to)
            stmt = select(*cols).where(where, coarse, ProfileBin.display_level >= level)
        parts.append(fetch_numeric(session, stmt, len(cols)))
        # and every row of the (partial) buckets at the range's two ends (primary
        # key): their stored extremes may lie outside the range
        span = DISPLAY_LEVEL_BASE**level
        for bin_order in (ProfileBin.bin, ProfileBin.bin.desc()):
            edge = session.scalar(select(ProfileBin.bin).where(by_bin).order_by(bin_order).limit(1))
            if edge is not None:
                start = (int(edge) // span) * span
                stmt = select(*cols).where(by_bin, ProfileBin.bin.between(start, start + span - 1))
                parts.append(fetch_numeric(session, stmt, len(cols)))
    return display_frame(np.concatenate(parts), numeric, columns, wheel, max_points)
