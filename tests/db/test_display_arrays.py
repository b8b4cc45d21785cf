"""Display queries from memory (app/db/display_arrays.py) on SQLite and PostgreSQL: exactly the
rows of the SQL path (app/db/display.py) for every window, level, point count and column set;
read once per wheel in the background, bounded by bytes, columns added as asked."""

from __future__ import annotations

import threading

import numpy as np
import pandas as pd
import pytest

from app.db import crud, results_reader, results_writer
from app.db.display import display_level_of, display_rows, km_extent
from app.db.display_arrays import DisplayArrays
from app.db.models import COARSE_DISPLAY_LEVEL, JobStatus
from app.db.session import Database
from tests.db.support import add_run, profile_table

MAP_COLUMNS = results_reader.profile_columns(["sleeper_amp", "speed_mean", "sleeper_force_amp"])
N_BINS = 12_000


def _published(db: Database, profiles: pd.DataFrame) -> int:
    """Job id of a done job holding ``profiles`` (bins of 0.25 m)."""
    run_id = add_run(db)
    with db.write() as s:
        job = crud.create_job(s, run_id, {"bin_length_m": 0.25})
        results_writer.store_profile_rows(s, run_id, job.id, profiles)
        results_writer.publish_results(s, run_id, job.id, [])
        job.status = JobStatus.DONE
        return job.id


@pytest.fixture
def stored(any_db: Database) -> tuple[Database, int, pd.DataFrame]:
    """Two wheels of 3 km (bins on both sides of 0), some sleeper amplitudes missing."""
    profiles = profile_table(("11", "12"), n_bins=N_BINS, first_bin=-1_500, seed=5)
    gaps = np.random.default_rng(6).random(len(profiles)) < 0.01
    profiles.loc[gaps, "sleeper_amp"] = np.nan
    profiles.loc[profiles.index[100:300], "sleeper_amp"] = np.nan  # a gap of 50 m
    return any_db, _published(any_db, profiles), profiles


def _count_reads(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """The wheels :class:`DisplayArrays` reads from the database from now on, in order."""
    reads: list[str] = []
    original = DisplayArrays._read

    def counted(self, *args):
        reads.append(args[2])
        return original(self, *args)

    monkeypatch.setattr(DisplayArrays, "_read", counted)
    return reads


def _windows(km: np.ndarray) -> list[tuple[float | None, float | None]]:
    rng = np.random.default_rng(7)
    out: list[tuple[float | None, float | None]] = [
        (None, None), (km[0], km[-1]), (km[5], km[5]), (km[5] + 1e-9, km[6] - 1e-9), (None, km[40]),
        (km[-30], None), (km[0] - 1.0, km[0] - 0.5), (km[-1] + 0.1, None), (-0.02, 0.4), (km[0] - 1, km[-1] + 1),
    ]
    for _ in range(40):
        length = 0.0005 * (km[-1] - km[0]) / 0.0005 ** rng.random()  # 1 bin .. the whole wheel
        start = rng.uniform(km[0] - 0.05, km[-1])
        out.append((float(start), float(start + length)))
    return out


def test_answers_are_the_rows_of_the_sql_path(stored):
    """Every (point count, window) pair once, the wheel and the column set taken in turn: they only
    choose the rows' filter and the columns read, while the window and the point count choose the
    level, the index path and the edge buckets. Every level of the pyramid, all rows (0) to the
    coarsest, is compared for each wheel and for each column set; every fixed window (the ends,
    one bin, empty ranges, beyond the profile) with every point count."""
    db, job_id, profiles = stored
    arrays = DisplayArrays(64 * 1024 * 1024, background=False)
    km = profiles["km"].to_numpy()[:N_BINS]
    column_sets = [MAP_COLUMNS, results_reader.profile_columns(["sleeper_amp"])[1:],
                   results_reader.profile_columns(None)]
    turns = [(wheel, c) for wheel in ("11", "12") for c in range(len(column_sets))]
    with db.read() as s:
        extents = {wheel: km_extent(s, job_id, wheel) for wheel in ("11", "12")}
    levels: dict[str | int, set[int]] = {key: set() for key in ("11", "12", *range(len(column_sets)))}
    compared = 0
    for max_points in (4, 37, 400, 2400, 20_000):
        for km_from, km_to in _windows(km):
            wheel, c = turns[compared % len(turns)]
            columns = column_sets[c]
            got = arrays.display_rows(db, job_id, wheel, max_points, 0.25, km_from=km_from, km_to=km_to,
                                      columns=columns)
            assert got is not None
            with db.read() as s:
                want = display_rows(s, job_id, wheel, max_points, 0.25, km_from=km_from, km_to=km_to,
                                    columns=columns)
                extent = km_extent(s, job_id, wheel)
            pd.testing.assert_frame_equal(got[0], want, check_exact=True)
            assert got[1] == extent
            level = display_level_of(extent, km_from, km_to, max_points, 0.25)
            levels[wheel].add(level)
            levels[c].add(level)
            compared += 1
    assert compared == 5 * 50
    # levels 0 (all rows of the range, by primary key), 1 (primary key), 2 and more (the coarse
    # index) up to the top of the pyramid, for each wheel and each column set
    top = display_level_of(extents["11"], None, None, 4, 0.25)
    assert top > COARSE_DISPLAY_LEVEL
    assert all(seen == set(range(top + 1)) for seen in levels.values()), levels
    assert 0 < arrays.size <= arrays.max_bytes


def test_the_api_answers_byte_for_byte_as_without_arrays(stored, service_settings):
    from app.profiles import answer as api
    from app.profiles.query import ProfileQuery

    db, job_id, profiles = stored
    arrays = DisplayArrays(64 * 1024 * 1024)
    query = ProfileQuery(1, job_id, 0.25, 1, "12", None, None, 0.25, 2400,
                              ("sleeper_amp", "speed_mean", "sleeper_force_amp"), "columns")
    first = api.profile_body(db, service_settings, query, arrays)  # the database answers; the wheel is read
    assert arrays.wait(60) and arrays.size > 0
    for km_from, km_to in _windows(profiles["km"].to_numpy()[:N_BINS])[:20]:
        for layout in ("columns", "rows"):
            q = ProfileQuery(1, job_id, 0.25, 1, "12", km_from, km_to, 0.25, 300,
                                  ("sleeper_amp", "speed_mean", "sleeper_force_amp"), layout)
            assert api.profile_body(db, service_settings, q, arrays) == api.profile_body(db, service_settings, q)
    assert first == api.profile_body(db, service_settings, query, arrays)


def test_a_wheel_is_read_in_the_background_once(stored, monkeypatch):
    db, job_id, _ = stored
    arrays = DisplayArrays(64 * 1024 * 1024)
    reads: list[str] = []
    release = threading.Event()
    original = DisplayArrays._read

    def slow_read(self, db, job_id, wheel, entry, wanted):
        reads.append(wheel)
        release.wait(30)
        return original(self, db, job_id, wheel, entry, wanted)

    monkeypatch.setattr(DisplayArrays, "_read", slow_read)
    for _ in range(5):  # not there yet: the caller asks the database, one read starts
        assert arrays.display_rows(db, job_id, "11", 100, 0.25, columns=MAP_COLUMNS) is None
    assert reads == ["11"]
    release.set()
    assert arrays.wait(60)
    assert arrays.display_rows(db, job_id, "11", 100, 0.25, columns=MAP_COLUMNS) is not None
    # a column more: read (only that column) and added to the wheel's entry
    size = arrays.size
    more = (*MAP_COLUMNS, "residual_rms")
    assert arrays.display_rows(db, job_id, "11", 100, 0.25, columns=more) is None
    assert arrays.wait(60) and reads == ["11", "11"]
    assert arrays.size == size + 8 * N_BINS
    assert arrays.display_rows(db, job_id, "11", 100, 0.25, columns=more) is not None
    assert arrays.display_rows(db, job_id, "11", 100, 0.25, columns=MAP_COLUMNS) is not None
    assert reads == ["11", "11"]


def test_concurrent_queries_of_a_wheel_read_it_once(stored, monkeypatch):
    db, job_id, _ = stored
    arrays = DisplayArrays(64 * 1024 * 1024, background=False)
    reads = _count_reads(monkeypatch)
    answers: list[object] = []
    threads = [threading.Thread(target=lambda: answers.append(
        arrays.display_rows(db, job_id, "12", 500, 0.25, km_from=0.5, columns=MAP_COLUMNS))) for _ in range(6)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    assert reads == ["12"] and len(answers) == 6 and all(a is not None for a in answers)


def test_budget_least_recently_used_wheels_and_what_is_not_kept(stored):
    db, job_id, _ = stored
    wheel_bytes = N_BINS * (8 + 8 + 2 + 8 * 3)  # bin, km, level, three columns (+ positions per level)
    arrays = DisplayArrays(6 * wheel_bytes, background=False)  # one wheel < a quarter of the budget
    assert arrays.display_rows(db, job_id, "11", 100, 0.25, columns=MAP_COLUMNS) is not None
    assert arrays.display_rows(db, job_id, "12", 100, 0.25, columns=MAP_COLUMNS) is not None
    assert arrays.size <= arrays.max_bytes
    everything = results_reader.profile_columns(None)  # 21 columns: over a quarter of the budget
    assert arrays.display_rows(db, job_id, "12", 100, 0.25, columns=everything) is None
    assert arrays.display_rows(db, job_id, "12", 100, 0.25, columns=MAP_COLUMNS) is not None  # kept
    small = DisplayArrays(wheel_bytes, background=False)  # a wheel is over a quarter: the database answers
    assert small.display_rows(db, job_id, "11", 100, 0.25, columns=MAP_COLUMNS) is None
    assert small.size < 100  # only the marker
    assert DisplayArrays(0).display_rows(db, job_id, "11", 100, 0.25, columns=MAP_COLUMNS) is None
    # a job without rows (or gone): the database answers, nothing kept but a marker
    assert arrays.display_rows(db, job_id + 1, "11", 100, 0.25, columns=MAP_COLUMNS) is None


def test_lru_drops_the_least_recently_used_wheel(db, monkeypatch):
    wheels = ("11", "12", "21", "22", "31", "32")
    job_id = _published(db, profile_table(wheels, n_bins=2_000, seed=9))
    arrays = DisplayArrays(4 * 2_000 * (8 + 8 + 2 + 6 + 8 * 3), background=False)  # room for 4 of them
    reads = _count_reads(monkeypatch)
    for wheel in wheels:
        assert arrays.display_rows(db, job_id, wheel, 100, 0.25, columns=MAP_COLUMNS) is not None
        assert arrays.size <= arrays.max_bytes
    assert reads == list(wheels)
    arrays.display_rows(db, job_id, "32", 100, 0.25, columns=MAP_COLUMNS)  # still held
    assert reads == list(wheels)
    arrays.display_rows(db, job_id, "11", 100, 0.25, columns=MAP_COLUMNS)  # dropped: read again
    assert reads == [*wheels, "11"]
