"""The settings' ground floor: the base of every settings group and the core group.

Every setting can be given as an environment variable (``TRACKVKF_DATABASE_URL``,
``TRACKVKF_RUN_STORE``, ...) or in a ``.env`` file in the working directory. Each service package
declares its own group of settings (``app/places/settings.py``, ``app/analytics/settings.py``, …):
a :class:`SettingsGroup` whose fields carry their full names (``places_gap_m`` is
``TRACKVKF_PLACES_GAP_M``) and whose defaults are the numerics' own constants. The service's
settings, one object for the API, the worker and the CLI, are the composition of the groups
(:class:`app.settings.Settings`, :func:`app.settings.get_settings`): it sits above the services,
this module below them, so a group can name the constants of the numerics it configures.
"""

from __future__ import annotations

from pathlib import Path

from pydantic import Field, field_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

__all__ = ["SettingsGroup", "CoreSettings", "DEFAULT_SECRET_KEY", "ProductionConfigError", "API_PREFIX",
           "ENV_PREFIX", "GIB"]

GIB = 1024**3

#: Prefix of every setting's environment variable.
ENV_PREFIX = "TRACKVKF_"

#: URL prefix of the REST API (routes, links in answers, hints in messages).
API_PREFIX = "/api/v1"

#: The development secret key; production mode refuses to start with it.
DEFAULT_SECRET_KEY = "trackvkf-insecure-development-key-change-me"


class ProductionConfigError(RuntimeError):
    """The settings are not safe for ``TRACKVKF_ENV=production``."""


class SettingsGroup(BaseSettings):
    """The base of a settings group: ``TRACKVKF_<FIELD NAME>`` from the environment or ``.env``.

    A group is a pydantic-settings class of its own (``PlacesSettings()`` reads the
    ``TRACKVKF_PLACES_*`` variables alone) and a base of the service's composed settings. Its
    fields are described in the numpydoc ``Attributes`` section of its docstring, from which the
    configuration reference is generated (:mod:`app.core.config_doc`); the first line of the
    docstring is the group's title there.
    """

    model_config = SettingsConfigDict(
        env_prefix=ENV_PREFIX, env_file=".env", env_file_encoding="utf-8", extra="ignore"
    )

    @classmethod
    def env_names(cls) -> list[str]:
        """The environment variables of the group's settings, in its order."""
        return [f"{ENV_PREFIX}{name.upper()}" for name in cls.model_fields]


class CoreSettings(SettingsGroup):
    """Core: the database, the run store, the environment and secret key, logging, list pages.

    Attributes
    ----------
    database_url : str
        SQLAlchemy URL. ``sqlite:///./var/trackvkf.db`` (default) selects the
        embedded mode; a ``postgresql+psycopg://`` URL the production mode.
    run_store : Path
        Directory of the run store: canonical run files, uploads in progress
        and chunk results live below it.
    shared_store : str, optional
        Production mode on hosts without a common file system: fsspec URL
        (``s3://bucket/prefix`` with s3fs installed, ``file:///mnt/shared/…``)
        shared by the API and worker hosts. The API publishes run files there;
        workers fetch run files from there into their own run store and keep
        chunk results there (:mod:`app.core.sharedstore`). Default: none (the
        run store directory is the only store; share it between hosts by a
        network file system, or run on one host).
    min_free_bytes : int
        Free space the run store keeps in reserve, bytes (default 1 GiB). An
        upload that would leave less is refused with 507 (checked against its
        declared size before it is received, while it is written and before the
        canonical file is written), and ``/health`` reports the store as
        ``low_space`` (status ``degraded``) below it.
    env : str
        ``development`` (default) or ``production``. Production refuses to
        start with the default secret key, with ``auth_disabled`` or while a
        user with printed demo credentials is active.
    secret_key : str
        Server secret (>= 32 characters in production): keys the CSRF tokens.
    log_level : str
        Python logging level name for the service loggers.
    log_format : str
        ``text`` (default) or ``json``: one JSON object per log line (time,
        level, logger, message, pid, exception), uvicorn's logs too.
    max_page_size : int
        Largest page a list endpoint returns.
    db_lock_wait_s : float
        How long a request waits for the database's write lock (SQLite: the busy timeout, its
        retries within this deadline), s; past it the answer is 503 with ``Retry-After``
        (``"field": "database"``), never a 500.
    """

    database_url: str = "sqlite:///./var/trackvkf.db"
    run_store: Path = Path("./var/runs")
    shared_store: str | None = None
    min_free_bytes: int = Field(default=GIB, ge=0)
    env: str = "development"
    secret_key: str = DEFAULT_SECRET_KEY
    log_level: str = "INFO"
    log_format: str = Field(default="text", pattern="^(text|json)$")
    max_page_size: int = Field(default=500, ge=1)
    db_lock_wait_s: float = Field(default=15.0, gt=0, le=600)

    @field_validator("env")
    @classmethod
    def _check_env(cls, value: str) -> str:
        value = value.strip().lower()
        if value not in ("development", "production"):
            raise ValueError(f"env must be development or production, got {value!r}")
        return value

    @property
    def is_production(self) -> bool:
        """Whether ``TRACKVKF_ENV=production``."""
        return self.env == "production"

    @property
    def is_sqlite(self) -> bool:
        """Whether the database URL selects SQLite (embedded mode)."""
        return self.database_url.startswith("sqlite")
