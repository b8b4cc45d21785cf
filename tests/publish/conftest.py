"""The publish step's tests use the db layer's database fixture."""

from tests.db.conftest import db  # noqa: F401 - the fixture
