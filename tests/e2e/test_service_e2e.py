"""End to end over HTTP: simulate → upload (real uvicorn) → worker → profile and wheels
checked against the simulator's ground truth."""

from __future__ import annotations

import io

import numpy as np
import pandas as pd
import pytest

from tests.api.support import store_files

pytestmark = pytest.mark.timeout(600)

INTERIOR_M = 50.0  # bins closer than this to either end of a wheel's track are not judged


def _interior(df: pd.DataFrame) -> pd.DataFrame:
    km = df["km"].to_numpy()
    lo, hi = km.min() + INTERIOR_M / 1000, km.max() - INTERIOR_M / 1000
    return df[(km >= lo) & (km <= hi)]


def test_upload_process_and_query_against_truth(service, sim_run):
    path, truth = sim_run
    service.start_worker()
    with service.client(timeout=120) as client:
        with open(path, "rb") as fh:
            r = client.post("/api/v1/runs", files={"file": (path.name, fh, "application/x-hdf5")})
        assert r.status_code == 201, r.text
        run = r.json()
        assert run["summary"]["n_samples"] == truth.n_samples
        assert run["summary"]["fs"] == truth.fs

        job = service.wait_job(client, run["latest_job"]["id"])
        assert job["status"] == "done", f"{job['error']}\n{service.log_text()}"
        assert job["progress"] == 1.0 and job["chunks_done"] == job["n_chunks"] >= 1
        assert job["meta"]["worker"]["run_sha256"] == run["sha256"]
        assert job["started_at"] and job["finished_at"]

        # the same file again: the existing run, no new job
        with open(path, "rb") as fh:
            again = client.post("/api/v1/runs", files={"file": (path.name, fh)})
        assert again.status_code == 200 and again.json()["id"] == run["id"]
        assert client.get(f"/api/v1/runs/{run['id']}/jobs").json()["total"] == 1

        # sleeper-passage amplitude per 25 cm vs truth, every wheel
        n_rows = {}
        for wheel, tb in truth.bins.items():
            body = client.get(f"/api/v1/runs/{run['id']}/profile", params={"wheel": wheel}).json()
            prof = pd.DataFrame(body["rows"])
            n_rows[wheel] = len(prof)
            assert len(prof) > 0.9 * len(tb)
            merged = prof.merge(
                pd.DataFrame({"bin": tb.bin, "true_amp": tb.amplitude_mps2}), on="bin"
            )
            merged = _interior(merged)
            merged = merged[np.isfinite(merged["sleeper_amp"]) & (merged["sleeper_amp"] > 0)]
            assert len(merged) > 0.8 * len(tb)
            r_log = np.corrcoef(np.log(merged["sleeper_amp"]), np.log(merged["true_amp"]))[0, 1]
            # 0.90: the default 3 m track resolution (issue 15) follows the truth along the track but
            # lets ~7x the noise bandwidth of the old ~21 m band into each 25 cm bin, and the default
            # resonance amplitude model is weaker than the power law at some speeds (lower SNR at the
            # same 2 m/s² noise): measured 0.908-0.919 (power law: 0.944-0.951)
            assert r_log >= 0.90, f"wheel {wheel}: Pearson(log amp) = {r_log:.3f}"
            err = np.abs(np.log(merged["sleeper_amp"]) - np.log(merged["true_amp"]))
            assert np.median(err) <= 0.08, f"wheel {wheel}: median |ln error| = {np.median(err):.3f}"  # 0.059-0.064
            # force amplitude follows m_u * acceleration amplitude
            ratio = np.nanmedian(merged["sleeper_force_amp"] * 1000 / merged["sleeper_amp_raw"])
            assert ratio == pytest.approx(truth.unsprung_mass_kg, rel=0.15)

        # aggregated levels
        agg = client.get(
            f"/api/v1/runs/{run['id']}/profile", params={"wheel": "11", "level": 100}
        ).json()
        assert agg["n_rows"] >= 14 and "sleeper_amp_p95" in agg["columns"]

        # wheel OOR: every true order above 20 µm within 10 %
        wheels = client.get(f"/api/v1/runs/{run['id']}/wheels").json()["items"]
        assert {w["wheel"] for w in wheels} == set(truth.wheels)
        checked = 0
        for w in wheels:
            true = truth.wheels[w["wheel"]]
            for order in w["orders"]:
                rho = float(true.rho_um[order["order"] - 1])
                if rho > 20.0:
                    assert order["radius_um"] == pytest.approx(rho, rel=0.10), (w["wheel"], order)
                    checked += 1
            assert len(w["profile_um"]) == 360
        assert checked >= 4

        # exports stream the same rows
        csv = client.get(f"/api/v1/runs/{run['id']}/profile.csv", params={"wheel": "42"})
        exported = pd.read_csv(io.StringIO(csv.text), dtype={"wheel": str})
        assert len(exported) == n_rows["42"]
        pq = client.get(f"/api/v1/runs/{run['id']}/profile.parquet")
        table = pd.read_parquet(io.BytesIO(pq.content))
        assert len(table) == sum(n_rows.values())

        # delete: rows and files go
        assert client.delete(f"/api/v1/runs/{run['id']}").status_code == 204
        assert client.get(f"/api/v1/runs/{run['id']}").status_code == 404
    assert store_files(service.run_store) == []


#: the file is refused while it is parsed, before the API writes to any database: the same in both modes
@pytest.mark.parametrize("service", ["sqlite"], indirect=True)
def test_bad_upload_over_http_leaves_nothing(service, tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("Z11,speed\n1,2\n3,4\n")
    with service.client(timeout=60) as client:
        with open(bad, "rb") as fh:
            r = client.post(
                "/api/v1/runs",
                files={"file": (bad.name, fh, "text/csv")},
                data={"metadata": '{"vehicle_id": "X"}'},
            )
        assert r.status_code == 422
        assert r.json()["detail"].startswith(r.json()["field"] + ": ")
        assert client.get("/api/v1/runs").json()["total"] == 0
    assert store_files(service.run_store) == []
