"""Issue 24, defects 2 and 5: hostile requests get a 4xx naming the field, never a 500;
and a 500 that still happens answers in the project's error shape on a connection that stays open."""

from __future__ import annotations

import json
import socket
import threading
import time
from pathlib import Path

import pytest
import uvicorn
from fastapi import Depends

from app.api.deps import require_role
from app.main import create_app
from tests.api.support import create_api_key, make_settings, migrate_database

FEATURE = {
    "type": "Feature",
    "properties": {"line_id": "4010", "track": "1", "km": [12.0, 12.1]},
    "geometry": {"type": "LineString", "coordinates": [[9.0, 48.0], [9.0, 48.0009]]},
}


def _collection(**over) -> dict:
    feature = json.loads(json.dumps(FEATURE))
    feature["properties"].update(over)
    return {"type": "FeatureCollection", "features": [feature]}


def _post_geometry(client, text: str | bytes):
    return client.post("/api/v1/geometry", files={"file": ("g.geojson", text, "application/geo+json")})


def _field(r, status: int | tuple[int, ...] = 422) -> str:
    want = (status,) if isinstance(status, int) else status
    assert r.status_code in want, r.text
    body = r.json()
    assert set(body) == {"detail", "field"}, body
    assert body["detail"].startswith(f"{body['field']}: "), body
    return body["field"]


def test_geometry_is_accepted(client) -> None:
    r = _post_geometry(client, json.dumps(_collection()))
    assert r.status_code == 201, r.text


def test_geometry_nested_deeper_than_the_recursion_limit_is_a_4xx(client) -> None:
    doc = json.dumps(_collection())
    deep = "[" * 100_000 + "]" * 100_000
    text = doc.replace('"line_id": "4010"', f'"line_id": "4010", "extra": {deep}')
    assert _field(_post_geometry(client, text)) == "file"


def test_geometry_integer_of_5000_digits_is_a_4xx(client) -> None:
    text = json.dumps(_collection()).replace('"line_id": "4010"', '"line_id": ' + "7" * 5000)
    field = _field(_post_geometry(client, text))
    assert field in ("file", "features[0]")


def test_geometry_coordinate_of_5000_digits_is_a_4xx(client) -> None:
    text = json.dumps(_collection()).replace("[9.0, 48.0]", "[9" + "0" * 5000 + ", 48.0]")
    _field(_post_geometry(client, text))


@pytest.mark.parametrize("crs", ["IAU_2015:49900", "IAU_2015:30100", "EPSG:4978", "EPSG:5714",
                                 "ESRI:104971"])
def test_geometry_non_earth_or_non_horizontal_crs_is_a_4xx_naming_crs(client, crs: str) -> None:
    doc = _collection()
    doc["crs"] = {"type": "name", "properties": {"name": crs}}
    assert _field(_post_geometry(client, json.dumps(doc))) == "crs"


def test_geometry_nul_in_line_id_is_refused(client) -> None:
    r = _post_geometry(client, json.dumps(_collection(line_id="40\x0010")))
    assert _field(r) == "features[0]"
    assert "NUL" in r.json()["detail"]
    r = _post_geometry(client, json.dumps(_collection(track="1\x00")))
    assert _field(r) == "features[0]"


def test_channel_map_nul_in_source_is_refused(client) -> None:
    for channels in ({"Z11": "AccZ\x00_1R"}, {"Z11": {"source": "AccZ_1R", "group": "A\x00"}},
                     {"Z11": {"source": "AccZ_1R", "unit": "g\x00"}}):
        r = client.post("/api/v1/channel-maps", json={"vehicle_id": "V-7", "name": "m", "channels": channels})
        field = _field(r)
        assert field.startswith("channel_map.channels.Z11"), r.text
        assert "NUL" in r.json()["detail"]
    r = client.post("/api/v1/channel-maps", json={"vehicle_id": "V-7", "name": "m\x00",
                                                  "channels": {"Z11": "AccZ_1R"}})
    assert _field(r) == "name", r.text
    r = client.post("/api/v1/channel-maps", json={"vehicle_id": "V\x007", "name": "m",
                                                  "channels": {"Z11": "AccZ_1R"}})
    assert _field(r) == "vehicle_id", r.text


def test_alignment_reference_run_id_2_63_is_a_4xx(client) -> None:
    r = client.get("/api/v1/runs/1/alignment", params={"reference_run_id": 2**63})
    assert _field(r) == "reference_run_id"
    r = client.get(f"/api/v1/runs/{2**63}/alignment")
    assert _field(r) == "run_id"


def test_every_integer_id_parameter_is_bounded(client) -> None:
    """Every path or query parameter named ``*_id`` that is an integer has a maximum (2³¹−1)."""
    schema = client.get("/api/v1/openapi.json").json() if False else client.app.openapi()
    unbounded = []
    for path, ops in schema["paths"].items():
        for method, op in ops.items():
            for p in op.get("parameters", []) if isinstance(op, dict) else []:
                s = p.get("schema", {})
                options = s.get("anyOf", [s])
                for o in options:
                    if o.get("type") == "integer" and (p["name"].endswith("_id") or p["name"] == "id"):
                        if o.get("maximum", 2**63) > 2**31 - 1:
                            unbounded.append(f"{method.upper()} {path} {p['name']}")
    assert unbounded == []


@pytest.mark.parametrize("body", ["deep", "huge-int", "huge-float", "long"])
def test_patch_with_deep_or_huge_json_names_the_field(client, body: str) -> None:
    text = {
        "deep": '{"metadata": ' + "[" * 100_000 + "]" * 100_000 + "}",
        "huge-int": '{"metadata": {"km_start": ' + "9" * 5000 + "}}",
        "huge-float": '{"metadata": {"km_start": 1' + "0" * 400 + ".5}}",
        "long": '{"metadata": {"vehicle_id": "' + "x" * 3_000_000 + '"}}',
    }[body]
    r = client.patch("/api/v1/runs/1", content=text, headers={"content-type": "application/json"})
    assert r.status_code in (400, 404, 413, 422), r.text
    body_ = r.json()
    assert set(body_) == {"detail", "field"}, body_
    if r.status_code != 404:
        assert body_["field"] in ("body", "metadata", "metadata.km_start", "metadata.vehicle_id", "request")


def test_unknown_route_and_method_answer_in_the_error_shape(client) -> None:
    assert _field(client.get("/api/v1/no-such-thing"), 404) == "path"
    assert _field(client.delete("/api/v1/health"), 405) == "method"


# --- a 500 keeps the connection --------------------------------------------------------


def _http(sock: socket.socket, path: str, key: str) -> tuple[int, dict[str, str], bytes]:
    sock.sendall(
        f"GET {path} HTTP/1.1\r\nHost: 127.0.0.1\r\nAuthorization: Bearer {key}\r\n\r\n".encode()
    )
    buf = b""
    while b"\r\n\r\n" not in buf:
        chunk = sock.recv(65536)
        if not chunk:
            raise ConnectionError("connection closed before the answer's header")
        buf += chunk
    head, _, rest = buf.partition(b"\r\n\r\n")
    lines = head.decode("latin-1").split("\r\n")
    status = int(lines[0].split()[1])
    headers = {k.lower(): v.strip() for k, v in (line.split(":", 1) for line in lines[1:])}
    length = int(headers.get("content-length", "0"))
    while len(rest) < length:
        chunk = sock.recv(65536)
        if not chunk:
            raise ConnectionError("connection closed inside the answer's body")
        rest += chunk
    return status, headers, rest[:length]


def test_a_500_answers_in_the_error_shape_and_keeps_the_connection(tmp_path: Path) -> None:
    settings = make_settings(tmp_path)
    migrate_database(settings.database_url)
    key = create_api_key(settings.database_url, "viewer")
    app = create_app(settings)

    def explode() -> dict:
        raise RuntimeError("a bug with a secret path /etc/shadow in its message")

    app.add_api_route("/api/v1/explode", explode, methods=["GET"], dependencies=[Depends(require_role("viewer"))])
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="critical"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    try:
        deadline = time.monotonic() + 30
        while not server.started:
            assert time.monotonic() < deadline, "uvicorn did not start"
            time.sleep(0.05)
        with socket.create_connection(("127.0.0.1", port), timeout=10) as sock:
            status, headers, body = _http(sock, "/api/v1/explode", key)
            assert status == 500
            doc = json.loads(body)
            assert doc == {"detail": "server: internal error (logged on the server)", "field": "server"}
            assert "connection" not in headers or headers["connection"].lower() != "close"
            assert headers.get("x-content-type-options") == "nosniff"  # the security headers too
            status, _, body = _http(sock, "/api/v1/health", key)  # the same connection
            assert status == 200, body
    finally:
        server.should_exit = True
        thread.join(10)
