"""Issue 32 finding 1: an asset import held the write lock for a minute (one transaction, one DELETE
per line and track), and a status change sent meanwhile got 500 "database is locked".

Now an import writes in short batches, invisible until one short transaction makes it live (all
its lines at once), then deletes the replaced rows in batches; a reader between two batches sees
the old assets whole, never a mix; an import cut short leaves the old assets live and its rows
are swept by the next; what one import may touch is capped (413); and a write that cannot get
the lock within ``TRACKVKF_DB_LOCK_WAIT_S`` is a 503 with ``Retry-After``, never a 500. SQLite
and PostgreSQL where the queries differ.
"""

from __future__ import annotations

import sqlite3

import pytest
from sqlalchemy import func, select

from app.assets import service
from app.core.security import Actor
from app.db.models import Asset, AssetImport
from app.db.session import Database

ACTOR = Actor.command_line("tests")


def _csv(rows: list[tuple]) -> bytes:
    return ("line_id,track,type,km,km_to\n" + "".join(
        f"{ln},{'' if tr is None else tr},{ty},{km},{'' if to is None else to}\n" for ln, tr, ty, km, to in rows)).encode()


def _seen(db: Database) -> list[tuple]:
    items, total = service.find_assets(db, limit=10_000)
    assert total == len(items)
    return sorted((a["line_id"], a["track"] or "", a["type"], a["km"]) for a in items)


@pytest.fixture(params=["sqlite", "postgresql"])
def database(request, make_client):
    overrides = {"parse_isolated": False, "assets_import_batch_rows": 100}
    if request.param == "postgresql":
        cluster = request.getfixturevalue("pg_cluster")
        if isinstance(cluster, str):
            pytest.skip(cluster)
        overrides["database_url"] = cluster.create_database()
    client = make_client(**overrides)
    db = Database(client.settings.database_url)
    yield client.settings, db
    db.dispose()


OLD = [("L1", "1", "switch", 1.0 + i / 100, None) for i in range(150)] + [("L1", None, "bridge", 5.0, 5.2),
                                                                         ("L2", "1", "weld", 3.0, None)]
NEW = [("L1", "1", "weld", 2.0 + i / 1000, None) for i in range(330)] + [("L3", "2", "level_crossing", 7.0, None)]


def test_an_import_is_written_in_batches_and_goes_live_at_once(database):
    settings, db = database
    service.import_assets(db, settings, ACTOR, _csv(OLD), "old.csv", sleep=lambda s: None)
    old = _seen(db)
    assert len(old) == 152
    pauses = []

    def between_batches(seconds: float) -> None:  # another request, while the import runs
        pauses.append(seconds)
        if len(pauses) <= 4:  # the four batches of the 331 new rows: invisible
            assert _seen(db) == old

    got = service.import_assets(db, settings, ACTOR, _csv(NEW), "new.csv", sleep=between_batches)
    assert got == {"imported": 331, "replaced": 150, "lines": 2}  # L1 track 1 replaced; L1 (no track), L2 kept
    assert len(pauses) >= 4 and all(p >= 0.1 for p in pauses[:4]) == settings.is_sqlite
    new = _seen(db)
    assert len(new) == 331 + 2 and ("L1", "1", "switch", 1.0) not in new and ("L1", "", "bridge", 5.0) in new
    with db.read() as s:  # the replaced rows are gone, not only hidden
        assert s.scalar(select(func.count()).select_from(Asset)) == len(new)


def test_an_import_cut_short_leaves_the_old_assets_and_is_swept_by_the_next(database):
    settings, db = database
    service.import_assets(db, settings, ACTOR, _csv(OLD), "old.csv", sleep=lambda s: None)
    old = _seen(db)

    def killed(seconds: float) -> None:
        raise KeyboardInterrupt  # the importer dies after its first batch

    with pytest.raises(KeyboardInterrupt):
        service.import_assets(db, settings, ACTOR, _csv(NEW), "new.csv", sleep=killed)
    assert _seen(db) == old
    with db.read() as s:
        assert s.scalar(select(AssetImport.state).order_by(AssetImport.id.desc()).limit(1)) == "abandoned"
        assert s.scalar(select(func.count()).select_from(Asset)) == len(old)  # its batch swept already
    assert service.import_assets(db, settings, ACTOR, _csv(NEW[:5]), "again.csv",
                                 sleep=lambda s: None)["replaced"] == 150
    with db.read() as s:
        assert s.scalar(select(func.count()).select_from(Asset)) == 5 + 2


def test_what_one_import_may_touch_is_capped(make_client):
    client = make_client(parse_isolated=False, assets_import_max_lines=2, assets_import_max_rows=200)
    many_lines = _csv([(f"L{i}", "1", "weld", 1.0, None) for i in range(3)])
    r = client.post("/api/v1/assets", files={"file": ("a.csv", many_lines, "text/csv")})
    assert r.status_code == 413 and r.json()["field"] == "file" and "TRACKVKF_ASSETS_IMPORT_MAX_LINES" in r.text
    many_rows = _csv([("L1", "1", "weld", 1.0 + i / 1000, None) for i in range(201)])
    r = client.post("/api/v1/assets", files={"file": ("a.csv", many_rows, "text/csv")})
    assert r.status_code == 413 and "TRACKVKF_ASSETS_IMPORT_MAX_ROWS" in r.text
    assert client.get("/api/v1/assets").json()["total"] == 0


def test_a_write_waiting_past_the_lock_deadline_is_a_503_not_a_500(make_client):
    client = make_client(db_lock_wait_s=0.3)
    path = client.settings.database_url.removeprefix("sqlite:///")
    blocker = sqlite3.connect(path, isolation_level=None)
    try:
        blocker.execute("BEGIN IMMEDIATE")  # another writer holding the lock
        r = client.post("/api/v1/auth/users", json={"username": "erika", "password": "a-long-password-1",
                                                    "role": "viewer"})
        assert r.status_code == 503, r.text
        assert r.json()["field"] == "database" and int(r.headers["Retry-After"]) >= 1
    finally:
        blocker.execute("ROLLBACK")
        blocker.close()
    r = client.post("/api/v1/auth/users", json={"username": "erika", "password": "a-long-password-1", "role": "viewer"})
    assert r.status_code == 201, r.text  # the 503 changed nothing: the retry creates the user
