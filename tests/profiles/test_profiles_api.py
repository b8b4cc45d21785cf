"""Profile, wheel and job endpoints on stored (synthetic) results."""

from __future__ import annotations

import io

import numpy as np
import pandas as pd
import pytest

from app import publish
from app.db import queue
from app.db.session import Database
from tests.api import runfiles

N_BINS = 2000  # 500 m per wheel
BIN0 = 50_000  # km 12.5


def _synthetic(n_bins: int = N_BINS):
    rng = np.random.default_rng(3)
    frames = []
    for wheel in ("11", "12", "41", "42"):
        b = np.arange(BIN0, BIN0 + n_bins)
        frames.append(pd.DataFrame({
            "wheel": wheel, "bin": b, "km": (b + 0.5) * 0.25 / 1000, "n_samples": 125,
            "speed_mean": 20.0, "sleeper_amp": rng.lognormal(0, 0.3, n_bins),
            **{f"order_amp_{i:02d}": rng.random(n_bins) for i in range(1, 12)},
            "residual_rms": 0.2, "sleeper_force_amp": rng.random(n_bins),
            "sleeper_amp_raw": rng.lognormal(0.2, 0.3, n_bins), "sleeper_amp_sd": rng.uniform(0.1, 0.3, n_bins),
            "sleeper_amp_sd_shared": rng.uniform(0.0, 0.1, n_bins),
        }))
    wheels = [{"wheel": w, "wheel_diameter_m": 0.92, "n_windows": 5,
               "orders": [{"order": k, "radius_um": 10.0 * k, "radius_um_p05": 9.0 * k,
                           "radius_um_p95": 11.0 * k, "phase_rad": 0.1, "accel_amp": 0.5}
                          for k in range(1, 12)],
               "angles_deg": list(np.arange(360.0)), "profile_um": list(np.sin(np.arange(360.0))),
               "profile_p05_um": [0.0] * 360, "profile_p95_um": [1.0] * 360}
              for w in ("11", "12", "41", "42")]
    return pd.concat(frames, ignore_index=True), wheels


@pytest.fixture
def processed(client, tmp_path):
    """A run whose job was completed with synthetic results; returns (client, run_id, df)."""
    path = runfiles.write_hdf5(tmp_path / "r.h5", runfiles.channels(10_000))
    with open(path, "rb") as fh:
        run = client.post("/api/v1/runs", files={"file": (path.name, fh)}).json()
    db = Database(client.settings.database_url)
    try:
        job_id = queue.claim_next_job(db, "test", 30)
        assert job_id == run["latest_job"]["id"]
        df, wheels = _synthetic()
        assert publish.publish_job(db, job_id, run["id"], df, wheels, {"software": "t"}, worker_id="test")
    finally:
        db.dispose()
    return client, run["id"], df


def test_profile_rows_in_km_range(processed):
    client, run_id, df = processed
    r = client.get(f"/api/v1/runs/{run_id}/profile",
                   params={"wheel": "12", "km_from": 12.6, "km_to": 12.7})
    assert r.status_code == 200, r.text
    body = r.json()
    want = df[(df.wheel == "12") & (df.km >= 12.6) & (df.km <= 12.7)]
    assert body["n_rows"] == len(want) == 400
    assert body["level_m"] == 0.25 and body["bin_length_m"] == 0.25 and not body["truncated"]
    got = pd.DataFrame(body["rows"])
    np.testing.assert_allclose(got["sleeper_amp"], want["sleeper_amp"])
    assert list(got["bin"]) == list(want["bin"])


@pytest.mark.parametrize("level", [1, 10, 100])
def test_profile_aggregated(processed, level):
    client, run_id, df = processed
    r = client.get(f"/api/v1/runs/{run_id}/profile", params={"wheel": "41", "level": level})
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["n_rows"] == N_BINS * 0.25 / level
    first = body["rows"][0]
    per = int(level / 0.25)
    seg = df[df.wheel == "41"].iloc[:per]
    assert first["n_bins"] == per
    assert first["sleeper_amp_mean"] == pytest.approx(seg["sleeper_amp"].mean())
    assert first["sleeper_amp_max"] == pytest.approx(seg["sleeper_amp"].max())
    assert first["sleeper_amp_p95"] == pytest.approx(np.percentile(seg["sleeper_amp"], 95))
    assert first["km_from"] == pytest.approx(12.5)



@pytest.mark.parametrize(
    ("params", "status", "field"),
    [
        ({"wheel": "13"}, 404, "wheel"),
        ({"wheel": "11", "level": 0.3}, 422, "level"),
        ({"wheel": "11", "km_from": 13, "km_to": 12}, 422, "km_from"),
        ({"wheel": "11", "km_from": "nan"}, 422, None),
        ({"wheel": "11", "level": 1e9}, 422, None),
        ({"wheel": "../x"}, 422, None),
    ],
)
def test_profile_bad_parameters(processed, params, status, field):
    client, run_id, _ = processed
    r = client.get(f"/api/v1/runs/{run_id}/profile", params=params)
    assert r.status_code == status, r.text
    if field:
        assert r.json()["field"] == field


def test_profile_before_results_is_409(client, tmp_path):
    path = runfiles.write_hdf5(tmp_path / "r.h5", runfiles.channels(10_000))
    with open(path, "rb") as fh:
        run_id = client.post("/api/v1/runs", files={"file": (path.name, fh)}).json()["id"]
    r = client.get(f"/api/v1/runs/{run_id}/profile", params={"wheel": "11"})
    assert r.status_code == 409 and "no results yet" in r.json()["detail"]
    assert client.get(f"/api/v1/runs/{run_id}/wheels").status_code == 409
    assert client.get("/api/v1/runs/777/profile", params={"wheel": "11"}).status_code == 404


def test_csv_and_parquet_exports(processed):
    client, run_id, df = processed
    r = client.get(f"/api/v1/runs/{run_id}/profile.csv")
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/csv")
    assert "attachment" in r.headers["content-disposition"]
    got = pd.read_csv(io.StringIO(r.text), dtype={"wheel": str})
    assert len(got) == len(df)
    assert list(got.columns[:3]) == ["wheel", "bin", "km"]
    np.testing.assert_allclose(got["sleeper_amp"], df.sort_values(["wheel", "bin"])["sleeper_amp"], rtol=1e-8)

    r = client.get(f"/api/v1/runs/{run_id}/profile.parquet", params={"wheel": "42", "km_to": 12.55})
    assert r.status_code == 200
    got = pd.read_parquet(io.BytesIO(r.content))
    assert set(got["wheel"]) == {"42"} and len(got) == 200

    r = client.get(f"/api/v1/runs/{run_id}/profile.csv", params={"wheel": "11", "level": 100})
    got = pd.read_csv(io.StringIO(r.text))
    assert len(got) == 5 and "sleeper_amp_p95" in got.columns


def test_roughness_columns_stored_returned_and_exported(processed):
    """sleeper_amp_raw, sleeper_amp_sd and its shared part per bin, in the exports, and the segments' 1-σ at a
    level (with the shared part, also when only sleeper_amp_sd is asked for)."""
    from app.analysis.uncertainty import segment_sd

    client, run_id, df = processed
    want = df[df.wheel == "11"]
    rows = pd.DataFrame(client.get(f"/api/v1/runs/{run_id}/profile", params={"wheel": "11"}).json()["rows"])
    for col in ("sleeper_amp_raw", "sleeper_amp_sd", "sleeper_amp_sd_shared"):
        np.testing.assert_allclose(rows[col], want[col])
    got = pd.read_csv(io.StringIO(client.get(f"/api/v1/runs/{run_id}/profile.csv").text), dtype={"wheel": str})
    assert {"sleeper_amp_raw", "sleeper_amp_sd", "sleeper_amp_sd_shared"} <= set(got.columns)
    body = client.get(f"/api/v1/runs/{run_id}/profile",
                      params={"wheel": "11", "level": 10, "columns": "sleeper_amp,sleeper_amp_sd"}).json()
    agg = pd.DataFrame(body["rows"])
    _, sd = segment_sd(want["bin"].to_numpy(), want["sleeper_amp_sd"].to_numpy(), 10.0,
                       shared=want["sleeper_amp_sd_shared"].to_numpy())
    np.testing.assert_allclose(agg["sleeper_amp_sd_mean"], sd, rtol=1e-9)
    assert "sleeper_amp_sd_shared_mean" not in agg.columns  # read for the rule, not answered unasked
    full = pd.DataFrame(client.get(f"/api/v1/runs/{run_id}/profile", params={"wheel": "11", "level": 10}).json()["rows"])
    np.testing.assert_allclose(full["sleeper_amp_sd_mean"], sd, rtol=1e-9)
    # correlated along the track: far above sd/sqrt(40), below the bins' mean sd
    assert (agg["sleeper_amp_sd_mean"] < agg["sleeper_amp_sd_max"]).all()
    assert agg["sleeper_amp_sd_mean"].mean() > 2 * want["sleeper_amp_sd"].mean() / np.sqrt(40)


def test_the_step_estimate_is_answered_and_an_older_job_says_it_has_none(client, processed, tmp_path):
    """``sleeper_step`` per bin in the answer, its segments and the CSV (label and unit in the reader's
    language); a job processed before the step estimate was stored (``processed``: its meta names none)
    answers null there and ``step_estimate_stored: false``, a new one ``true``; not asked for: null."""
    from app.core.csv_labels import column_label

    client, old_run, _ = processed
    body = client.get(f"/api/v1/runs/{old_run}/profile", params={"wheel": "11", "km_to": 12.51}).json()
    assert body["step_estimate_stored"] is False
    assert all(r["sleeper_step"] is None for r in body["rows"]) and len(body["rows"]) == 40
    asked = client.get(f"/api/v1/runs/{old_run}/profile",
                       params={"wheel": "11", "max_points": 400, "columns": "sleeper_step"}).json()
    assert asked["step_estimate_stored"] is False and "sleeper_step" in asked["columns"]
    unasked = client.get(f"/api/v1/runs/{old_run}/profile", params={"wheel": "11", "columns": "sleeper_amp"}).json()
    assert unasked["step_estimate_stored"] is None
    old_csv = pd.read_csv(io.StringIO(client.get(f"/api/v1/runs/{old_run}/profile.csv",
                                                 params={"wheel": "11"}).text))
    assert old_csv["sleeper_step"].isna().all()

    path = runfiles.write_hdf5(tmp_path / "new.h5", runfiles.channels(10_000, seed=9))
    with open(path, "rb") as fh:
        run = client.post("/api/v1/runs", files={"file": (path.name, fh)}).json()
    df, wheels = _synthetic()
    df["sleeper_step"] = np.where(df["bin"] < BIN0 + 1000, 1.25, 0.8)
    db = Database(client.settings.database_url)
    try:
        job_id = queue.claim_next_job(db, "test", 30)
        assert publish.publish_job(db, job_id, run["id"], df, wheels, {"step_estimate": {"penalty": 16.0}},
                                   worker_id="test")
    finally:
        db.dispose()
    body = client.get(f"/api/v1/runs/{run['id']}/profile", params={"wheel": "41"}).json()
    assert body["step_estimate_stored"] is True
    np.testing.assert_allclose(pd.DataFrame(body["rows"])["sleeper_step"], df[df.wheel == "41"]["sleeper_step"])
    seg = pd.DataFrame(client.get(f"/api/v1/runs/{run['id']}/profile",
                                  params={"wheel": "41", "level": 100, "columns": "sleeper_step"}).json()["rows"])
    np.testing.assert_allclose(seg["sleeper_step_mean"], [1.25, 1.25, 1.025, 0.8, 0.8])
    for lang in ("en", "de", "fr", "it"):
        r = client.get(f"/api/v1/runs/{run['id']}/profile.csv", params={"wheel": "41", "header": "labels"},
                       headers={"Accept-Language": lang})
        header = r.text.split("\n", 1)[0]
        label = column_label("sleeper_step", lang)
        assert label in header and label.endswith("[m/s²]"), (lang, header)
    assert len({column_label("sleeper_step", lang) for lang in ("en", "de", "fr", "it")}) == 4
    got = pd.read_csv(io.StringIO(client.get(f"/api/v1/runs/{run['id']}/profile.csv").text), dtype={"wheel": str})
    np.testing.assert_allclose(got["sleeper_step"], df.sort_values(["wheel", "bin"])["sleeper_step"])


def test_wheels(processed):
    client, run_id, _ = processed
    r = client.get(f"/api/v1/runs/{run_id}/wheels")
    assert r.status_code == 200
    items = r.json()["items"]
    assert [w["wheel"] for w in items] == ["11", "12", "41", "42"]
    assert items[0]["orders"][2]["radius_um"] == pytest.approx(30.0)
    assert len(items[0]["profile_um"]) == 360


def test_run_detail_shows_done_job_and_provenance(processed):
    client, run_id, _ = processed
    job = client.get(f"/api/v1/runs/{run_id}").json()["latest_job"]
    assert job["status"] == "done" and job["progress"] == 1.0
    assert set(job["meta"]) == {"software", "condition"} and job["meta"]["software"] == "t"
    assert job["meta"]["condition"]["stored"] is True  # publishing wrote the run's segment condition rows
    jobs = client.get(f"/api/v1/runs/{run_id}/jobs").json()
    assert jobs["total"] == 1


def test_reprocess_validates_and_queues(processed):
    client, run_id, _ = processed
    r = client.post(f"/api/v1/runs/{run_id}/jobs", json={"filter_order": 7})
    assert r.status_code == 422 and r.json()["field"] == "filter_order"
    r = client.post(f"/api/v1/runs/{run_id}/jobs", json={"n_wheel_orders": 20})
    assert r.status_code == 422 and r.json()["field"] == "n_wheel_orders"
    r = client.post(f"/api/v1/runs/{run_id}/jobs", json={"bandwidth_orders": 5})
    assert r.status_code == 422 and r.json()["field"] == "bandwidth_orders"
    r = client.post(f"/api/v1/runs/{run_id}/jobs", json={"colour": "red"})
    assert r.status_code == 422
    r = client.post(f"/api/v1/runs/{run_id}/jobs", json={"bandwidth_orders": 0.2, "filter_order": 3})
    assert r.status_code == 201, r.text
    job = r.json()
    assert job["status"] == "queued"
    assert job["settings"]["bandwidth_orders"] == 0.2 and job["settings"]["filter_order"] == 3
    assert job["settings"]["n_wheel_orders"] == 11
    # one active job per run
    r = client.post(f"/api/v1/runs/{run_id}/jobs", json={})
    assert r.status_code == 409
    # cancel a queued job, then reprocessing is possible again (settings carried over)
    r = client.post(f"/api/v1/jobs/{job['id']}/cancel")
    assert r.status_code == 200 and r.json()["status"] == "cancelled"
    assert client.post(f"/api/v1/jobs/{job['id']}/cancel").status_code == 409
    r = client.post(f"/api/v1/runs/{run_id}/jobs")
    assert r.status_code == 201 and r.json()["settings"]["filter_order"] == 3
    # the old results are still served until a new job finishes
    assert client.get(f"/api/v1/runs/{run_id}/profile", params={"wheel": "11"}).status_code == 200
    listing = client.get("/api/v1/jobs", params={"status": "cancelled"}).json()
    assert [j["id"] for j in listing["items"]] == [job["id"]]
    assert client.get("/api/v1/jobs", params={"status": "bogus"}).status_code == 422
    assert client.get("/api/v1/jobs/4242").status_code == 404


def test_health(client):
    body = client.get("/api/v1/health").json()
    assert body["status"] == "ok" and body["database"] == "ok"


def test_profile_row_cap_sets_truncated(processed):
    client, run_id, _ = processed
    client.app.state.settings = client.settings.model_copy(update={"max_profile_rows": 100})
    body = client.get(f"/api/v1/runs/{run_id}/profile", params={"wheel": "11"}).json()
    assert body["n_rows"] == 100 and body["truncated"] is True


@pytest.mark.parametrize("params", [{"wheel": "11", "km_to": 12.52}, {"wheel": "11", "level": 100},
                                    {"wheel": "11", "km_from": 99.0}])
def test_csv_export_header_in_the_users_language(processed, params):
    """``header=labels``: each column's label and unit in the request's language (a segment's statistics
    named), the rows unchanged; the field names by default; another ``header`` → 422 naming it."""
    import csv

    from app.core.csv_labels import column_label

    client, run_id, _df = processed
    plain = client.get(f"/api/v1/runs/{run_id}/profile.csv", params=params)
    labels = client.get(f"/api/v1/runs/{run_id}/profile.csv", params={**params, "header": "labels"},
                        headers={"Accept-Language": "de"})
    assert plain.status_code == labels.status_code == 200, labels.text
    fields, *rows = plain.text.split("\n")
    words, *same = labels.text.split("\n")
    (names,) = list(csv.reader([fields]))
    (got,) = list(csv.reader([words]))
    assert same == rows and names[0] == "wheel"
    assert got == [column_label(c, "de") for c in names]
    assert got[0] == "Rad" and got != names
    if "level" in params:
        assert "Schwellenfachamplitude, Mittelwert [m/s²]" in got
    bad = client.get(f"/api/v1/runs/{run_id}/profile.csv", params={**params, "header": "names"})
    assert bad.status_code == 422 and "header" in bad.text
