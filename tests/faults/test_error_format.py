"""Issue 18 item 11: every error in the documented ``{"detail", "field"}`` form.

Validation errors of query, path and body parameters came in FastAPI's list
format; CSV files with NUL bytes or bytes that are not UTF-8 got "not
delimited text". Both are precise now.
"""

from __future__ import annotations

import json

import pytest

from tests.api import runfiles
from tests.faults.support import csv_run, last_upload_audit, upload_file


@pytest.mark.parametrize(
    ("method", "url", "kwargs", "field"),
    [
        ("get", "/api/v1/runs", {"params": {"limit": "abc"}}, "limit"),
        ("get", "/api/v1/runs", {"params": {"limit": 0}}, "limit"),
        ("get", "/api/v1/runs/abc", {}, "run_id"),
        ("get", "/api/v1/runs/99999999999999999999", {}, "run_id"),
        ("get", "/api/v1/jobs", {"params": {"status": "x" * 500}}, "status"),
        ("post", "/api/v1/runs/1/jobs", {"json": {"bandwidth_orders": "wide"}}, "bandwidth_orders"),
        ("post", "/api/v1/runs/1/jobs", {"content": b"{not json", "headers": {"content-type": "application/json"}}, "body"),
        ("post", "/api/v1/auth/login", {"json": {"username": "a"}}, "password"),
    ],
)
def test_request_validation_errors_name_the_field(client, method, url, kwargs, field):
    r = getattr(client, method)(url, **kwargs)
    assert r.status_code == 422, r.text
    body = r.json()
    assert set(body) == {"detail", "field"}, body
    assert body["field"] == field
    assert isinstance(body["detail"], str) and body["detail"].startswith(f"{field}: ")
    assert len(body["detail"]) < 400


def test_the_openapi_schema_documents_the_error_form(client):
    schema = client.get("/openapi.json").json()
    assert "HTTPValidationError" not in schema["components"]["schemas"]
    error = schema["components"]["schemas"]["ApiError"]
    assert set(error["properties"]) == {"detail", "field"}
    refs = [
        op["responses"]["422"]["content"]["application/json"]["schema"]
        for ops in schema["paths"].values() for op in ops.values() if "422" in op.get("responses", {})
    ]
    assert refs and all(r == {"$ref": "#/components/schemas/ApiError"} for r in refs)


@pytest.mark.parametrize("name", ["nul.csv", "nul"])
def test_csv_with_a_nul_byte(client, tmp_path, name):
    path = tmp_path / name
    good = csv_run(tmp_path).read_bytes()
    cut = good.index(b"\n", 2000) + 5
    path.write_bytes(good[:cut] + b"\x00" + good[cut:])
    r = upload_file(client, path, json.dumps(runfiles.metadata()), "text/csv")
    assert r.status_code == 422, r.text
    detail = r.json()["detail"]
    assert "NUL" in detail and f"byte {cut}" in detail, detail
    assert "not delimited text" not in detail
    assert last_upload_audit(client)["outcome"] == "rejected"


@pytest.mark.parametrize("where", ["head", "tail"])
def test_csv_that_is_not_utf8(client, tmp_path, where):
    good = csv_run(tmp_path).read_bytes()
    cut = good.index(b"\n", 100 if where == "head" else len(good) - 3000) + 3
    path = tmp_path / "latin1.csv"
    path.write_bytes(good[:cut] + "é".encode("latin-1") + good[cut:])
    r = upload_file(client, path, json.dumps(runfiles.metadata()), "text/csv")
    assert r.status_code == 422, r.text
    detail = r.json()["detail"]
    assert "UTF-8" in detail and f"byte {cut}" in detail and "0xe9" in detail, detail
