"""Command line of trackvkf: ``serve``, ``worker``, ``migrate``, ``demo``, ``simulate``,
``process``, ``user`` (create, set-password, list) and ``key`` (create, revoke, list).

Every command reads the service settings from ``TRACKVKF_*`` environment
variables (see :class:`app.core.config.Settings`).
"""

from __future__ import annotations

import hashlib
import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Annotated, Any

import typer

from app.core.config import get_settings
from app.core.logging import configure_logging

__all__ = ["app", "main"]

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    help="Track stiffness and wheel out-of-roundness from axle-box accelerations.",
)


def _echo(message: str) -> None:
    typer.echo(message, err=False)


def _refuse_unsafe_production() -> None:
    """Exit with a message when production mode is configured unsafely."""
    from app.core.config import ProductionConfigError
    from app.db.session import Database
    from app.main import check_production_database

    settings = get_settings()
    try:
        settings.check_production()
        if settings.is_production:
            db = Database(settings.database_url)
            try:
                check_production_database(db)
            finally:
                db.dispose()
    except ProductionConfigError as exc:
        typer.echo(f"error: refusing to start in production mode: {exc}", err=True)
        raise typer.Exit(2) from None


# --- service ----------------------------------------------------------------
@app.command()
def serve(
    host: Annotated[str, typer.Option(help="Interface to listen on")] = "127.0.0.1",
    port: Annotated[int, typer.Option(help="TCP port")] = 8000,
    log_level: Annotated[str, typer.Option(help="uvicorn log level")] = "info",
) -> None:
    """Run the REST API (uvicorn). Migrate the database first (``trackvkf migrate``).

    With ``TRACKVKF_ENV=production`` it refuses to start without a secret key
    of its own or while a user still has the password printed by ``demo``.
    """
    import uvicorn

    _refuse_unsafe_production()
    uvicorn.run(
        "app.main:create_app", factory=True, host=host, port=port, log_level=log_level.lower()
    )


@app.command()
def worker(
    once: Annotated[bool, typer.Option(help="Exit after one job (local mode)")] = False,
    exit_when_idle: Annotated[bool, typer.Option(help="Exit when no job is queued")] = False,
    processes: Annotated[
        int, typer.Option(help="PostgreSQL mode: worker processes (0 = one per core)")
    ] = 1,
    local: Annotated[bool, typer.Option(help="Local job loop even on PostgreSQL")] = False,
) -> None:
    """Process queued jobs until Ctrl-C: the local worker on SQLite, Procrastinate
    workers on PostgreSQL (mode from TRACKVKF_DATABASE_URL)."""
    from worker.runner import run_worker

    settings = get_settings()
    configure_logging(settings.log_level)
    try:
        if settings.is_sqlite or local:
            run_worker(settings, once=once, exit_when_idle=exit_when_idle)
        else:
            from worker.tasks import run_worker_process, run_workers

            code = (
                run_worker_process(settings, wait=False)
                if exit_when_idle
                else run_workers(settings, processes)
            )
            if code:
                raise typer.Exit(code)
    except KeyboardInterrupt:
        raise typer.Exit(130) from None


@app.command()
def migrate(
    revision: Annotated[str, typer.Option(help="Target revision")] = "head",
) -> None:
    """Apply the database migrations (Alembic) to TRACKVKF_DATABASE_URL."""
    from app.db import migrate as db_migrate

    settings = get_settings()
    db_migrate.upgrade(settings.database_url, revision)
    _echo(f"database {settings.database_url} at {db_migrate.current_revision(settings.database_url)}")


# --- simulation and local processing ---------------------------------------------
@app.command()
def simulate(
    out: Annotated[Path, typer.Argument(help="Output run file (.h5); truth is written beside it")],
    length_km: Annotated[float, typer.Option(help="Length of the simulated line, km")] = 5.0,
    fs: Annotated[float, typer.Option(help="Sample rate, Hz")] = 10_000.0,
    seed: Annotated[int, typer.Option(help="Random seed")] = 0,
    forces: Annotated[bool, typer.Option(help="Also simulate Q (force) channels")] = True,
    reference: Annotated[bool, typer.Option(
        help="Also write matching subsidence, maintenance and superstructure CSV files "
        "(OUT stem + '-reference/')")] = False,
    recorder: Annotated[str | None, typer.Option(
        help="Write OUT as a recorder file (mdf4 or tdms) with drifting odometry, plus its channel "
        "map and metadata JSON beside it")] = None,
    gnss: Annotated[bool, typer.Option(
        help="With --recorder: a GNSS group (3 m noise, 30 s outages) and the line geometry "
        "(OUT stem + '.line.geojson')")] = False,
) -> None:
    """Write a synthetic run in the canonical format with its ground truth beside it."""
    from app.simulate.run import simulate_run

    out.parent.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    if recorder is not None:
        from app.simulate.recorder import GnssSimulation, simulate_recorder_run

        if recorder not in ("mdf4", "tdms"):
            raise typer.BadParameter("mdf4 or tdms", param_hint="--recorder")
        rec = simulate_recorder_run(out, recorder, gnss=GnssSimulation() if gnss else None, seed=seed,
                                    length_km=length_km, fs=fs, with_forces=forces)
        _echo(f"wrote {out} in {time.perf_counter() - t0:.1f} s; channel map {rec.channel_map_path}, "
              f"metadata {rec.metadata_path}" + (f", geometry {rec.geometry_path}" if gnss else ""))
        return
    truth = simulate_run(out, length_km=length_km, fs=fs, seed=seed, with_forces=forces)
    _echo(f"wrote {out} ({out.stat().st_size / 1e6:.1f} MB) in {time.perf_counter() - t0:.1f} s")
    truth_path = getattr(truth, "path", None)
    if truth_path:
        _echo(f"ground truth: {truth_path}")
    if reference:
        from app.simulate.reference import simulate_reference

        meta_line = "SIM"  # simulate_run's default line_id and track
        ref = simulate_reference(truth.line, out.with_name(f"{out.stem}-reference"), line_id=meta_line,
                                 track="1", seed=seed)
        _echo("reference data: " + ", ".join(ref.files[k] for k in ("subsidence", "maintenance", "superstructure")))


def _file_sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        while block := fh.read(1 << 20):
            digest.update(block)
    return digest.hexdigest()


def _wheel_tables(wheels: list[dict[str, Any]]):
    import pandas as pd

    order_rows, profile_rows = [], []
    for w in wheels:
        for o in w.get("orders", []):
            order_rows.append(
                {"wheel": str(w["wheel"]), "wheel_diameter_m": w.get("wheel_diameter_m"), **o}
            )
        angles = w.get("angles_deg") or []
        for i, angle in enumerate(angles):
            profile_rows.append(
                {
                    "wheel": str(w["wheel"]),
                    "angle_deg": angle,
                    "profile_um": (w.get("profile_um") or [None] * len(angles))[i],
                    "profile_p05_um": (w.get("profile_p05_um") or [None] * len(angles))[i],
                    "profile_p95_um": (w.get("profile_p95_um") or [None] * len(angles))[i],
                }
            )
    return pd.DataFrame(order_rows), pd.DataFrame(profile_rows)


def _jsonable(value: Any) -> Any:
    from app.core.jsonable import jsonable

    return jsonable(value)


@app.command()
def process(
    run_file: Annotated[Path, typer.Argument(help="Run file: HDF5, CSV, Parquet, MDF4 or TDMS")],
    out: Annotated[Path, typer.Option("--out", "-o", help="Output directory")] = Path("trackvkf-out"),
    format: Annotated[
        str | None, typer.Option("--format", help="hdf5, csv, parquet, mdf4 or tdms (default: detect)")
    ] = None,
    metadata: Annotated[
        Path | None, typer.Option(help="Metadata JSON file (required for CSV/Parquet)")
    ] = None,
    n_wheel_orders: Annotated[int | None, typer.Option(help="Wheel orders (default 11)")] = None,
    bandwidth_orders: Annotated[
        float | None, typer.Option(help="Bandwidth in wheel orders (default 0.1)")
    ] = None,
    filter_order: Annotated[int | None, typer.Option(help="VKF filter order q (default 2)")] = None,
    channel_map: Annotated[
        Path | None, typer.Option(help="Channel map JSON file (MDF4/TDMS recorder files)")
    ] = None,
    geometry: Annotated[
        Path | None, typer.Option(help="Line geometry GeoJSON (runs placed by GNSS)")
    ] = None,
) -> None:
    """Process a run file locally (no server): profiles and wheel OOR to CSV and Parquet.

    Intermediate chunk results are kept in ``OUT/.work`` so an interrupted run
    resumes where it stopped.
    """
    from tqdm import tqdm

    from app.analysis.settings import ProcessingSettings
    from app.io import RunFileError, ingest
    from app.io.geometry import parse_geojson
    from worker.pipeline import run_pipeline

    if not run_file.is_file():
        raise typer.BadParameter(f"{run_file} is not a file", param_hint="RUN_FILE")
    changes = {
        k: v
        for k, v in {
            "n_wheel_orders": n_wheel_orders,
            "bandwidth_orders": bandwidth_orders,
            "filter_order": filter_order,
        }.items()
        if v is not None
    }
    try:
        settings = ProcessingSettings.from_dict(changes)
    except ValueError as exc:
        raise typer.BadParameter(str(exc)) from None
    md = None
    if metadata is not None:
        try:
            md = json.loads(metadata.read_text(encoding="utf-8"))
        except (OSError, json.JSONDecodeError) as exc:
            raise typer.BadParameter(f"cannot read {metadata}: {exc}", param_hint="--metadata") from None

    extras = {}
    for name, path in (("channel_map", channel_map), ("geometry", geometry)):
        if path is not None:
            try:
                extras[name] = json.loads(path.read_text(encoding="utf-8"))
            except (OSError, json.JSONDecodeError) as exc:
                raise typer.BadParameter(f"cannot read {path}: {exc}", param_hint=f"--{name.replace('_', '-')}") from None
    source_sha = _file_sha256(run_file)
    key = hashlib.sha256(
        json.dumps({"sha": source_sha, "md": md, "settings": settings.to_dict(), **extras},
                   sort_keys=True).encode()
    ).hexdigest()[:16]
    work = out / ".work" / key
    work.mkdir(parents=True, exist_ok=True)
    canonical = work / "run.h5"
    if not canonical.is_file():
        _echo(f"validating {run_file} ...")
        try:
            lines = parse_geojson(extras["geometry"]) if "geometry" in extras else []
            summary = ingest(run_file, format, md, canonical, channel_map=extras.get("channel_map"),
                             geometry=lambda line, track: next(
                                 (g for g in lines if (g.line_id, g.track) == (line, track)), None))
        except RunFileError as exc:
            typer.echo(f"error: {exc}", err=True)
            raise typer.Exit(2) from None
        for warning in summary.warnings:
            typer.echo(f"warning: {warning}", err=True)
        _echo(
            f"{summary.duration_s:.1f} s at {summary.fs:g} Hz, {summary.distance_m / 1000:.2f} km, "
            f"channels {', '.join(summary.channels)}"
        )
    with tqdm(total=100, unit="%", desc="processing", bar_format="{l_bar}{bar}| {elapsed}") as bar:

        def progress(fraction: float) -> None:
            bar.update(max(0.0, 100 * fraction - bar.n))

        results = run_pipeline(canonical, settings, work / "chunks", progress=progress)
        progress(1.0)

    out.mkdir(parents=True, exist_ok=True)
    results.profiles.to_csv(out / "profiles.csv", index=False)
    results.profiles.to_parquet(out / "profiles.parquet", index=False)
    orders, wheel_profiles = _wheel_tables(results.wheels)
    orders.to_csv(out / "wheel_orders.csv", index=False)
    orders.to_parquet(out / "wheel_orders.parquet", index=False)
    wheel_profiles.to_csv(out / "wheel_profiles.csv", index=False)
    wheel_profiles.to_parquet(out / "wheel_profiles.parquet", index=False)
    (out / "wheels.json").write_text(json.dumps(_jsonable(results.wheels), indent=1))
    meta = {
        **dict(results.meta or {}),
        "source_file": str(run_file),
        "source_sha256": source_sha,
        "settings": settings.to_dict(),
    }
    (out / "meta.json").write_text(json.dumps(_jsonable(meta), indent=1))
    _echo(
        f"{len(results.profiles)} profile rows, {len(results.wheels)} wheels -> {out}/ "
        "(profiles.csv/.parquet, wheel_orders.csv/.parquet, wheel_profiles.csv/.parquet, "
        "wheels.json, meta.json)"
    )


# --- users and API keys ---------------------------------------------------------------
user_app = typer.Typer(no_args_is_help=True, help="Browser users (stored with Argon2id password hashes).")
key_app = typer.Typer(no_args_is_help=True, help="API keys of data systems (stored hashed, shown once).")
app.add_typer(user_app, name="user")
app.add_typer(key_app, name="key")

_CLI_ACTOR = "cli"


def _database():
    from app.db.session import Database

    return Database(get_settings().database_url)


def _cli_audit(session, action: str, target: str, detail: dict | None = None) -> None:
    from app.db import auth_crud

    auth_crud.audit(
        session, actor=f"{_CLI_ACTOR}:{os.environ.get('USER', 'unknown')}", actor_kind="cli",
        action=action, target=target, detail=detail,
    )


def _new_password() -> str:
    import secrets

    return secrets.token_urlsafe(12)


@user_app.command("create")
def user_create(
    username: Annotated[str, typer.Argument(help="Login name")],
    role: Annotated[str, typer.Option(help="viewer, engineer or admin")] = "viewer",
    password: Annotated[
        str | None,
        typer.Option(help="Password (>= 10 characters); prompted when omitted, "
                     "or generated and printed with --generate"),
    ] = None,
    generate: Annotated[bool, typer.Option(help="Generate a password and print it")] = False,
) -> None:
    """Create a browser user with a role."""
    from app.db import auth_crud

    if password is None:
        password = _new_password() if generate else typer.prompt(
            "password", hide_input=True, confirmation_prompt=True
        )
    db = _database()
    try:
        with db.write() as session:
            auth_crud.create_user(session, username, password, role, created_by=_CLI_ACTOR)
            _cli_audit(session, "user.create", username, {"role": role})
    except auth_crud.AuthError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2) from None
    finally:
        db.dispose()
    _echo(f"user {username} ({role}) created")
    if generate:
        _echo(f"password: {password}")


@user_app.command("set-password")
def user_set_password(
    username: Annotated[str, typer.Argument(help="Login name")],
    password: Annotated[str | None, typer.Option(help="New password; prompted when omitted")] = None,
    generate: Annotated[bool, typer.Option(help="Generate a password and print it")] = False,
) -> None:
    """Set a user's password (ends its sessions; clears the demo-credentials mark)."""
    from app.db import auth_crud

    if password is None:
        password = _new_password() if generate else typer.prompt(
            "new password", hide_input=True, confirmation_prompt=True
        )
    db = _database()
    try:
        with db.write() as session:
            if auth_crud.update_user(session, username, password=password) is None:
                typer.echo(f"error: no user {username!r}", err=True)
                raise typer.Exit(2)
            _cli_audit(session, "user.update", username, {"password": "changed"})
    except auth_crud.AuthError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2) from None
    finally:
        db.dispose()
    _echo(f"password of {username} changed")
    if generate:
        _echo(f"password: {password}")


@user_app.command("list")
def user_list() -> None:
    """List users: name, role, active, last login."""
    from app.db import auth_crud

    db = _database()
    try:
        with db.read() as session:
            for u in auth_crud.list_users(session):
                flags = ("" if u.active else " inactive") + (" demo-credentials" if u.demo_credentials else "")
                _echo(f"{u.username}\t{u.role}\tlast login {u.last_login_at or '-'}{flags}")
    finally:
        db.dispose()


@key_app.command("create")
def key_create(
    name: Annotated[str, typer.Argument(help="What the key is for (e.g. the data system)")],
    role: Annotated[str, typer.Option(help="viewer, engineer or admin")] = "engineer",
    expires_in_days: Annotated[int | None, typer.Option(help="Lifetime in days (default: none)")] = None,
) -> None:
    """Create an API key and print it once (only its hash is stored)."""
    import datetime as dt

    from app.db import auth_crud
    from app.db.models import utcnow

    expires = utcnow() + dt.timedelta(days=expires_in_days) if expires_in_days else None
    db = _database()
    try:
        with db.write() as session:
            row, key = auth_crud.create_api_key(
                session, name, role, created_by=_CLI_ACTOR, expires_at=expires
            )
            _cli_audit(session, "key.create", str(row.id), {"name": name, "role": role, "prefix": row.prefix})
            key_id = row.id
    except auth_crud.AuthError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2) from None
    finally:
        db.dispose()
    typer.echo(f"API key {key_id} ({name}, {role}); shown once, keep it safe:", err=True)
    _echo(key)


@key_app.command("revoke")
def key_revoke(key_id: Annotated[int, typer.Argument(help="Key id (see `trackvkf key list`)")]) -> None:
    """Revoke an API key."""
    from app.db import auth_crud

    db = _database()
    try:
        with db.write() as session:
            row = auth_crud.revoke_api_key(session, key_id)
            if row is None:
                typer.echo(f"error: no API key {key_id}", err=True)
                raise typer.Exit(2)
            _cli_audit(session, "key.revoke", str(key_id), {"name": row.name})
    finally:
        db.dispose()
    _echo(f"API key {key_id} revoked")


@key_app.command("list")
def key_list() -> None:
    """List API keys: id, prefix, name, role, last use, revocation."""
    from app.db import auth_crud

    db = _database()
    try:
        with db.read() as session:
            for k in auth_crud.list_api_keys(session):
                state = f"revoked {k.revoked_at}" if k.revoked_at else "active"
                _echo(f"{k.id}\ttvk_{k.prefix}_…\t{k.name}\t{k.role}\tlast used {k.last_used_at or '-'}\t{state}")
    finally:
        db.dispose()


def _demo_credentials(settings) -> tuple[str | None, str, int]:
    """Create the demo admin on first start; a short-lived upload key every start.

    Returns the admin password when it was created now (else None) and the key.
    """
    import datetime as dt

    from app.db import auth_crud
    from app.db.models import utcnow

    db = _database()
    password = None
    try:
        with db.write() as session:
            if auth_crud.count_users(session) == 0:
                password = _new_password()
                auth_crud.create_user(
                    session, "admin", password, "admin", created_by="demo", demo_credentials=True
                )
                _cli_audit(session, "user.create", "admin", {"role": "admin", "by": "demo"})
            row, key = auth_crud.create_api_key(
                session, "demo-upload", "engineer", created_by="demo",
                expires_at=utcnow() + dt.timedelta(hours=1),
            )
            _cli_audit(session, "key.create", str(row.id), {"name": row.name, "role": row.role, "by": "demo"})
            key_id = row.id
    finally:
        db.dispose()
    return password, key, key_id


def _revoke_demo_key(key_id: int) -> None:
    from app.db import auth_crud

    db = _database()
    try:
        with db.write() as session:
            auth_crud.revoke_api_key(session, key_id)
            _cli_audit(session, "key.revoke", str(key_id), {"name": "demo-upload", "by": "demo"})
    finally:
        db.dispose()


# --- demo ---------------------------------------------------------------------------
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


@app.command()
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
    _echo(f"database ready: {settings.database_url}")
    admin_password, upload_key, upload_key_id = _demo_credentials(settings)

    demo_dir = Path(settings.run_store).resolve().parent / "demo"
    run_file = demo_dir / f"demo-run-{length_km:g}km-{fs:g}Hz.h5"
    if not run_file.is_file():
        _echo(f"simulating a {length_km:g} km demo run at {fs:g} Hz ...")
        from app.simulate.run import simulate_run

        demo_dir.mkdir(parents=True, exist_ok=True)
        simulate_run(run_file, length_km=length_km, fs=fs, seed=7, with_forces=True)
    _echo(f"demo run: {run_file}")

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
        _echo(f"API up at {base}; uploading the demo run ...")
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
            _echo(f"run {run_id} {'created' if resp.status_code == 201 else 'already uploaded'}")
            job = run["latest_job"]
            last: tuple = ()
            while job["status"] in ("queued", "running"):
                state = (job["status"], job["chunks_done"], job["n_chunks"])
                if state != last:
                    chunks = f", {job['chunks_done']}/{job['n_chunks']} chunks" if job["n_chunks"] else ""
                    _echo(f"  job {job['id']} {job['status']}{chunks}")
                    last = state
                time.sleep(1.0)
                for p in procs:
                    if p.poll() is not None:
                        raise RuntimeError(f"process {p.args} exited with {p.returncode}")
                job = client.get(f"{base}/api/v1/jobs/{job['id']}").json()
            _echo(f"  job {job['id']} {job['status']}" + (f": {job['error']}" if job["error"] else ""))
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
        _echo(f"\n{login}  login page               {base}/login")
        _echo(
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
        _echo("Serving until Ctrl-C ...")
        while all(p.poll() is None for p in procs):
            time.sleep(0.5)
        raise RuntimeError("a service process exited unexpectedly")
    except KeyboardInterrupt:
        _echo("\nstopping ...")
    except RuntimeError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(1) from None
    finally:
        _stop(procs)


def main() -> None:
    """Entry point of the ``trackvkf`` console script."""
    app()

