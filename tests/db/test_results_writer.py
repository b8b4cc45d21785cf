"""The results writer (app/db/results_writer.py): profile rows stored and read back
unchanged through the readers, on SQLite (plain inserts) and PostgreSQL (binary COPY);
display levels ranked per wheel over whole profiles; wheel rows as JSON; retries,
publishing and discarding."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from sqlalchemy import func, select

from app.analysis.aggregate import display_levels
from app.db import crud, results_reader, results_writer
from app.db.models import JobStatus, ProfileBin, WheelOOR
from app.db.session import Database
from tests.db.support import add_run, profile_table


def _job(db: Database, run_id: int) -> int:
    with db.write() as s:
        return crud.create_job(s, run_id, {"bin_length_m": 0.25}).id


def _store(db: Database, run_id: int, job_id: int, profiles: pd.DataFrame) -> int:
    with db.write() as s:
        return results_writer.store_profile_rows(s, run_id, job_id, profiles)


def _count(db: Database, model: type = ProfileBin) -> int:
    with db.read() as s:
        return s.scalar(select(func.count()).select_from(model))


def _stored_levels(db: Database, job_id: int) -> pd.DataFrame:
    with db.read() as s:
        rows = s.execute(
            select(ProfileBin.wheel, ProfileBin.bin, ProfileBin.display_level)
            .where(ProfileBin.job_id == job_id).order_by(ProfileBin.wheel, ProfileBin.bin)
        ).all()
    return pd.DataFrame(rows, columns=["wheel", "bin", "display_level"])


def test_stored_rows_read_back_unchanged(any_db):
    db = any_db
    run_id = add_run(db)
    job_id = _job(db, run_id)
    profiles = profile_table(("42", "11", "12"), n_bins=300, seed=1)
    profiles.loc[5, "speed_mean"] = np.nan
    profiles.loc[7, "sleeper_force_amp"] = np.inf  # not a number a reader can use: stored as NULL
    profiles["order_amp_12"] = 1.0  # orders beyond the stored columns are left out
    shuffled = profiles.sample(frac=1.0, random_state=3)
    assert _store(db, run_id, job_id, shuffled) == len(profiles)

    expected = (
        profiles.drop(columns="order_amp_12")
        .sort_values(["wheel", "bin"], kind="stable")
        .reset_index(drop=True)[list(results_reader.PROFILE_COLUMNS)]
    )
    expected.loc[expected["sleeper_force_amp"] == np.inf, "sleeper_force_amp"] = np.nan
    with db.read() as s:
        got = results_reader.job_profile_frame(s, job_id)
        assert results_reader.stored_profile_wheels(s, job_id) == ["11", "12", "42"]
        assert results_reader.results_job_id(s, run_id) is None  # stored, not yet shown
        assert results_reader.profile_rows(s, run_id).empty
    pd.testing.assert_frame_equal(got, expected, check_exact=True)


def test_display_levels_ranked_per_wheel_over_the_whole_profile(db):
    """Levels come from each wheel's whole profile, also when it is inserted in batches."""
    run_id = add_run(db)
    job_id = _job(db, run_id)
    n = results_writer._INSERT_BATCH + 37
    profiles = pd.concat(
        [profile_table(("11",), n_bins=n, seed=2), profile_table(("12",), n_bins=400, seed=3)],
        ignore_index=True,
    )
    assert _store(db, run_id, job_id, profiles) == n + 400
    stored = _stored_levels(db, job_id)
    for wheel, part in profiles.groupby("wheel"):
        expected = display_levels(part["bin"].to_numpy(), part["sleeper_amp"].to_numpy())
        got = stored[stored["wheel"] == wheel]
        assert list(got["bin"]) == list(part["bin"])
        np.testing.assert_array_equal(got["display_level"].to_numpy(), expected)
    assert stored["display_level"].max() >= 5  # a real pyramid, not all zeros


def test_without_sleeper_amplitude_every_row_is_level_zero(db):
    run_id = add_run(db)
    job_id = _job(db, run_id)
    profiles = profile_table(n_bins=20)[["wheel", "bin", "km", "n_samples", "speed_mean"]]
    _store(db, run_id, job_id, profiles)
    assert set(_stored_levels(db, job_id)["display_level"]) == {0}
    with db.read() as s:
        got = results_reader.job_profile_frame(s, job_id, columns=["speed_mean", "sleeper_amp"])
    assert got["sleeper_amp"].isna().all()
    np.testing.assert_array_equal(got["speed_mean"], profiles.sort_values(["wheel", "bin"])["speed_mean"])


def test_a_retried_store_replaces_the_rows_of_its_wheels_only(db):
    run_id = add_run(db)
    job_id = _job(db, run_id)
    first = profile_table(n_bins=30, seed=4)
    _store(db, run_id, job_id, first)
    _store(db, run_id, job_id, first)
    assert _count(db) == 60
    again = profile_table(("11",), n_bins=10, seed=5)  # wheel 11 again, shorter
    _store(db, run_id, job_id, again)
    with db.read() as s:
        got = results_reader.job_profile_frame(s, job_id)
    assert (got["wheel"] == "11").sum() == 10 and (got["wheel"] == "12").sum() == 30
    np.testing.assert_array_equal(got.loc[got["wheel"] == "11", "sleeper_amp"], again["sleeper_amp"])


def test_bad_input_writes_nothing(db):
    run_id = add_run(db)
    job_id = _job(db, run_id)
    _store(db, run_id, job_id, profile_table(n_bins=5))
    with pytest.raises(ValueError, match="missing column.*n_samples"):
        _store(db, run_id, job_id, profile_table(n_bins=8).drop(columns="n_samples"))
    assert _count(db) == 10  # the earlier rows untouched, none added
    with pytest.raises(LookupError, match="does not exist"):
        _store(db, run_id + 1, job_id, profile_table(n_bins=5))
    with db.write() as s:
        assert results_writer.lock_run_for_results(s, run_id)
        assert not results_writer.lock_run_for_results(s, run_id + 1)
        with pytest.raises(ValueError, match="'wheel' key"):
            results_writer.publish_results(s, run_id, job_id, [{"n_windows": 3}])


def test_publish_makes_a_job_the_runs_and_stores_wheels_as_json(db):
    run_id = add_run(db)
    old_job, new_job = _job(db, run_id), _job(db, run_id)
    _store(db, run_id, old_job, profile_table(n_bins=12, seed=6))
    with db.write() as s:
        results_writer.publish_results(s, run_id, old_job, [{"wheel": "11"}, {"wheel": "12"}, {"wheel": "41"}])
    _store(db, run_id, new_job, profile_table(("11",), n_bins=7, seed=7))
    assert _count(db) == 31  # both jobs' rows until the new one is published
    wheel = {
        "wheel": np.str_("11"),
        "wheel_diameter_m": np.float64(0.92),
        "n_windows": np.int64(12),
        "orders": [{"order": np.int64(1), "radius_um": np.float64(12.5), "phase_deg": np.nan}],
        "angles_deg": np.array([0.0, 120.0, 240.0]),
        "profile_um": np.array([1.5, np.nan, -2.0]),
        "profile_p05_um": None,
        "refined_diameter_m": np.float64(0.9213),
    }
    with db.write() as s:
        results_writer.publish_results(
            s, run_id, new_job, [wheel, {"wheel": "12", "wheel_diameter_m": float("nan")}]
        )
        crud.get_job(s, new_job).status = JobStatus.DONE  # as publish_job does, same transaction
    assert _count(db) == 7  # the old job's rows are gone
    with db.read() as s:
        assert results_reader.results_job_id(s, run_id) == new_job
        rows = results_reader.get_wheels(s, run_id)
        assert [w.wheel for w in rows] == ["11", "12"]  # wheel 41 of the old job replaced
        w11, w12 = rows
        assert (w11.job_id, w11.wheel_diameter_m, w11.n_windows) == (new_job, 0.92, 12)
        assert w11.orders == [{"order": 1, "radius_um": 12.5, "phase_deg": None}]
        assert w11.angles_deg == [0.0, 120.0, 240.0]
        assert w11.profile_um == [1.5, None, -2.0]
        assert w11.profile_p05_um is None and w11.profile_p95_um is None
        assert w11.extra == {"refined_diameter_m": 0.9213}
        assert w12.wheel_diameter_m is None and w12.extra is None and w12.orders == []


def test_discard_deletes_one_jobs_rows(db):
    run_id = add_run(db)
    keep, drop = _job(db, run_id), _job(db, run_id)
    _store(db, run_id, keep, profile_table(n_bins=4))
    _store(db, run_id, drop, profile_table(n_bins=6))
    with db.write() as s:
        results_writer.discard_profile_rows(s, drop)
    with db.read() as s:
        assert results_reader.stored_profile_wheels(s, drop) == []
        assert len(results_reader.job_profile_frame(s, keep)) == 8
    assert _count(db, WheelOOR) == 0
