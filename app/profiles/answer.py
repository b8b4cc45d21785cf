"""The answer of a profile query: the rows read (from the process' display arrays, the stored
display pyramid or the full rows), the stiffness index added, aggregated to the level,
decimated to ``max_points`` keeping the peaks, and encoded (:mod:`app.profiles.encoding`).

The head of an answer has the fields of :class:`app.api.schemas.profiles.ProfileOut` (its
OpenAPI schema) besides ``rows``/``data``, in the same order.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from app.analysis.aggregate import aggregate_profile, display_indices
from app.analytics.stiffness_index import INDEX_COLUMNS
from app.core.jsonable import jsonable
from app.db import results_reader
from app.db.display import display_rows, km_extent
from app.db.display_arrays import DisplayArrays
from app.db.models import PROFILE_VALUE_COLUMNS
from app.db.session import Database
from app.profiles.encoding import columns_json, encoded, rows_json
from app.profiles.query import AGGREGATED_COLUMNS, ProfileQuery
from app.settings import Settings

__all__ = ["aggregate", "decimate", "profile_body", "Computed", "compute"]

#: an answer's body and, when kept in memory, its cache entry (body, gzip body or None)
Computed = tuple[bytes, tuple[bytes, bytes | None] | None]


def aggregate(
    df: pd.DataFrame, level_m: float, bin_length: float, columns: Sequence[str] | None = None
) -> pd.DataFrame:
    """Segments of ``level_m`` (mean, max, p95 of the indicator columns and of the index columns present)."""
    wanted = AGGREGATED_COLUMNS if columns is None else [c for c in columns if c in AGGREGATED_COLUMNS]
    wanted = [*wanted, *(c for c in INDEX_COLUMNS if c in df.columns)]
    out = aggregate_profile(df, level_m, list(wanted), bin_length)
    out.insert(0, "wheel", df["wheel"].iloc[0] if len(df) else "")
    return out


def decimate(df: pd.DataFrame, max_points: int, column: str) -> pd.DataFrame:
    """At most ``max_points`` rows of ``df`` keeping the peaks of ``column``."""
    if len(df) <= max_points:
        return df
    km_col = "km" if "km" in df.columns else "km_from"
    idx = display_indices(
        df[km_col].to_numpy(dtype=np.float64),
        df[column].to_numpy(dtype=np.float64, na_value=np.nan),
        max_points,
    )
    return df.iloc[idx].reset_index(drop=True)


def profile_body(
    db: Database, settings: Settings, query: ProfileQuery, arrays: DisplayArrays | None = None
) -> bytes:
    """The encoded answer of a profile query (read, aggregate, decimate, encode).

    ``arrays``: the process' display arrays, which answer display queries
    (``max_points`` at the stored bins) from memory where they can.
    """
    q = query
    run_id, job_id, bin_length, k, wheel = q.run_id, q.job_id, q.bin_length, q.k, q.wheel
    km_from, km_to, level, max_points, values = q.km_from, q.km_to, q.level, q.max_points, q.values
    ctx = q.index
    read = {"wheel": wheel, "km_from": km_from, "km_to": km_to, "columns": values}
    if values is not None and k > 1:  # a segment's 1-σ needs the shared part of its bins' (aggregate_profile)
        read["columns"] = [*values, *(f"{c}_shared" for c in values
                                      if f"{c}_shared" in PROFILE_VALUE_COLUMNS and f"{c}_shared" not in values)]
    in_memory = None
    if arrays is not None and max_points is not None and k == 1:  # a published job's arrays
        in_memory = arrays.display_rows(db, job_id, wheel, max_points, bin_length, km_from=km_from, km_to=km_to,
                                        columns=results_reader.profile_columns(values))
    if in_memory is not None:
        df, extent = in_memory
    else:
        with db.read() as session:  # one snapshot: the extent and the rows of the same job
            extent = km_extent(session, job_id, wheel)
            if max_points is not None and k == 1:
                # a few thousand rows of the stored display pyramid, whatever the range
                df = display_rows(session, job_id, wheel, max_points, bin_length, km_from=km_from, km_to=km_to,
                                  columns=results_reader.profile_columns(values), extent=extent)
            elif max_points is None and k == 1:
                df = results_reader.job_profile_frame(session, job_id, limit=settings.max_profile_rows + 1, **read)
            else:
                df = results_reader.job_profile_frame(session, job_id, **read)
    if ctx is not None:
        df = ctx.add_columns(df)
    truncated = False
    if max_points is not None and k > 1:
        df = decimate(aggregate(df, level, bin_length, values), max_points, "sleeper_amp_max")
    elif max_points is None:
        if k > 1:
            df = aggregate(df, level, bin_length, values)
        truncated = len(df) > settings.max_profile_rows
        df = df.iloc[: settings.max_profile_rows]
    head = jsonable({
        "run_id": run_id,
        "job_id": job_id,
        "wheel": wheel,
        "level_m": float(level),
        "bin_length_m": float(bin_length),
        "km_from": None if km_from is None else float(km_from),
        "km_to": None if km_to is None else float(km_to),
        "km_extent": [float(x) for x in extent] if extent is not None else None,
        "max_points": max_points,
        "n_rows": len(df),
        "truncated": truncated,
        "columns": [str(c) for c in df.columns],
        "reference": ctx.describe() if ctx is not None else None,
        "step_estimate_stored": q.steps_stored,
    })
    return columns_json(head, df) if q.layout == "columns" else rows_json(head, df)


def compute(db: Database, settings: Settings, query: ProfileQuery, keep_bytes: int,
            arrays: DisplayArrays | None) -> Computed:
    """The answer's body and, if at most ``keep_bytes`` long, its cache entry (body, gzip body)."""
    body = profile_body(db, settings, query, arrays)
    return body, encoded(body) if len(body) <= keep_bytes else None
