"""The results reader (app/db/results_reader.py) on a real SQLite database: km ranges
through the primary key select exactly the rows a plain filter selects, column subsets,
limits across wheels, keyset pages, which job a run shows."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from sqlalchemy import select

from app.db import crud, results_reader, results_writer
from app.db.models import PROFILE_VALUE_COLUMNS, JobStatus, ProfileBin
from app.db.session import Database
from tests.db.support import add_run, profile_table


def _published(db: Database, profiles: pd.DataFrame, bin_length_m: float = 0.25) -> tuple[int, int]:
    """A run whose done job holds ``profiles``: (run id, job id)."""
    run_id = add_run(db)
    with db.write() as s:
        job = crud.create_job(s, run_id, {"bin_length_m": bin_length_m})
        results_writer.store_profile_rows(s, run_id, job.id, profiles)
        results_writer.publish_results(s, run_id, job.id, [])
        job.status = JobStatus.DONE
        return run_id, job.id


def test_km_range_through_bin_range_selects_exactly_the_rows_in_it(db):
    bin_length = 0.1
    profiles = profile_table(("11",), n_bins=2_000, first_bin=-700, bin_length_m=bin_length)
    _, job_id = _published(db, profiles, bin_length)
    km = profiles["km"].to_numpy()
    rng = np.random.default_rng(11)
    cases = [(None, None), (km[0], km[-1]), (km[10], km[10]), (km[3] + 1e-9, km[4] - 1e-9)]
    cases += [tuple(sorted(rng.uniform(km[0] - 0.01, km[-1] + 0.01, 2))) for _ in range(30)]
    cases += [(a, None) for a in rng.uniform(km[0], km[-1], 5)] + [(None, b) for b in rng.uniform(km[0], km[-1], 5)]
    with db.read() as s:
        for km_from, km_to in cases:
            inside = np.ones(len(km), dtype=bool)
            if km_from is not None:
                inside &= km >= km_from
            if km_to is not None:
                inside &= km <= km_to
            for length in (None, bin_length):
                where = results_reader.profile_where(job_id, "11", km_from, km_to, length)
                got = s.scalars(select(ProfileBin.bin).where(where).order_by(ProfileBin.bin)).all()
                assert got == list(profiles["bin"][inside]), (km_from, km_to, length)
            frame = results_reader.job_profile_frame(s, job_id, wheel="11", km_from=km_from, km_to=km_to)
            assert list(frame["bin"]) == list(profiles["bin"][inside])


def test_columns_wheels_and_limits(db):
    profiles = profile_table(("11", "12", "41"), n_bins=40, seed=8)
    run_id, job_id = _published(db, profiles)
    with db.read() as s:
        part = results_reader.profile_rows(s, run_id, columns=["sleeper_amp", "speed_mean", "sleeper_amp"])
        assert list(part.columns) == ["wheel", "bin", "km", "sleeper_amp", "speed_mean"]
        pd.testing.assert_frame_equal(part, profiles[list(part.columns)], check_exact=True)
        twelve = results_reader.profile_rows(s, run_id, wheel="12")
        assert set(twelve["wheel"]) == {"12"} and len(twelve) == 40
        limited = results_reader.job_profile_frame(s, job_id, limit=95)  # 40 + 40 + 15
        assert len(limited) == 95 and list(limited["wheel"].drop_duplicates()) == ["11", "12", "41"]
        assert list(limited["bin"][80:]) == list(profiles["bin"][80:95])
        after = results_reader.job_profile_frame(s, job_id, wheel="41", after_bin=1_030)
        assert list(after["bin"]) == list(range(1_031, 1_040))
        assert results_reader.job_profile_frame(s, job_id, wheel="99").empty
        with pytest.raises(ValueError, match="unknown column"):
            results_reader.profile_rows(s, run_id, columns=["sleeper_amp", "bogus"])


@pytest.mark.parametrize("page_size", [1, 7, 25, 50, 1_000])
def test_pages_of_a_wheel_join_to_the_whole_wheel(db, page_size):
    profiles = profile_table(("11", "12"), n_bins=50, seed=9)
    _, job_id = _published(db, profiles)
    km_from, km_to = profiles["km"].iloc[3], profiles["km"].iloc[45]
    with db.read() as s:
        whole = results_reader.job_profile_frame(s, job_id, wheel="12", km_from=km_from, km_to=km_to)
    pages = list(results_reader.iter_profile_pages(db.read, job_id, "12", km_from=km_from, km_to=km_to,
                                                   page_size=page_size))
    assert all(len(p) <= page_size for p in pages)
    assert len(pages) == -(-len(whole) // page_size)  # no empty trailing page
    pd.testing.assert_frame_equal(pd.concat(pages, ignore_index=True), whole, check_exact=True)
    assert len(whole) == 43


def test_a_run_shows_its_latest_done_job(db):
    run_id, first = _published(db, profile_table(n_bins=3), bin_length_m=0.5)
    with db.write() as s:
        running = crud.create_job(s, run_id, {"bin_length_m": 0.1})
        running.status = JobStatus.RUNNING
        running_id = running.id
    with db.read() as s:
        assert results_reader.results_job_id(s, run_id) == first
        job = results_reader.results_job(s, run_id)
        assert job.id == first and results_reader.bin_length_of(job) == 0.5
        assert results_reader.job_bin_length(s, running_id) == 0.1
        assert results_reader.bin_length_of(None) == 0.25
        empty_run = add_run(db, sha="e" * 64)
        assert results_reader.results_job_id(s, empty_run) is None
        assert results_reader.results_job(s, empty_run) is None
        empty = results_reader.profile_rows(s, empty_run, columns=["n_samples"])
        assert list(empty.columns) == ["wheel", "bin", "km", "n_samples"] and empty.empty
        assert results_reader.get_wheels(s, empty_run) == []


def test_profile_frame_types_result_rows():
    assert results_reader.profile_columns() == results_reader.PROFILE_COLUMNS
    assert results_reader.PROFILE_COLUMNS == ("wheel", "bin", "km", *PROFILE_VALUE_COLUMNS)
    frame = results_reader.profile_frame([(11, 5, 0.00125, 100, None)], ["wheel", "bin", "km", "n_samples", "sleeper_amp"])
    assert frame["wheel"].tolist() == ["11"]
    assert frame["bin"].dtype == np.int64 and frame["n_samples"].dtype == np.int64
    assert frame["km"].dtype == np.float64 and np.isnan(frame["sleeper_amp"].iloc[0])
    empty = results_reader.profile_frame([])
    assert list(empty.columns) == list(results_reader.PROFILE_COLUMNS) and empty.empty
    assert empty["bin"].dtype == np.int64 and empty["speed_mean"].dtype == np.float64
