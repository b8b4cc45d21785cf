"""Reads for display: a few columns of a long profile, then whole rows of chosen bins."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd
from sqlalchemy import and_, select
from sqlalchemy.orm import Session

from app.db.crud import PROFILE_COLUMNS, profile_frame
from app.db.models import ProfileBin

__all__ = ["profile_column_arrays", "profile_rows_of_bins"]

_IN_BATCH = 900  # bins per IN (...) list: below SQLite's oldest variable limit


def _where(run_id: int, wheel: str, km_from: float | None, km_to: float | None):
    conditions = [ProfileBin.run_id == run_id, ProfileBin.wheel == wheel]
    if km_from is not None:
        conditions.append(ProfileBin.km >= km_from)
    if km_to is not None:
        conditions.append(ProfileBin.km <= km_to)
    return and_(*conditions)


def profile_column_arrays(
    session: Session,
    run_id: int,
    wheel: str,
    columns: Sequence[str],
    *,
    km_from: float | None = None,
    km_to: float | None = None,
) -> dict[str, np.ndarray]:
    """``bin`` (int64) and ``columns`` (float64, NULL -> NaN) of one wheel's profile, by km.

    Reading a few columns of a long run is several times faster than whole rows,
    which is what display decimation needs to choose its rows.
    """
    unknown = [c for c in columns if c not in PROFILE_COLUMNS or c in ("wheel", "bin")]
    if unknown:
        raise ValueError(f"columns: unknown or non-numeric profile column(s) {unknown}")
    cols = [ProfileBin.bin, *(getattr(ProfileBin, c) for c in columns)]
    # ordered by km along the (run_id, wheel, km) index: no sort; km grows with the bin
    stmt = select(*cols).where(_where(run_id, wheel, km_from, km_to)).order_by(ProfileBin.km)
    rows = session.connection().execute(stmt).all()
    data = list(zip(*rows, strict=True)) if rows else [()] * len(cols)
    out: dict[str, np.ndarray] = {"bin": np.array(data[0], dtype=np.int64)}
    for i, name in enumerate(columns, start=1):
        out[name] = np.array(data[i], dtype=np.float64)  # None -> NaN
    return out


def profile_rows_of_bins(session: Session, run_id: int, wheel: str, bins: np.ndarray) -> pd.DataFrame:
    """Whole stored rows (:data:`~app.db.crud.PROFILE_COLUMNS`) of the given bins of one wheel, by bin."""
    wanted = np.unique(np.asarray(bins, dtype=np.int64))
    cols = [getattr(ProfileBin, c) for c in PROFILE_COLUMNS]
    rows: list = []
    for start in range(0, wanted.size, _IN_BATCH):
        part = [int(b) for b in wanted[start : start + _IN_BATCH]]
        stmt = select(*cols).where(
            ProfileBin.run_id == run_id, ProfileBin.wheel == wheel, ProfileBin.bin.in_(part)
        )
        rows.extend(session.connection().execute(stmt).all())
    df = profile_frame(rows)
    return df.sort_values("bin", kind="stable").reset_index(drop=True)
