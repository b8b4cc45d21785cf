"""Security primitives, the rate limiter, production-mode refusal, and the ingest limits."""

from __future__ import annotations

import gzip

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from app.core import security
from app.core.config import DEFAULT_SECRET_KEY, ProductionConfigError
from app.core.ratelimit import RateLimiter
from app.db import auth_crud
from app.db.session import Database
from app.io import RunFileError, ingest
from app.io.limits import IngestLimits
from app.settings import Settings
from tests.api import runfiles
from tests.api.support import make_settings, migrate_database

STRONG_KEY = "k" * 48
#: OWASP's minimum Argon2id cost that takes least time (19 MiB, 2 passes): what production accepts
OWASP_COST = {"password_hash_time_cost": 2, "password_hash_memory_kib": 19456, "password_hash_parallelism": 1}


def test_password_hash_is_argon2id_salted_and_verifies():
    """At the default (real) cost: argon2-cffi's defaults, 3 passes over 64 MiB with 4 lanes."""
    h1, h2 = security.hash_password("correct horse"), security.hash_password("correct horse")
    assert h1.startswith("$argon2id$v=19$m=65536,t=3,p=4$") and h1 != h2
    assert security.verify_password(h1, "correct horse")
    assert not security.verify_password(h1, "correct horsE")
    assert not security.verify_password("not a hash", "correct horse")
    with pytest.raises(ValueError, match="at least"):
        security.hash_password("short")


def test_the_password_cost_setting_makes_the_hashes(monkeypatch):
    monkeypatch.setenv("TRACKVKF_PASSWORD_HASH_TIME_COST", "2")
    monkeypatch.setenv("TRACKVKF_PASSWORD_HASH_MEMORY_KIB", "19456")
    monkeypatch.setenv("TRACKVKF_PASSWORD_HASH_PARALLELISM", "1")
    cost = Settings(_env_file=None).password_cost
    assert cost == security.PasswordCost(time_cost=2, memory_kib=19456, parallelism=1)
    h = security.hash_password("correct horse", cost)
    assert h.startswith("$argon2id$v=19$m=19456,t=2,p=1$")
    assert security.verify_password(h, "correct horse") and not security.verify_password(h, "correct horsE")
    # a hash of another cost is verified with its own parameters, and asks to be made again
    assert security.password_needs_rehash(h) and not security.password_needs_rehash(h, cost)
    with pytest.raises(ValueError, match="8 KiB of memory per lane"):
        Settings(_env_file=None, password_hash_memory_kib=16, password_hash_parallelism=4)


def test_production_refuses_a_password_cost_below_owasps_minimum(tmp_path):
    from app.main import create_app

    with pytest.raises(ProductionConfigError, match="TRACKVKF_PASSWORD_HASH_TIME_COST"):
        create_app(make_settings(tmp_path, env="production", secret_key=STRONG_KEY))  # the tests' cost
    for memory_kib, passes in security.OWASP_ARGON2ID_MINIMUMS:
        at = make_settings(tmp_path, env="production", secret_key=STRONG_KEY, password_hash_memory_kib=memory_kib,
                           password_hash_time_cost=passes, password_hash_parallelism=1)
        at.check_production()
        for below in ({"password_hash_memory_kib": memory_kib - 1}, {"password_hash_time_cost": passes - 1}):
            if below.get("password_hash_time_cost") == 0:
                continue  # one pass is Argon2's least: 46 MiB with 1 pass has no fewer passes
            settings = at.model_copy(update=below)
            with pytest.raises(ProductionConfigError, match="OWASP"):
                settings.check_production()
    make_settings(tmp_path, env="production", secret_key=STRONG_KEY,
                  password_hash_memory_kib=65536, password_hash_time_cost=3, password_hash_parallelism=4).check_production()


def test_api_key_format_and_digest():
    k = security.new_api_key()
    assert k.key.startswith(f"tvk_{k.prefix}_") and len(k.prefix) == 8
    assert security.api_key_prefix(k.key) == k.prefix
    assert k.digest == security.token_digest(k.key) and k.key not in k.digest
    assert security.api_key_prefix("tvk_short_x") is None
    assert security.new_api_key().key != k.key


def test_csrf_token_is_bound_to_the_session_and_the_secret():
    token = security.new_session_token()
    csrf = security.csrf_token("secret-a", token)
    assert security.csrf_matches("secret-a", token, csrf)
    assert not security.csrf_matches("secret-b", token, csrf)
    assert not security.csrf_matches("secret-a", security.new_session_token(), csrf)
    assert not security.csrf_matches("secret-a", token, None)


def test_role_order():
    assert security.role_allows("admin", "engineer") and security.role_allows("engineer", "engineer")
    assert not security.role_allows("viewer", "engineer")
    with pytest.raises(ValueError, match="role"):
        security.role_rank("root")


def test_rate_limiter_sliding_window_and_bounded_keys():
    now = [0.0]
    limiter = RateLimiter(3, 10.0, max_keys=2, clock=lambda: now[0])
    assert [limiter.hit("a") for _ in range(3)] == [None, None, None]
    assert limiter.hit("a") == pytest.approx(10.0)
    now[0] = 5.0
    assert limiter.hit("a") == pytest.approx(5.0)  # refused hits are not counted
    assert limiter.hit("b") is None
    now[0] = 10.5
    assert limiter.hit("a") is None  # the first hits left the window
    limiter.hit("c")  # a third key evicts the least recently used ("b")
    assert set(limiter._hits) == {"a", "c"}
    with pytest.raises(ValueError, match="limit"):
        RateLimiter(0, 1.0)


def test_production_refuses_default_secret_and_disabled_auth(tmp_path):
    from app.main import create_app

    with pytest.raises(ProductionConfigError, match="TRACKVKF_SECRET_KEY"):
        create_app(make_settings(tmp_path, env="production"))
    with pytest.raises(ProductionConfigError, match="TRACKVKF_SECRET_KEY"):
        create_app(make_settings(tmp_path, env="production", secret_key="short"))
    with pytest.raises(ProductionConfigError, match="AUTH_DISABLED"):
        create_app(make_settings(tmp_path, env="production", secret_key=STRONG_KEY, auth_disabled=True))
    assert make_settings(tmp_path).secret_key == DEFAULT_SECRET_KEY  # development default


def test_production_refuses_printed_demo_credentials(tmp_path):
    from app.main import create_app

    settings = make_settings(tmp_path, env="production", secret_key=STRONG_KEY, **OWASP_COST)
    migrate_database(settings.database_url)
    db = Database(settings.database_url)
    with db.write() as s:
        auth_crud.create_user(s, "admin", "printed-password", "admin", demo_credentials=True,
                              password_cost=settings.password_cost)
    with pytest.raises(ProductionConfigError, match="default credentials.*'admin'"):
        create_app(settings)
    with db.write() as s:
        auth_crud.update_user(s, "admin", password="a new secret password", password_cost=settings.password_cost)
    db.dispose()
    app = create_app(settings)
    app.state.db.dispose()


def test_auth_disabled_runs_as_the_anonymous_principal(make_client):
    client = make_client(auth_disabled=True, anonymous_role="viewer")
    client.headers.pop("Authorization")
    assert client.get("/api/v1/auth/me").json() == {"name": "local", "role": "viewer", "kind": "anonymous",
                                                     "language": None, "answered_in": "en"}
    assert client.delete("/api/v1/runs/1").status_code == 403


# --- ingest limits (app.io) ---------------------------------------------------------------
def test_hdf5_with_too_many_root_members(tmp_path):
    import h5py

    path = tmp_path / "many.h5"
    with h5py.File(path, "w") as h5:
        for i in range(70):
            h5[f"x{i}"] = np.zeros(3)
    with pytest.raises(RunFileError, match="70 root members exceed the limit of 64"):
        ingest(path, None, runfiles.metadata(), tmp_path / "out.h5")
    assert not (tmp_path / "out.h5").exists()


def test_parquet_decode_limit_and_column_limit(tmp_path):
    n = 3_000_000
    path = tmp_path / "zeros.parquet"
    pq.write_table(pa.table({"Z11": np.zeros(n), "speed": np.zeros(n)}), path, compression="zstd")
    small = IngestLimits(max_expansion_ratio=1.0, expansion_floor_bytes=1024)
    with pytest.raises(RunFileError, match="decompression bomb"):
        ingest(path, None, runfiles.metadata(), tmp_path / "out.h5", small)
    wide = tmp_path / "wide.parquet"
    pq.write_table(pa.table({f"c{i}": [0.0] for i in range(100)}), wide)
    with pytest.raises(RunFileError, match="100 columns exceed the limit of 64"):
        ingest(wide, None, runfiles.metadata(), tmp_path / "out.h5")


def test_parquet_footer_length_is_checked_before_parsing(tmp_path):
    path = tmp_path / "lying.parquet"
    pq.write_table(pa.table(runfiles.channels(n=1000)), path)
    data = bytearray(path.read_bytes())
    data[-8:-4] = (2**31 - 1).to_bytes(4, "little")
    path.write_bytes(bytes(data))
    with pytest.raises(RunFileError, match="does not fit the file"):
        ingest(path, "parquet", runfiles.metadata(), tmp_path / "out.h5")


def test_gzip_csv_within_the_limit_is_accepted(tmp_path):
    path = tmp_path / "run.csv.gz"
    text = runfiles.write_csv(tmp_path / "run.csv").read_bytes()
    path.write_bytes(gzip.compress(text))
    summary = ingest(path, None, runfiles.metadata(), tmp_path / "out.h5")
    assert summary.n_samples == runfiles.N
    tight = IngestLimits(max_expansion_ratio=1.0, expansion_floor_bytes=1024)
    with pytest.raises(RunFileError, match="decompression bomb"):
        ingest(path, None, runfiles.metadata(), tmp_path / "out2.h5", tight)


def test_limits_are_validated():
    with pytest.raises(ValueError, match="max_columns"):
        IngestLimits(max_columns=0)
    with pytest.raises(ValueError, match="max_expansion_ratio"):
        IngestLimits(max_expansion_ratio=0.5)
