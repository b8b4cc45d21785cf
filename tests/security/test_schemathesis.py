"""Property-based API test (Schemathesis) against the app's own OpenAPI schema,
authenticated as admin: no input gives a 5xx and every answer conforms to the schema.

Bounded for CI: ``MAX_EXAMPLES`` generated cases per operation and no
shrinking phase; the module runs in well under two minutes on two cores. One
test per operation, so routes added to the API later are fuzzed too.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import schemathesis
from hypothesis import HealthCheck, Phase, given, settings
from schemathesis.checks import not_a_server_error
from schemathesis.specs.openapi.checks import response_schema_conformance

from app.main import create_app
from tests.api.support import auth_headers, create_api_key, make_settings, migrate_database

MAX_EXAMPLES = 12
CHECKS = [not_a_server_error, response_schema_conformance]


@pytest.fixture(scope="module")
def fuzz_target(tmp_path_factory):
    """The app on a migrated database, an admin key, and the loaded schema."""
    tmp: Path = tmp_path_factory.mktemp("schemathesis")
    app_settings = make_settings(
        tmp, upload_rate_limit=100_000, login_rate_limit=100_000, max_upload_bytes=1 << 20
    )
    migrate_database(app_settings.database_url)
    key = create_api_key(app_settings.database_url, "admin", "schemathesis")
    app = create_app(app_settings)
    schema = schemathesis.openapi.from_asgi("/openapi.json", app, headers=auth_headers(key))
    operations = {f"{op.method.upper()} {op.path}": op for op in (r.ok() for r in schema.get_all_operations())}
    return app, key, operations


def _operation_ids() -> list[str]:
    """Operations of the schema, for parametrisation (app built without a database)."""
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        app = create_app(make_settings(Path(tmp)))
        paths = app.openapi()["paths"]
        app.state.db.dispose()
    methods = ("get", "post", "put", "patch", "delete")
    return sorted(f"{m.upper()} {p}" for p, ops in paths.items() for m in ops if m in methods)


@pytest.mark.parametrize("operation_id", _operation_ids())
def test_operation_conforms_and_never_fails(fuzz_target, operation_id):
    _, key, operations = fuzz_target
    operation = operations[operation_id]

    @given(case=operation.as_strategy())
    @settings(
        max_examples=MAX_EXAMPLES,
        deadline=None,
        phases=[Phase.explicit, Phase.generate],
        suppress_health_check=list(HealthCheck),
        database=None,
    )
    def run(case):
        case.call_and_validate(headers=auth_headers(key), checks=CHECKS)

    run()
