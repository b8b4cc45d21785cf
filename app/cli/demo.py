"""Command ``demo``: migrate, simulate the demo data, start API and worker, upload and process
it over HTTP (runs of two lines at several dates and reference data: every page has content)."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Annotated

import typer

from app.cli._common import cli_audit, database, echo, new_password, service_settings

__all__ = ["demo"]


def _demo_credentials(settings) -> tuple[str | None, str, int]:
    """Create the demo admin on first start; a short-lived upload key every start.

    Returns the admin password when it was created now (else None) and the key.
    """
    import datetime as dt

    from app.db import auth_crud
    from app.db.models import utcnow

    db = database()
    password = None
    try:
        with db.write() as session:
            if auth_crud.count_users(session) == 0:
                password = new_password()
                auth_crud.create_user(
                    session, "admin", password, "admin", created_by="demo", demo_credentials=True,
                    password_cost=settings.password_cost,
                )
                cli_audit(session, "user.create", "admin", {"role": "admin", "by": "demo"})
            row, key = auth_crud.create_api_key(
                session, "demo-upload", "engineer", created_by="demo",
                expires_at=utcnow() + dt.timedelta(hours=1),
            )
            cli_audit(session, "key.create", str(row.id), {"name": row.name, "role": row.role, "by": "demo"})
            key_id = row.id
    finally:
        db.dispose()
    return password, key, key_id


def _revoke_demo_key(key_id: int) -> None:
    from app.db import auth_crud

    db = database()
    try:
        with db.write() as session:
            auth_crud.revoke_api_key(session, key_id)
            cli_audit(session, "key.revoke", str(key_id), {"name": "demo-upload", "by": "demo"})
    finally:
        db.dispose()


def _port_free(host: str, port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        try:
            sock.bind((host, port))
        except OSError:
            return False
        return True


def _wait_healthy(base: str, procs: list[subprocess.Popen], timeout_s: float = 60.0) -> None:
    import httpx

    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        for p in procs:
            if p.poll() is not None:
                raise RuntimeError(f"process {p.args} exited with {p.returncode}")
        try:
            if httpx.get(f"{base}/api/v1/health", timeout=2).status_code == 200:
                return
        except httpx.HTTPError:
            pass
        time.sleep(0.3)
    raise RuntimeError(f"the API did not answer on {base} within {timeout_s:.0f} s")


def _stop(procs: list[subprocess.Popen]) -> None:
    for p in procs:
        if p.poll() is None:
            p.send_signal(signal.SIGTERM)
    for p in procs:
        try:
            p.wait(timeout=15)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


def _post_file(client, url: str, path: Path, content_type: str, params: dict | None = None) -> tuple[int, dict]:
    """POST a file as the multipart field ``file``; (status, JSON body). Raises RuntimeError
    naming the file for anything but 200/201."""
    with open(path, "rb") as fh:
        resp = client.post(url, params=params, files={"file": (path.name, fh, content_type)})
    if resp.status_code not in (200, 201):
        raise RuntimeError(f"{path.name}: {resp.status_code} {resp.text}")
    return resp.status_code, resp.json()


def _upload_runs(client, base: str, files: list[Path]) -> list[dict]:
    """Upload the run files (a file uploaded before answers 200 with its run); the runs."""
    runs = []
    for path in files:
        status, run = _post_file(client, f"{base}/api/v1/runs", path, "application/x-hdf5")
        state = "created" if status == 201 else "already uploaded"
        echo(f"  run {run['id']} {state}: line {run['line_id']} track {run['track']}, "
             f"{run['vehicle_id']}, {str(run['start_time'])[:10]}")
        runs.append(run)
    return runs


def _import_reference(client, base: str, files: dict[str, Path]) -> None:
    """Import the reference files, replacing what the demo imported before (confirmed: on a restart
    the demo's line has its runs, and the rows are the same)."""
    for kind, path in files.items():
        _, body = _post_file(client, f"{base}/api/v1/reference/{kind}", path, "text/csv",
                             {"mode": "replace", "confirm": "true"})
        echo(f"  {kind}: {body['imported']} rows")


def _import_geometry(client, base: str, files: list[Path]) -> None:
    """Import the lines' geometry (a line imported again replaces its geometry)."""
    for path in files:
        _post_file(client, f"{base}/api/v1/geometry", path, "application/geo+json")
        echo(f"  geometry: {path.name}")


def _import_assets(client, base: str, path: Path | None) -> None:
    """Import the line's known discontinuities (an import replaces the line's assets)."""
    if path is None:
        return
    _, body = _post_file(client, f"{base}/api/v1/assets", path, "text/csv")
    echo(f"  assets: {body['imported']} (switches, bridge, level crossing, joint, weld)")


def _settled(job: dict) -> bool:
    """A job ended, and if it published, its run's places follow-up ran (issue 24: the places follow
    the publish commit)."""
    if job["status"] in ("queued", "running"):
        return False
    places = ((job.get("meta") or {}).get("condition") or {}).get("places") or {}
    return not (job["status"] == "done" and places.get("pending"))


def _wait_jobs(client, base: str, runs: list[dict], procs: list[subprocess.Popen]) -> None:
    """Follow the runs' latest jobs until none is queued or running and their places are updated,
    printing changes."""
    jobs = {run["latest_job"]["id"]: run["latest_job"] for run in runs if run.get("latest_job")}
    shown: dict[int, tuple] = {}
    while True:
        for job_id, job in jobs.items():
            state = (job["status"], job["chunks_done"], job["n_chunks"])
            if shown.get(job_id) != state:
                chunks = f", {job['chunks_done']}/{job['n_chunks']} chunks" if job["n_chunks"] else ""
                error = f": {job['error']}" if job.get("error") else ""
                echo(f"  job {job_id} (run {job['run_id']}) {job['status']}{chunks}{error}")
                shown[job_id] = state
        if all(_settled(job) for job in jobs.values()):
            return
        time.sleep(1.0)
        for p in procs:
            if p.poll() is not None:
                raise RuntimeError(f"process {p.args} exited with {p.returncode}")
        for job_id, job in jobs.items():
            if not _settled(job):
                jobs[job_id] = client.get(f"{base}/api/v1/jobs/{job_id}").json()


def _activate_hint() -> str:
    """How to get ``trackvkf`` on PATH in another terminal (the venv the demo runs in)."""
    venv = Path(sys.prefix)
    if venv.name == ".venv":
        return f"cd {venv.parent} && source .venv/bin/activate && trackvkf --help"
    return f"source {venv}/bin/activate && trackvkf --help"


def _where_to_look(base: str, runs: list[dict], line: tuple[str, str]) -> str:
    first = runs[0]["id"]
    api = f"{base}/api/v1"
    line_q = f"line_id={line[0]}&track={line[1]}"
    return (
        "\nWhere to look:\n"
        f"  dashboard (runs)         {base}/\n"
        f"  stiffness map, run {first:<5} {base}/runs/{first}\n"
        f"  line view                {base}/lines\n"
        f"  condition (places)       {base}/condition\n"
        f"  map                      {base}/map\n"
        f"  wheels                   {base}/wheels\n"
        f"  correlations             {base}/correlations\n"
        f"  API docs (OpenAPI)       {base}/docs\n"
        f"  run detail (JSON)        {api}/runs/{first}\n"
        f"  profile, wheel 11, 10 m  {api}/runs/{first}/profile?wheel=11&level=10\n"
        f"  profile export (CSV)     {api}/runs/{first}/profile.csv?wheel=11\n"
        f"  wheel OOR                {api}/runs/{first}/wheels\n"
        f"  subsidence fit           {api}/analytics/subsidence-fit?{line_q}\n"
        f"  places (work list)       {api}/condition/places?{line_q}\n"
        f"  section classes          {api}/condition/sections?{line_q}\n"
        f"  assets                   {api}/assets?{line_q}\n"
        f"  jobs                     {api}/jobs\n"
        "\nThe command line, in another terminal:\n"
        f"  {_activate_hint()}\n"
    )


def demo(
    host: Annotated[str, typer.Option(help="Interface for the API")] = "127.0.0.1",
    port: Annotated[int, typer.Option(help="TCP port for the API")] = 8000,
    length_km: Annotated[float, typer.Option(help="Length of each demo run, km (>= 2)")] = 3.0,
    fs: Annotated[float, typer.Option(help="Sample rate of the demo runs, Hz")] = 10_000.0,
    serve_after: Annotated[
        bool, typer.Option("--serve/--no-serve", help="Keep serving after processing (until Ctrl-C)")
    ] = True,
) -> None:
    """Migrate, simulate the demo data (a history of 10 runs of line SIM with a tamping, a developing
    soft spot and a new change, one run of SIM-B, reference data, assets, line geometry), start API
    and worker, import and upload it all over HTTP, process it, print where to look."""
    import httpx

    from app.db import migrate as db_migrate
    from app.simulate.demo import DEMO_HISTORY_RUNS, DEMO_RUNS, write_demo_dataset

    settings = service_settings()
    if settings.is_production:
        typer.echo("error: the demo does not run with TRACKVKF_ENV=production", err=True)
        raise typer.Exit(2)
    if not length_km >= 2:
        typer.echo(f"error: --length-km must be >= 2 (the demo's history needs it), got {length_km:g}", err=True)
        raise typer.Exit(2)
    if not _port_free(host, port):
        typer.echo(f"error: port {port} on {host} is in use; pass --port", err=True)
        raise typer.Exit(1)
    db_migrate.upgrade(settings.database_url)
    echo(f"database ready: {settings.database_url}")
    admin_password, upload_key, upload_key_id = _demo_credentials(settings)

    demo_dir = Path(settings.run_store).resolve().parent / "demo"
    # the amplitudes follow the resonance model (app.simulate.amplitude): not a power law in speed
    n_runs = DEMO_HISTORY_RUNS + sum(r.line_id != DEMO_RUNS[0].line_id for r in DEMO_RUNS)
    echo(f"demo data in {demo_dir}: {n_runs} runs of {length_km:g} km at {fs:g} Hz "
         "(a history of line SIM, two weeks apart), reference data and assets (simulated once, then reused) ...")
    data = write_demo_dataset(demo_dir, length_km=length_km, fs=fs, amplitude_model="resonance", history=True)

    base = f"http://{host}:{port}"
    env = dict(os.environ)

    def _interrupt(signum: int, frame: object) -> None:  # noqa: ARG001
        raise KeyboardInterrupt

    # Ctrl-C and SIGTERM stop the demo and its processes (also when started in background)
    signal.signal(signal.SIGINT, _interrupt)
    signal.signal(signal.SIGTERM, _interrupt)
    api = subprocess.Popen(
        [sys.executable, "-m", "uvicorn", "--factory", "app.main:create_app",
         "--host", host, "--port", str(port), "--log-level", "warning"],
        env=env,
    )
    wrk = subprocess.Popen([sys.executable, "-m", "worker"], env=env)
    procs = [api, wrk]
    try:
        _wait_healthy(base, procs)
        echo(f"API up at {base}; importing and uploading the demo data ...")
        headers = {"Authorization": f"Bearer {upload_key}"}
        with httpx.Client(timeout=600, headers=headers) as client:
            # reference data first: a run's places are found when it is published, on its line's
            # superstructure classes and maintenance records as they are then
            echo(f"importing the reference data of line {data.reference_line[0]} "
                 f"track {data.reference_line[1]} ...")
            _import_reference(client, base, data.reference)
            _import_geometry(client, base, data.geometry)
            _import_assets(client, base, data.assets)
            echo("uploading the runs (in date order: the worker processes them in that order) ...")
            runs = _upload_runs(client, base, data.runs)
            _wait_jobs(client, base, runs, procs)
        _revoke_demo_key(upload_key_id)
        if admin_password is not None:
            login = (
                "Log in (first start: these credentials are printed once and stored hashed;\n"
                "change the password with `trackvkf user set-password admin`):\n"
                f"  user admin\n  password {admin_password}\n"
            )
        else:
            login = (
                "Log in as admin with the password printed at the first demo start\n"
                "(forgotten: `trackvkf user set-password admin --generate`).\n"
            )
        echo(f"\n{login}  login page               {base}/login")
        echo(_where_to_look(base, runs, data.reference_line))
        if not serve_after:
            return
        echo("Serving until Ctrl-C ...")
        while all(p.poll() is None for p in procs):
            time.sleep(0.5)
        raise RuntimeError("a service process exited unexpectedly")
    except KeyboardInterrupt:
        echo("\nstopping ...")
    except RuntimeError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(1) from None
    finally:
        _stop(procs)
