"""Command ``demo``: migrate, simulate a demo run, start API and worker, process it over HTTP."""

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

from app.cli._common import cli_audit, database, echo, new_password
from app.core.config import get_settings

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
                    session, "admin", password, "admin", created_by="demo", demo_credentials=True
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


def demo(
    host: Annotated[str, typer.Option(help="Interface for the API")] = "127.0.0.1",
    port: Annotated[int, typer.Option(help="TCP port for the API")] = 8000,
    length_km: Annotated[float, typer.Option(help="Length of the demo run, km")] = 3.0,
    fs: Annotated[float, typer.Option(help="Sample rate of the demo run, Hz")] = 10_000.0,
    serve_after: Annotated[
        bool, typer.Option("--serve/--no-serve", help="Keep serving after processing (until Ctrl-C)")
    ] = True,
) -> None:
    """Migrate, simulate a demo run, start API and worker, upload and process it over HTTP."""
    import httpx

    from app.db import migrate as db_migrate

    settings = get_settings()
    if settings.is_production:
        typer.echo("error: the demo does not run with TRACKVKF_ENV=production", err=True)
        raise typer.Exit(2)
    db_migrate.upgrade(settings.database_url)
    echo(f"database ready: {settings.database_url}")
    admin_password, upload_key, upload_key_id = _demo_credentials(settings)

    demo_dir = Path(settings.run_store).resolve().parent / "demo"
    # the amplitude follows the resonance model (app.simulate.amplitude): not a power law in speed
    run_file = demo_dir / f"demo-run-{length_km:g}km-{fs:g}Hz-resonance.h5"
    if not run_file.is_file():
        echo(f"simulating a {length_km:g} km demo run at {fs:g} Hz ...")
        from app.simulate.run import simulate_run

        demo_dir.mkdir(parents=True, exist_ok=True)
        simulate_run(run_file, length_km=length_km, fs=fs, seed=7, with_forces=True)
    echo(f"demo run: {run_file}")

    if not _port_free(host, port):
        typer.echo(f"error: port {port} on {host} is in use; pass --port", err=True)
        raise typer.Exit(1)
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
        echo(f"API up at {base}; uploading the demo run ...")
        headers = {"Authorization": f"Bearer {upload_key}"}
        with open(run_file, "rb") as fh, httpx.Client(timeout=600, headers=headers) as client:
            resp = client.post(
                f"{base}/api/v1/runs",
                files={"file": (run_file.name, fh, "application/x-hdf5")},
            )
            if resp.status_code not in (200, 201):
                raise RuntimeError(f"upload failed: {resp.status_code} {resp.text}")
            run = resp.json()
            run_id = run["id"]
            echo(f"run {run_id} {'created' if resp.status_code == 201 else 'already uploaded'}")
            job = run["latest_job"]
            last: tuple = ()
            while job["status"] in ("queued", "running"):
                state = (job["status"], job["chunks_done"], job["n_chunks"])
                if state != last:
                    chunks = f", {job['chunks_done']}/{job['n_chunks']} chunks" if job["n_chunks"] else ""
                    echo(f"  job {job['id']} {job['status']}{chunks}")
                    last = state
                time.sleep(1.0)
                for p in procs:
                    if p.poll() is not None:
                        raise RuntimeError(f"process {p.args} exited with {p.returncode}")
                job = client.get(f"{base}/api/v1/jobs/{job['id']}").json()
            echo(f"  job {job['id']} {job['status']}" + (f": {job['error']}" if job["error"] else ""))
        _revoke_demo_key(upload_key_id)
        runs = f"{base}/api/v1/runs/{run_id}"
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
        echo(
            "\nWhere to look:\n"
            f"  API docs (OpenAPI)       {base}/docs\n"
            f"  run detail               {runs}\n"
            f"  profile, wheel 11, 10 m  {runs}/profile?wheel=11&level=10\n"
            f"  profile export (CSV)     {runs}/profile.csv?wheel=11\n"
            f"  wheel OOR                {runs}/wheels\n"
            f"  jobs                     {base}/api/v1/jobs\n"
        )
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
