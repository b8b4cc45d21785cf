"""Database layer: models, sessions, migrations and the shared queries."""

from app.db.session import Database, make_engine

__all__ = ["Database", "make_engine"]
