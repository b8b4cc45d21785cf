"""The display query over HTTP: compact column layout, gzip, ETag/304, answer cache (issue 18, load).

The dashboard asks ``layout=columns``; data systems keep the row objects by default.
"""

from __future__ import annotations

import gzip

import numpy as np
import pandas as pd
import pytest

from app import publish
from app.db import queue
from app.db.session import Database
from tests.profiles.test_profiles_api import _synthetic, processed  # noqa: F401 - the fixture

URL = "/api/v1/runs/{}/profile"


def _get(client, run_id, headers=None, **params):
    return client.get(URL.format(run_id), params={"wheel": "12", **params}, headers=headers or {})


@pytest.mark.parametrize(
    "params",
    [
        {"max_points": 300},
        {"max_points": 300, "columns": "sleeper_amp,speed_mean,sleeper_force_amp", "km_from": 12.55},
        {"level": 10},
        {"km_from": 12.6, "km_to": 12.65},
    ],
)
def test_column_layout_holds_the_rows_with_fixed_decimals(processed, params):  # noqa: F811
    client, run_id, _ = processed
    rows = _get(client, run_id, **params).json()
    cols = _get(client, run_id, layout="columns", **params).json()
    assert "rows" not in cols and cols["n_rows"] == rows["n_rows"] > 0
    assert cols["columns"] == [c for c in rows["columns"] if c != "wheel"] == list(cols["data"])
    want = pd.DataFrame(rows["rows"])
    for name in cols["columns"]:
        got = np.array(cols["data"][name], dtype=float)
        expected = want[name].to_numpy(dtype=float)
        if name in ("km", "km_from", "km_to"):
            np.testing.assert_allclose(got, expected, atol=5e-7, rtol=0)  # 6 decimals: 1 mm
        else:  # 5 significant digits of the column's largest value
            scale = np.nanmax(np.abs(expected)) if np.isfinite(expected).any() else 1.0
            np.testing.assert_allclose(got, expected, atol=scale * 1e-4, rtol=0, equal_nan=True)


def test_column_layout_is_much_smaller(processed):  # noqa: F811
    client, run_id, _ = processed
    params = {"max_points": 1000, "columns": "sleeper_amp,speed_mean,sleeper_force_amp"}
    rows = _get(client, run_id, headers={"Accept-Encoding": "identity"}, **params)
    cols = _get(client, run_id, headers={"Accept-Encoding": "identity"}, layout="columns", **params)
    assert len(cols.content) < 0.5 * len(rows.content)


def test_answers_are_gzip_encoded_for_clients_that_accept_it(processed):  # noqa: F811
    client, run_id, _ = processed
    params = {"max_points": 1000, "layout": "columns"}
    plain = _get(client, run_id, headers={"Accept-Encoding": "identity"}, **params)
    assert "content-encoding" not in plain.headers
    zipped = client.get(URL.format(run_id), params={"wheel": "12", **params},
                        headers={"Accept-Encoding": "gzip"}, extensions={})
    assert zipped.headers["content-encoding"] == "gzip"
    assert zipped.content == plain.content  # httpx decodes it
    assert int(zipped.headers["content-length"]) < 0.6 * len(plain.content)
    # every other large answer too (the middleware): the run list, an export
    r = client.get(f"/api/v1/runs/{run_id}/profile.csv", params={"wheel": "12"}, headers={"Accept-Encoding": "gzip"})
    assert r.headers["content-encoding"] == "gzip" and r.text.startswith("\"wheel\",\"bin\",\"km\"")


def test_etag_revalidation_answers_304_until_a_new_job_is_published(processed):  # noqa: F811
    client, run_id, _ = processed
    params = {"max_points": 500, "layout": "columns"}
    first = _get(client, run_id, **params)
    etag = first.headers["etag"]
    assert first.headers["cache-control"] == "private, no-cache"
    again = _get(client, run_id, headers={"If-None-Match": etag}, **params)
    assert again.status_code == 304 and again.content == b"" and again.headers["etag"] == etag
    assert again.headers["x-content-type-options"] == "nosniff"
    other = _get(client, run_id, headers={"If-None-Match": etag}, **{**params, "max_points": 501})
    assert other.status_code == 200 and other.headers["etag"] != etag
    assert _get(client, run_id, headers={"If-None-Match": etag}, max_points=500).status_code == 200  # rows layout

    # reprocess: the new job's results replace the old ones and the ETag changes
    r = client.post(f"/api/v1/runs/{run_id}/jobs", json={"bandwidth_orders": 0.2})
    assert r.status_code == 201, r.text
    db = Database(client.settings.database_url)
    try:
        job_id = queue.claim_next_job(db, "test", 30)
        df, wheels = _synthetic()
        df["sleeper_amp"] *= 2.0
        assert publish.publish_job(db, job_id, run_id, df, wheels, {"software": "t"}, worker_id="test")
    finally:
        db.dispose()
    fresh = _get(client, run_id, headers={"If-None-Match": etag}, **params)
    assert fresh.status_code == 200 and fresh.headers["etag"] != etag
    assert fresh.json()["job_id"] == job_id
    old = np.array(first.json()["data"]["sleeper_amp"])
    np.testing.assert_allclose(np.array(fresh.json()["data"]["sleeper_amp"]), 2 * old, atol=2e-4, rtol=0)


def test_cached_answer_is_the_computed_one(processed):  # noqa: F811
    client, run_id, _ = processed
    cache = client.app.state.profile_cache
    cache.clear()
    params = {"max_points": 400, "layout": "columns", "km_from": 12.51, "km_to": 12.9}
    first = _get(client, run_id, headers={"Accept-Encoding": "identity"}, **params)
    assert len(cache) == 1 and cache.misses >= 1
    hits = cache.hits
    second = _get(client, run_id, headers={"Accept-Encoding": "gzip"}, **params)
    assert cache.hits == hits + 1
    assert second.content == first.content
    assert gzip.decompress(gzip.compress(first.content)) == second.content


def test_cache_keeps_its_byte_budget():
    from app.core.bytecache import ByteLRU

    cache: ByteLRU[bytes] = ByteLRU(400)
    for i in range(10):
        assert cache.put(str(i), b"x" * 90, 90)
    assert cache.size <= 400 and len(cache) == 4
    assert cache.get("0") is None and cache.get("9") == b"x" * 90
    assert not cache.put("big", b"x" * 101, 101)  # over a quarter of the budget: not kept
    with pytest.raises(ValueError):
        ByteLRU(-1)


def test_profile_computations_wait_their_turn_without_blocking_other_requests(processed, monkeypatch):  # noqa: F811
    import threading

    import anyio

    from app.profiles import answer as profiles

    client, run_id, _ = processed
    client.app.state.profile_limiter = anyio.CapacityLimiter(1)
    release, running, peak = threading.Event(), [], []
    original = profiles.profile_body

    def slow(*args, **kwargs):
        running.append(1)
        peak.append(len(running))
        try:
            assert release.wait(30)
            return original(*args, **kwargs)
        finally:
            running.pop()

    monkeypatch.setattr(profiles, "profile_body", slow)
    answers: list[int] = []
    threads = [threading.Thread(target=lambda n=n: answers.append(
        _get(client, run_id, max_points=100 + n, layout="columns").status_code)) for n in range(3)]
    for t in threads:
        t.start()
    for _ in range(300):  # until one computation runs and holds the only slot
        if running:
            break
        threading.Event().wait(0.05)
    assert running
    # meanwhile other requests are answered
    for _ in range(5):
        assert client.get("/api/v1/runs").status_code == 200
    assert len(answers) == 0
    release.set()
    for t in threads:
        t.join(60)
    assert answers == [200, 200, 200] and max(peak) == 1


def test_concurrent_requests_for_one_answer_compute_it_once(processed, monkeypatch):  # noqa: F811
    import threading

    from app.profiles import answer as profiles

    client, run_id, _ = processed
    client.app.state.profile_cache.clear()
    release, calls = threading.Event(), []
    original = profiles.profile_body

    def slow(*args, **kwargs):
        calls.append(1)
        assert release.wait(30)
        return original(*args, **kwargs)

    monkeypatch.setattr(profiles, "profile_body", slow)
    bodies: list[bytes] = []
    threads = [threading.Thread(target=lambda: bodies.append(
        _get(client, run_id, max_points=321, layout="columns").content)) for _ in range(4)]
    for t in threads:
        t.start()
    for _ in range(300):
        if calls:
            break
        threading.Event().wait(0.05)
    threading.Event().wait(0.5)  # the other three arrive meanwhile and wait for the first
    release.set()
    for t in threads:
        t.join(60)
    assert len(bodies) == 4 and len(set(bodies)) == 1
    assert len(calls) == 1
    assert client.app.state.profile_pending == {}


def test_zooms_from_memory_are_the_answers_of_the_database(processed):  # noqa: F811
    from app.db.display_arrays import DisplayArrays

    client, run_id, _ = processed
    state = client.app.state
    windows = [{}, {"km_from": 12.5005}, {"km_to": 12.61}, {"km_from": 12.55, "km_to": 12.5501},
               {"km_from": 12.6, "km_to": 12.7}, {"km_from": 13.5}]
    params = [{"max_points": mp, "layout": layout, **w} for mp in (4, 150, 3000) for layout in ("rows", "columns")
              for w in windows]
    state.display_arrays = DisplayArrays(0)  # off: the database answers
    from_db = [_get(client, run_id, headers={"Accept-Encoding": "identity"}, **p).content for p in params]
    state.profile_cache.clear()
    state.display_arrays = DisplayArrays(64 * 1024 * 1024, background=False)
    from_memory = [_get(client, run_id, headers={"Accept-Encoding": "identity"}, **p).content for p in params]
    assert state.display_arrays.size > 0 and from_memory == from_db
