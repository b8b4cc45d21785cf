"""Display decimation of a long profile: GET /runs/{id}/profile with max_points.

A synthetic 100 km run (400 000 bins of 25 cm per wheel, four wheels) is stored in a fresh
SQLite database; the stiffness-map page's requests are timed through the ASGI app:
the whole run (max_points=3000 per wheel) and zooms to 10 km and 1 km.

    python bench/bench_profile_display.py [--km 100]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--km", type=float, default=100.0, help="run length, km")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()

    from display_run import store_display_run
    from fastapi.testclient import TestClient

    from app.db import migrate
    from app.main import create_app
    from app.settings import Settings

    tmp = Path(tempfile.mkdtemp(prefix="bench-profile-"))
    settings = Settings(_env_file=None, database_url=f"sqlite:///{tmp / 'db.sqlite'}",
                        run_store=tmp / "runs", log_level="WARNING")
    migrate.upgrade(settings.database_url)
    t0 = time.perf_counter()
    run_id, api_key, n_rows = store_display_run(settings.database_url, args.km)
    print(f"stored {n_rows} rows in {time.perf_counter() - t0:.1f} s")

    with TestClient(create_app(settings), headers={"Authorization": f"Bearer {api_key}"}) as client:
        cases = [("whole run", None, None, {}), ("10 km", 40.0, 50.0, {}), ("1 km", 45.0, 46.0, {}),
                 ("100 m", 45.0, 45.1, {}),
                 ("whole run, the map's columns", None, None, {"columns": "sleeper_amp,speed_mean,sleeper_force_amp"}),
                 ("line view: whole run in 100 m segments, all columns", None, None, {"level": 100, "max_points": None}),
                 ("line view: whole run in 100 m segments, sleeper_amp", None, None,
                  {"level": 100, "max_points": None, "columns": "sleeper_amp"}),
                 ("line view: whole run in 10 m segments, all columns", None, None, {"level": 10}),
                 ("line view: whole run in 10 m segments, sleeper_amp", None, None,
                  {"level": 10, "columns": "sleeper_amp"})]
        print("| view | rows per wheel in range | rows returned per wheel | median s per wheel | bytes per wheel |")
        print("|---|---|---|---|---|")
        for name, a, b, extra in cases:
            times = []
            for _ in range(args.repeat):
                t = time.perf_counter()
                params = {k: v for k, v in {"wheel": "12", "max_points": 3000, **extra}.items() if v is not None}
                if a is not None:
                    params.update(km_from=a, km_to=b)
                r = client.get(f"/api/v1/runs/{run_id}/profile", params=params)
                times.append(time.perf_counter() - t)
            r.raise_for_status()
            body = r.json()
            print(f"| {name} | {int(((b or args.km) - (a or 0.0)) * 4000)} | {body['n_rows']} | {statistics.median(times):.3f} | {len(r.content)} |")


if __name__ == "__main__":
    main()
