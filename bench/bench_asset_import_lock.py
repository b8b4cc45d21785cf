"""How long an audited write waits while a maximal asset import runs (issue 32 finding 1): the real API
(uvicorn, SQLite) importing ``--rows`` assets on ``--lines`` (line, track) pairs over HTTP, replacing an
earlier import of the same size, while a probe changes a user's role (``PATCH /auth/users/{name}``: an
audited write, one row and its audit entry) every ``--every`` seconds and records each answer's latency
and status.

``--root`` runs the API from another checkout (e.g. a ``git worktree`` of main before the change) on a
database migrated by that checkout: the same file, the same probe.

Usage::

    nice .venv/bin/python bench/bench_asset_import_lock.py [--rows 200000] [--lines 1000] [--root PATH]
"""

from __future__ import annotations

import argparse
import os
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import httpx

ROOT = Path(__file__).resolve().parents[1]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _asset_csv(rows: int, lines: int, seed: int) -> bytes:
    out = ["line_id,track,type,km,name"]
    per = rows // lines
    for i in range(rows):
        ln = i // per if i // per < lines else lines - 1
        out.append(f"B{ln:05d},1,{('switch', 'weld', 'insulated_joint')[i % 3]},{(i % per) * 0.01 + seed * 1e-4:.4f},"
                   f"asset {i}")
    return ("\n".join(out) + "\n").encode()


def _run(args: argparse.Namespace, root: Path) -> dict:
    work = Path(tempfile.mkdtemp(prefix="bench-asset-lock-"))
    url = f"sqlite:///{work / 'db.sqlite'}"
    env = {k: v for k, v in os.environ.items() if not k.startswith("TRACKVKF_")}
    env.update(PYTHONPATH=str(root), TRACKVKF_DATABASE_URL=url, TRACKVKF_RUN_STORE=str(work / "runs"),
               TRACKVKF_LOG_LEVEL="WARNING", TRACKVKF_PARSE_ISOLATED="false")
    py = sys.executable
    key = subprocess.run([py, "-c", (
        "from app.db import migrate, auth_crud\nfrom app.db.session import Database\n"
        f"migrate.upgrade({url!r})\ndb = Database({url!r})\n"
        "with db.write() as s:\n    _, key = auth_crud.create_api_key(s, 'bench', 'admin', created_by='bench')\n"
        "print(key)")], env=env, cwd=root, capture_output=True, text=True, check=True).stdout.strip().splitlines()[-1]
    port = _free_port()
    api = subprocess.Popen([py, "-m", "uvicorn", "--factory", "app.main:create_app", "--host", "127.0.0.1",
                            "--port", str(port), "--log-level", "warning"], env=env, cwd=root,
                           stdout=open(work / "api.log", "wb"), stderr=subprocess.STDOUT)
    base = f"http://127.0.0.1:{port}/api/v1"
    headers = {"Authorization": f"Bearer {key}"}
    try:
        for _ in range(300):
            try:
                if httpx.get(f"{base}/health", timeout=1).status_code == 200:
                    break
            except httpx.HTTPError:
                time.sleep(0.2)
        with httpx.Client(base_url=base, headers=headers, timeout=600) as c:
            assert c.post("/auth/users", json={"username": "probe", "password": "probe-password-1",
                                               "role": "viewer"}).status_code == 201
            first = c.post("/assets", files={"file": ("a.csv", _asset_csv(args.rows, args.lines, 0), "text/csv")})
            assert first.status_code == 201, first.text
        lat: list[tuple[float, int]] = []
        stop = threading.Event()

        def probe() -> None:
            roles = ("engineer", "viewer")
            with httpx.Client(base_url=base, headers=headers, timeout=120) as pc:
                i = 0
                while not stop.is_set():
                    t0 = time.perf_counter()
                    r = pc.patch("/auth/users/probe", json={"role": roles[i % 2]})
                    lat.append((time.perf_counter() - t0, r.status_code))
                    i += 1
                    stop.wait(args.every)

        data = _asset_csv(args.rows, args.lines, 1)
        th = threading.Thread(target=probe)
        th.start()
        time.sleep(1.0)
        n_before = len(lat)
        t0 = time.perf_counter()
        with httpx.Client(base_url=base, headers=headers, timeout=1200) as c:
            r = c.post("/assets", files={"file": ("b.csv", data, "text/csv")})
        import_s = time.perf_counter() - t0
        stop.set()
        th.join()  # the probe write in flight when the import answered counts too
        during = lat[n_before:]
        ok = [s for s, code in during if code == 200]
        codes: dict[int, int] = {}
        for _, code in during:
            codes[code] = codes.get(code, 0) + 1
        q = statistics.quantiles(ok, n=100, method="inclusive") if len(ok) >= 2 else [float("nan")] * 99
        return {"root": str(root), "import_status": r.status_code, "import_answer": r.text[:200],
                "import_s": import_s, "probes": len(during), "codes": codes, "p50_s": statistics.median(ok) if ok else None,
                "p99_s": q[98], "max_s": max(ok) if ok else None}
    finally:
        api.terminate()
        api.wait(30)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rows", type=int, default=200_000)
    ap.add_argument("--lines", type=int, default=1000)
    ap.add_argument("--every", type=float, default=0.05, help="pause of the probe between two writes, s")
    ap.add_argument("--root", type=Path, default=ROOT, help="checkout whose API runs (default: this one)")
    args = ap.parse_args()
    res = _run(args, args.root.resolve())
    for k, v in res.items():
        print(f"{k}: {v:.3f}" if isinstance(v, float) else f"{k}: {v}")


if __name__ == "__main__":
    main()
