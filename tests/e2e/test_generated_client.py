"""The API as integrators use it: a Python client generated from the running service's
/openapi.json with openapi-python-client drives channel map → upload (MDF4) → job → profile
→ CSV export against a real uvicorn + worker, so any drift of the schema breaks this test."""

from __future__ import annotations

import importlib
import io
import json
import shutil
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest

from app.simulate.recorder import simulate_recorder_run
from tests.api.support import create_api_key
from tests.e2e.conftest import running_service

pytestmark = pytest.mark.timeout(600)


def _generator() -> list[str]:
    exe = Path(sys.executable).with_name("openapi-python-client")
    if exe.is_file():
        return [str(exe)]
    found = shutil.which("openapi-python-client")
    if found is None:
        pytest.fail("openapi-python-client is not installed (dev extra of pyproject.toml)")
    return [found]


def test_generated_client_round_trip(tmp_path: Path) -> None:
    rec = simulate_recorder_run(tmp_path / "run.mf4", "mdf4", gnss=None, length_km=0.3, fs=5000.0,
                                seed=8, with_forces=False, vehicle_id="DS-1")
    with running_service(tmp_path / "svc") as svc:
        spec = httpx.get(f"{svc.base_url}/openapi.json", headers=svc.headers, timeout=30).json()
        (tmp_path / "openapi.json").write_text(json.dumps(spec))
        done = subprocess.run(
            [*_generator(), "generate", "--path", str(tmp_path / "openapi.json"), "--meta", "none",
             "--output-path", str(tmp_path / "gen" / "trackvkf_client")],
            capture_output=True, text=True, timeout=300,
        )
        assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
        sys.path.insert(0, str(tmp_path / "gen"))
        try:
            _round_trip(svc, rec)
        finally:
            sys.path.remove(str(tmp_path / "gen"))
            for name in [m for m in sys.modules if m == "trackvkf_client" or m.startswith("trackvkf_client.")]:
                del sys.modules[name]


def _round_trip(svc, rec) -> None:
    tc = importlib.import_module("trackvkf_client")
    types = importlib.import_module("trackvkf_client.types")
    models = importlib.import_module("trackvkf_client.models")
    upload = importlib.import_module("trackvkf_client.api.runs.upload_run_api_v1_runs_post")
    create_map = importlib.import_module("trackvkf_client.api.channel_maps.create_channel_map_api_v1_channel_maps_post")
    get_job = importlib.import_module("trackvkf_client.api.jobs.get_job_api_v1_jobs_job_id_get")
    get_profile = importlib.import_module("trackvkf_client.api.profiles.get_profile_api_v1_runs_run_id_profile_get")
    export_csv = importlib.import_module("trackvkf_client.api.profiles.export_csv_api_v1_runs_run_id_profile_csv_get")

    key = create_api_key(svc.database_url, "engineer", "data system")  # what a loader gets
    client = tc.AuthenticatedClient(base_url=svc.base_url, token=key, timeout=httpx.Timeout(120.0))
    svc.start_worker()
    with client as c:
        cmap = create_map.sync(client=c, body=models.ChannelMapIn.from_dict(
            {"vehicle_id": "DS-1", "name": "recorder", "channels": rec.channel_map["channels"]}))
        assert isinstance(cmap, models.ChannelMapOut), cmap
        body = models.UploadRunApiV1RunsPostFilesBody(
            file=types.File(payload=io.BytesIO(rec.path.read_bytes()), file_name=rec.path.name,
                            mime_type="application/octet-stream"),
            metadata=json.dumps(rec.metadata),
            channel_map=str(cmap.id),
        )
        run = upload.sync(client=c, body=body)
        assert isinstance(run, models.RunDetail), run
        assert run.source_format == "mdf4" and run.vehicle_id == "DS-1"
        assert isinstance(run.warnings, list)
        job_id = run.latest_job.id
        deadline = time.monotonic() + 240
        job = get_job.sync(job_id, client=c)
        while job.status not in ("done", "failed", "cancelled") and time.monotonic() < deadline:
            time.sleep(0.5)
            job = get_job.sync(job_id, client=c)
        assert job.status == "done", f"{job.error}\n{svc.log_text()}"
        profile = get_profile.sync(run.id, client=c, wheel="11", columns="sleeper_amp,speed_mean")
        assert isinstance(profile, models.ProfileOut), profile
        assert len(profile.rows) > 100
        row = profile.rows[0].to_dict()
        assert {"km", "sleeper_amp", "speed_mean"} <= set(row)
        exported = export_csv.sync_detailed(run.id, client=c, wheel="11")
        assert exported.status_code == 200
        lines = exported.content.decode().splitlines()
        assert lines[0].replace('"', "").startswith("wheel,bin,km") and len(lines) - 1 >= len(profile.rows)
        bad = upload.sync_detailed(client=c, body=models.UploadRunApiV1RunsPostFilesBody(
            file=types.File(payload=io.BytesIO(rec.path.read_bytes()[:4096]), file_name="cut.mf4",
                            mime_type="application/octet-stream"),
            metadata=json.dumps(rec.metadata), channel_map=str(cmap.id)))
        assert bad.status_code == 422 and isinstance(bad.parsed, models.ApiError)
