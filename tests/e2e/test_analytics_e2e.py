"""End to end over HTTP: simulated run + simulated reference data → real uvicorn + worker →
reference import → subsidence model and unsprung mass checked against the simulator's truth."""

from __future__ import annotations

import numpy as np
import pytest

pytestmark = pytest.mark.timeout(600)


# SQLite only: the backend's part (upload, queue, COPY, the worker) is covered on both by
# test_service_e2e.py; the analytics read the same rows through the same queries on either
@pytest.mark.parametrize("service", ["sqlite"], indirect=True)
def test_reference_import_and_analytics_over_http(service, tmp_path):
    from app.simulate.reference import simulate_reference
    from app.simulate.run import simulate_run
    from app.simulate.speed import SpeedProfile
    from app.simulate.track import generate_line

    line = generate_line(11_900.0, 13_700.0, np.random.default_rng([4, 7]),
                         anomaly_range_m=(12_050.0, 13_450.0), n_anomalies=2)
    path = tmp_path / "run.h5"
    truth = simulate_run(path, length_km=1.5, fs=2000.0, seed=1, line=line, noise_std=1.0,
                         speed_profile=SpeedProfile.constant(100 / 3.6), line_id="L1", track="2",
                         amplitude_model="power_law")
    ref = simulate_reference(line, tmp_path / "ref", line_id="L1", track="2", seed=1, fmt="parquet")
    service.start_worker()
    with service.client(timeout=120) as client:
        with open(path, "rb") as fh:
            run = client.post("/api/v1/runs", files={"file": (path.name, fh)}).json()
        job = service.wait_job(client, run["latest_job"]["id"])
        assert job["status"] == "done", service.log_text()

        # a bad file first: 422 naming row and column, nothing stored
        bad = b"line_id,track,km,subsidence_mm,date\nL1,2,12.1,-1.5,2016-06-01\nL1,2,12.2,deep,2016-06-01\n"
        r = client.post("/api/v1/reference/subsidence", files={"file": ("bad.csv", bad)})
        assert r.status_code == 422 and r.json()["field"] == "row 2, column subsidence_mm"
        assert client.get("/api/v1/reference/subsidence", params={"line_id": "L1"}).json()["items"] == []

        for kind in ("subsidence", "maintenance", "superstructure"):
            with open(ref.files[kind], "rb") as fh:
                r = client.post(f"/api/v1/reference/{kind}", files={"file": (f"{kind}.parquet", fh)})
            assert r.status_code == 201, r.text
            assert r.json()["imported"] > 0
        sup = client.get("/api/v1/reference/superstructure", params={"line_id": "L1", "track": "2"}).json()
        assert [s["type"] for s in sup["items"]] == [s.type for s in line.sections]

        fit = client.get("/api/v1/analytics/subsidence-fit",
                         params={"line_id": "L1", "track": "2", "confidence": 0.99}).json()
        a, b = ref.subsidence_fit_at(100 / 3.6, truth.alpha, truth.v_ref_mps)
        assert fit["log_base"] == "e" and len(fit["wheels"]) == 4
        for w in fit["wheels"]:
            assert w["slope_ci"][0] <= a <= w["slope_ci"][1], w
            assert w["intercept_ci"][0] <= b <= w["intercept_ci"][1], w

        mass = client.get("/api/v1/analytics/unsprung-mass", params={"line_id": "L1"}).json()
        for w in mass["wheels"]:
            assert abs(w["mass_kg"] - truth.unsprung_mass_kg) < 0.05 * truth.unsprung_mass_kg, w
            assert w["plausible"]
