"""Failed logins against audited writes on SQLite (issue 18, item 3).

A real ``trackvkf serve`` on SQLite; four loops post wrong passwords as fast as they can
(the per-address limits lifted), while an admin creates API keys one after another (an audited
write: the key row and its audit entry in one transaction). Before the fix a failed login held
SQLite's write lock while Argon2 verified the password: the write lock was busy 98 % of the
time and an audited write took 20 s instead of 0.14 s. Prints the audited writes' durations
with and without the login loops.

    python bench/bench_login_contention.py [--seconds 20] [--loops 4]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench_display_load import _env, _free_port, _serve, _stop  # noqa: E402

ADMIN, PASSWORD = "bench-admin", "bench password 1"


def _writes(base_url: str, key: str, seconds: float) -> list[float]:
    import httpx

    out: list[float] = []
    deadline = time.perf_counter() + seconds
    with httpx.Client(base_url=base_url, headers={"Authorization": f"Bearer {key}"}, timeout=120) as client:
        i = 0
        while time.perf_counter() < deadline:
            t = time.perf_counter()
            r = client.post("/api/v1/auth/keys", json={"name": f"k{i}-{t}", "role": "viewer"})
            r.raise_for_status()
            out.append(time.perf_counter() - t)
            i += 1
            time.sleep(0.2)
    return out


def _fail_logins(base_url: str, stop: threading.Event, count: list[int]) -> None:
    import httpx

    with httpx.Client(base_url=base_url, timeout=120) as client:
        while not stop.is_set():
            r = client.post("/api/v1/auth/login", json={"username": ADMIN, "password": "wrong password!"})
            assert r.status_code in (401, 429), r.text
            count.append(r.status_code)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--loops", type=int, default=4)
    args = parser.parse_args(argv)

    from app.db import auth_crud, migrate
    from app.db.session import Database

    tmp = Path(tempfile.mkdtemp(prefix="bench-login-"))
    url = f"sqlite:///{tmp / 'db.sqlite'}"
    migrate.upgrade(url)
    db = Database(url)
    with db.write() as session:
        auth_crud.create_user(session, ADMIN, PASSWORD, "admin")
        _, key = auth_crud.create_api_key(session, "bench-admin-key", "admin", created_by="bench")
    db.dispose()
    env = {**_env(url, tmp / "runs"), "TRACKVKF_LOGIN_NAME_FAILURE_LIMIT": "1000000"}
    port = _free_port()
    base_url = f"http://127.0.0.1:{port}"
    server = _serve(env, port, 1, tmp / "server.log")
    try:
        quiet = _writes(base_url, key, args.seconds / 2)
        stop, count = threading.Event(), []
        loops = [threading.Thread(target=_fail_logins, args=(base_url, stop, count)) for _ in range(args.loops)]
        for t in loops:
            t.start()
        t0 = time.perf_counter()
        busy = _writes(base_url, key, args.seconds)
        rate = len(count) / (time.perf_counter() - t0)
        stop.set()
        for t in loops:
            t.join()
    finally:
        _stop(server)
    print("| audited write (POST /auth/keys) | writes | median s | max s | failed logins/s |")
    print("|---|--:|--:|--:|--:|")
    print(f"| alone | {len(quiet)} | {statistics.median(quiet):.3f} | {max(quiet):.3f} | |")
    print(f"| with {args.loops} failing login loops | {len(busy)} | {statistics.median(busy):.3f} | "
          f"{max(busy):.3f} | {rate:.1f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
