"""Endpoints the dashboard needs: display decimation of profiles, the wheel trend of a
vehicle, the spectrogram of a km window (against a simulated run), the HTML pages."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from app.analysis.orders import railway_multipliers
from tests.profiles.test_profiles_api import N_BINS, processed  # noqa: F401 - fixture


def test_profile_max_points_keeps_peaks_and_rows(processed):  # noqa: F811
    client, run_id, df = processed
    r = client.get(f"/api/v1/runs/{run_id}/profile", params={"wheel": "12", "max_points": 100})
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["max_points"] == 100 and 50 <= body["n_rows"] <= 100 and not body["truncated"]
    got = pd.DataFrame(body["rows"])
    want = df[df.wheel == "12"].set_index("bin")
    assert np.all(np.diff(got["km"]) > 0)
    # rows are stored rows, whole (not averaged)
    np.testing.assert_allclose(got["sleeper_amp"], want.loc[got["bin"], "sleeper_amp"])
    np.testing.assert_allclose(got["order_amp_03"], want.loc[got["bin"], "order_amp_03"])
    # peaks survive: global extremes and the ends
    assert got["sleeper_amp"].max() == pytest.approx(want["sleeper_amp"].max())
    assert got["sleeper_amp"].min() == pytest.approx(want["sleeper_amp"].min())
    assert got["bin"].iloc[0] == want.index.min() and got["bin"].iloc[-1] == want.index.max()
    assert body["km_extent"] == pytest.approx([want["km"].min(), want["km"].max()])
    # every bucket's maximum is kept: the top 1 % of the values are all there
    top = want["sleeper_amp"].nlargest(N_BINS // 100)
    assert top.index.isin(got["bin"]).mean() > 0.5


def test_profile_max_points_in_a_km_range_and_aggregated(processed):  # noqa: F811
    client, run_id, df = processed
    r = client.get(f"/api/v1/runs/{run_id}/profile",
                   params={"wheel": "41", "km_from": 12.6, "km_to": 12.65, "max_points": 1000})
    body = r.json()
    assert body["n_rows"] == 200  # fewer rows than max_points: all of them
    r = client.get(f"/api/v1/runs/{run_id}/profile", params={"wheel": "41", "level": 10, "max_points": 10})
    body = r.json()
    assert 4 <= body["n_rows"] <= 10 and "sleeper_amp_max_mean" not in body["columns"]
    seg_max = df[df.wheel == "41"]["sleeper_amp"].max()
    assert max(row["sleeper_amp_max"] for row in body["rows"]) == pytest.approx(seg_max)


def test_profile_max_points_zoomed_reads_the_range_with_its_peaks(processed):  # noqa: F811
    client, run_id, df = processed
    want = df[df.wheel == "42"].set_index("bin")
    a, b = want["km"].quantile(0.3), want["km"].quantile(0.6)
    body = client.get(f"/api/v1/runs/{run_id}/profile",
                      params={"wheel": "42", "km_from": a, "km_to": b, "max_points": 60}).json()
    got = pd.DataFrame(body["rows"])
    inside = want[(want["km"] >= a) & (want["km"] <= b)]
    assert 30 <= body["n_rows"] <= 60 and got["km"].between(a, b).all()
    assert got["sleeper_amp"].max() == pytest.approx(inside["sleeper_amp"].max())
    assert got["sleeper_amp"].min() == pytest.approx(inside["sleeper_amp"].min())
    # the whole profile's extent, not the range's
    assert body["km_extent"] == pytest.approx([want["km"].min(), want["km"].max()])


def test_profile_columns_read_only_what_is_asked(processed):  # noqa: F811
    client, run_id, df = processed
    url = f"/api/v1/runs/{run_id}/profile"
    full = client.get(url, params={"wheel": "11", "max_points": 80}).json()
    some = client.get(url, params={"wheel": "11", "max_points": 80, "columns": "speed_mean"}).json()
    # sleeper_amp comes along: it chooses the rows; the same rows as with every column
    assert some["columns"] == ["wheel", "bin", "km", "speed_mean", "sleeper_amp"]
    assert [r["bin"] for r in some["rows"]] == [r["bin"] for r in full["rows"]]
    assert [r["speed_mean"] for r in some["rows"]] == [r["speed_mean"] for r in full["rows"]]
    agg_full = client.get(url, params={"wheel": "11", "level": 10}).json()
    agg = client.get(url, params={"wheel": "11", "level": 10, "columns": "sleeper_amp"}).json()
    assert [c for c in agg["columns"] if c.startswith("sleeper_amp")] == agg["columns"][-3:]
    assert not any(c.startswith(("order_amp", "speed")) for c in agg["columns"])
    assert [r["sleeper_amp_p95"] for r in agg["rows"]] == [r["sleeper_amp_p95"] for r in agg_full["rows"]]
    r = client.get(url, params={"wheel": "11", "columns": "sleeper_amp,bogus"})
    assert r.status_code == 422 and "columns" in r.text and "bogus" in r.text
    assert client.get(url, params={"wheel": "11", "columns": " , "}).status_code == 422


@pytest.mark.parametrize("value", [3, 0, -5])
def test_profile_max_points_is_checked(processed, value):  # noqa: F811
    client, run_id, _ = processed
    r = client.get(f"/api/v1/runs/{run_id}/profile", params={"wheel": "12", "max_points": value})
    assert r.status_code == 422 and "max_points" in r.text


def test_wheel_trend_of_a_vehicle(processed):  # noqa: F811
    client, run_id, _ = processed
    vehicle = client.get(f"/api/v1/runs/{run_id}").json()["vehicle_id"]
    body = client.get("/api/v1/wheels/trend", params={"vehicle_id": vehicle}).json()
    assert body["vehicle_id"] == vehicle and body["orders"] == list(range(1, 12))
    assert [i["wheel"] for i in body["items"]] == ["11", "12", "41", "42"]
    item = body["items"][0]
    assert item["run_id"] == run_id and item["wheel_diameter_m"] == 0.92
    assert item["radius_um"] == pytest.approx([10.0 * k for k in range(1, 12)])
    assert item["accel_amp"] == pytest.approx([0.5] * 11)
    assert item["peak_to_peak_um"] == pytest.approx(2.0, abs=1e-3)  # sin over 360 degrees
    one = client.get("/api/v1/wheels/trend", params={"vehicle_id": vehicle, "wheel": "41"}).json()
    assert [i["wheel"] for i in one["items"]] == ["41"]
    none = client.get("/api/v1/wheels/trend", params={"vehicle_id": "no-such-vehicle"}).json()
    assert none["items"] == [] and none["orders"] == []
    bad = client.get("/api/v1/wheels/trend", params={"vehicle_id": vehicle, "wheel": "13"})
    assert bad.status_code == 422


@pytest.fixture(scope="module")
def sim_file(tmp_path_factory):
    from app.simulate.run import simulate_run

    path = tmp_path_factory.mktemp("spec") / "spec-run.h5"
    truth = simulate_run(path, length_km=0.5, fs=8000.0, seed=4, with_forces=False,
                         wheel_diameters={"11": 0.9, "12": 0.9, "41": 0.88, "42": 0.88})
    return path, truth


def test_spectrogram_of_a_simulated_run(client, sim_file):
    path, truth = sim_file
    with open(path, "rb") as fh:
        run = client.post("/api/v1/runs", files={"file": (path.name, fh)}).json()
    km0 = run["km_start"]
    r = client.get(f"/api/v1/runs/{run['id']}/spectrogram",
                   params={"wheel": "41", "km_from": km0 + 0.2, "km_to": km0 + 0.4})
    assert r.status_code == 200, r.text
    s = r.json()
    assert s["channel"] == "Z41" and s["settings"]["n_wheel_orders"] == 11
    d_w = s["wheel_diameter_m"]
    assert d_w == pytest.approx(0.88)  # the wheel's own diameter from the run metadata
    km = np.array(s["km"])
    assert km.size > 10 and np.all(np.diff(km) > 0)
    assert km[0] >= km0 + 0.2 - 1e-3 and km[-1] <= km0 + 0.4 + 1e-3
    # speed at the frames = the simulator's speed at those positions (axle 4 trails axle 1)
    dist = (km - km0) * 1000.0 - truth.axle_positions["4"]
    t_sim = np.arange(truth.n_samples) / truth.fs
    v_true = np.interp(dist, truth.speed_profile.distance(t_sim), truth.speed_profile.speed(t_sim))
    speed = np.array(s["speed_kmh"]) / 3.6
    np.testing.assert_allclose(speed, v_true, rtol=0.02)
    mult = railway_multipliers(d_w, s["sleeper_spacing_m"], 11)
    orders = {o["label"]: np.array(o["freq_hz"]) for o in s["orders"]}
    np.testing.assert_allclose(orders["sleeper"], mult[0] * speed, rtol=1e-3)
    np.testing.assert_allclose(orders["5"], mult[5] * speed, rtol=1e-3)
    # the raw spectrogram shows the sleeper passage: its line stands out of the noise floor
    freq = np.array(s["freq_hz"])
    raw = np.array(s["raw_db"], dtype=float)
    comp = np.array(s["components_db"], dtype=float)
    assert raw.shape == comp.shape == (freq.size, km.size)
    j = km.size // 2
    at_sleeper = np.abs(freq - orders["sleeper"][j]) <= 2 * s["resolution_hz"]
    assert raw[at_sleeper, j].max() > np.median(raw[:, j]) + 8.0
    assert comp[at_sleeper, j].max() == pytest.approx(raw[at_sleeper, j].max(), abs=3.0)


@pytest.mark.parametrize(
    ("params", "status", "field"),
    [
        ({"wheel": "11", "km_from": 12.0, "km_to": 12.6}, 422, "km_to"),  # 600 m > 500 m
        ({"wheel": "11", "km_from": 12.3, "km_to": 12.2}, 422, "km_to"),
        ({"wheel": "11", "km_from": 40.0, "km_to": 40.2}, 422, "km_from"),  # outside the run
        ({"wheel": "13", "km_from": 12.1, "km_to": 12.2}, 422, "wheel"),
    ],
)
def test_spectrogram_rejects_bad_windows(client, sim_file, params, status, field):
    path, _ = sim_file
    with open(path, "rb") as fh:
        run = client.post("/api/v1/runs", files={"file": (path.name, fh)}).json()
    r = client.get(f"/api/v1/runs/{run['id']}/spectrogram", params=params)
    assert r.status_code == status, r.text
    assert field in r.text


def test_spectrogram_of_unknown_run(client):
    r = client.get("/api/v1/runs/999/spectrogram", params={"wheel": "11", "km_from": 1, "km_to": 1.1})
    assert r.status_code == 404


def test_pages_and_local_plotly(client):
    for path in ("/", "/runs/1", "/runs/1/spectrogram", "/lines", "/wheels", "/correlations"):
        r = client.get(path)
        assert r.status_code == 200 and r.headers["content-type"].startswith("text/html"), path
        assert '<script src="/vendor/plotly.min.js">' in r.text
        assert "http://" not in r.text and "https://" not in r.text, f"{path} names an outside URL"
    js = client.get("/vendor/plotly.min.js")
    assert js.status_code == 200 and "javascript" in js.headers["content-type"]
    assert len(js.content) > 1_000_000
    assert client.get("/static/js/api.js").status_code == 200
    assert "/vendor/plotly.min.js" not in client.get("/openapi.json").text


def test_favicon_ico_is_public(client):
    """Browsers ask for /favicon.ico on their own, also before login: an icon, not a 404."""
    client.cookies.clear()
    r = client.get("/favicon.ico", headers={"Authorization": ""})
    assert r.status_code == 200 and r.headers["content-type"] == "image/x-icon"
    assert r.content[:4] == b"\x00\x00\x01\x00"  # ICO header: reserved 0, type 1 (icon)


def test_docs_serve_swagger_ui_5():
    """Swagger UI >= 5 renders the OpenAPI 3.1 the app serves (UI 4 shows "Unable to render")."""
    from app.api.login_page import swagger_ui_dir

    path = swagger_ui_dir()
    assert int(path.name.removeprefix("swagger-ui-").split(".")[0]) >= 5
    assert (path / "swagger-ui-bundle.js").is_file() and (path / "swagger-ui.css").is_file()
