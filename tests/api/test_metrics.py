"""Issue 24 defect 8: /metrics was 404 and the logs plain text. Prometheus metrics (admin only)
over the ASGI client on a real database: requests by route template and status with latency
histograms, uploads and bytes, jobs by state, queue depth, workers, processing seconds per
run-second, webhook deliveries by outcome, condition flags; JSON log lines when asked."""

from __future__ import annotations

import io
import json
import logging
import os
import subprocess
import sys

from prometheus_client.parser import text_string_to_metric_families

from app.core.logging import JsonFormatter, configure_logging
from app.db import webhooks
from app.db.session import Database
from tests.api.support import auth_headers, create_api_key
from tests.faults.support import hdf5_run, upload_file
from worker.runner import LocalWorker


def scrape(client) -> dict[tuple[str, tuple], float]:
    """The samples of a scrape: (name, sorted labels) → value."""
    r = client.get("/metrics")
    assert r.status_code == 200, r.text
    assert r.headers["content-type"].startswith("text/plain")
    out = {}
    for family in text_string_to_metric_families(r.text):
        for sample in family.samples:
            out[(sample.name, tuple(sorted(sample.labels.items())))] = sample.value
    return out


def value(samples, name: str, **labels) -> float:
    return samples.get((name, tuple(sorted(labels.items()))), 0.0)


def test_metrics_need_an_admin(client):
    viewer = create_api_key(client.settings.database_url, "viewer", "v")
    assert client.get("/metrics", headers={"Authorization": ""}).status_code == 401
    r = client.get("/metrics", headers=auth_headers(viewer))
    assert r.status_code == 403 and r.json()["field"] == "role"


def test_requests_are_counted_by_route_template_and_status(client):
    before = scrape(client)
    for run_id in (101, 102, 103):  # three ids, one route template
        assert client.get(f"/api/v1/runs/{run_id}").status_code == 404
    client.get("/api/v1/health")
    client.get("/no/such/page")
    after = scrape(client)
    route = "/api/v1/runs/{run_id}"
    assert value(after, "trackvkf_http_requests_total", method="GET", route=route, status="404") - value(
        before, "trackvkf_http_requests_total", method="GET", route=route, status="404") == 3
    assert not any("/api/v1/runs/101" in str(k) for k in after)  # ids never become labels
    assert value(after, "trackvkf_http_request_duration_seconds_count", method="GET", route=route) - value(
        before, "trackvkf_http_request_duration_seconds_count", method="GET", route=route) == 3
    assert value(after, "trackvkf_http_requests_total", method="GET", route="(unmatched)", status="404") >= 1


def test_uploads_jobs_queue_processing_and_deliveries(client, tmp_path):
    settings = client.settings
    client.app.state.metrics_collector.cache_s = 0.0  # the database series are cached 5 s per process
    before = scrape(client)
    path = hdf5_run(tmp_path, n=40_000)
    size = path.stat().st_size
    assert upload_file(client, path).status_code == 201
    assert upload_file(client, path).status_code == 200  # the same file again
    empty = tmp_path / "empty.h5"
    empty.write_bytes(b"")
    assert upload_file(client, empty).status_code == 422
    mid = scrape(client)
    for outcome, n in (("created", 1), ("duplicate", 1), ("rejected", 1)):
        assert value(mid, "trackvkf_uploads_total", outcome=outcome) - value(
            before, "trackvkf_uploads_total", outcome=outcome) == n
    got = value(mid, "trackvkf_upload_bytes_total") - value(before, "trackvkf_upload_bytes_total")
    assert 2 * size < got < 2 * size + 10_000  # two bodies (and the multipart framing)
    assert value(mid, "trackvkf_jobs", status="queued") == 1 and value(mid, "trackvkf_queue_depth") == 1
    assert value(mid, "trackvkf_workers_alive", mode="local") == 0
    assert value(mid, "trackvkf_job_seconds_per_run_second_count") == 0

    db = Database(settings.database_url)
    worker = LocalWorker(settings, db=db)
    try:
        assert worker.run(exit_when_idle=True) == 1
        with db.write() as s:
            webhooks.create_webhook(s, "http://127.0.0.1:9/never")  # refused by the default policy
            webhooks.enqueue(s, webhooks.EVENT_PING, {"event": "ping"})
    finally:
        worker.runtime.close()
    after = scrape(client)
    assert value(after, "trackvkf_jobs", status="done") == 1 and value(after, "trackvkf_queue_depth") == 0
    assert value(after, "trackvkf_job_seconds_per_run_second_count") == 1
    assert 0 < value(after, "trackvkf_job_seconds_per_run_second_sum") < 60
    assert value(after, "trackvkf_job_seconds_per_run_second_bucket", le="+Inf") == 1
    assert value(after, "trackvkf_webhook_deliveries", status="pending", outcome="none") == 1
    from worker.deliveries import deliver_due

    assert deliver_due(db, settings) == 1
    after = scrape(client)
    assert value(after, "trackvkf_webhook_deliveries", status="pending", outcome="refused") == 1
    db.dispose()
    text = client.get("/metrics").text
    for family in ("trackvkf_condition_flags", "trackvkf_jobs_stuck", "trackvkf_queue_oldest_age_seconds"):
        assert f"# HELP {family} " in text


def test_json_log_lines():
    stream = io.StringIO()
    handler = logging.StreamHandler(stream)
    handler.setFormatter(JsonFormatter())
    logger = logging.getLogger("tests.jsonlog")
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)
    logger.propagate = False
    try:
        logger.info("run %s created", 7)
        try:
            raise ValueError("bad \"thing\"\n2nd line")
        except ValueError:
            logger.exception("failed")
    finally:
        logger.removeHandler(handler)
    first, second = (json.loads(line) for line in stream.getvalue().splitlines())
    assert first["message"] == "run 7 created" and first["level"] == "INFO" and first["logger"] == "tests.jsonlog"
    assert first["time"].endswith("Z") and isinstance(first["pid"], int)
    assert second["level"] == "ERROR" and 'ValueError: bad "thing"' in second["exception"]


def test_a_worker_process_logs_json_lines_when_asked(service_settings, tmp_path):
    """``TRACKVKF_LOG_FORMAT=json``: every line a real worker process writes is one JSON object."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("TRACKVKF_")}
    env.update(TRACKVKF_DATABASE_URL=service_settings.database_url, TRACKVKF_RUN_STORE=str(tmp_path / "runs"),
               TRACKVKF_LOG_FORMAT="json", TRACKVKF_LOG_LEVEL="INFO")
    proc = subprocess.run([sys.executable, "-m", "worker", "--exit-when-idle"], env=env, cwd=tmp_path,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    lines = [json.loads(line) for line in proc.stderr.splitlines()]
    assert any(x["logger"] == "worker.runner" and "started" in x["message"] for x in lines), lines
    bad = subprocess.run([sys.executable, "-m", "worker", "--exit-when-idle"], cwd=tmp_path, capture_output=True,
                         text=True, timeout=120, env={**env, "TRACKVKF_LOG_FORMAT": "xml"})
    assert bad.returncode != 0 and "log_format" in bad.stderr


def test_configure_logging_refuses_an_unknown_format():
    try:
        configure_logging("INFO", "xml")
    except ValueError as exc:
        assert "xml" in str(exc)
    else:
        raise AssertionError("xml accepted")
