"""Service settings, read from the environment with the ``TRACKVKF_`` prefix.

Every setting can be given as an environment variable (``TRACKVKF_DATABASE_URL``,
``TRACKVKF_RUN_STORE``, ...) or in a ``.env`` file in the working directory.
The API, the worker and the CLI all read the same :class:`Settings`.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path
from typing import Any

from pydantic import Field, field_validator, model_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

__all__ = ["Settings", "get_settings", "DEFAULT_SECRET_KEY", "ProductionConfigError", "API_PREFIX"]

_GIB = 1024**3

#: URL prefix of the REST API (routes, links in answers, hints in messages).
API_PREFIX = "/api/v1"

#: The development secret key; production mode refuses to start with it.
DEFAULT_SECRET_KEY = "trackvkf-insecure-development-key-change-me"


class ProductionConfigError(RuntimeError):
    """The settings are not safe for ``TRACKVKF_ENV=production``."""


class Settings(BaseSettings):
    """Settings of the trackvkf service (API, worker, CLI).

    Attributes
    ----------
    database_url : str
        SQLAlchemy URL. ``sqlite:///./var/trackvkf.db`` (default) selects the
        embedded mode; a ``postgresql+psycopg://`` URL the production mode.
    run_store : Path
        Directory of the run store: canonical run files, uploads in progress
        and chunk results live below it.
    max_upload_bytes : int
        Largest accepted upload body, bytes (default 8 GiB). Larger uploads get 413.
    upload_block_bytes : int
        Size of the blocks an upload is read and written in, bytes.
    max_metadata_bytes : int
        Largest accepted metadata JSON document, bytes.
    upload_ingest_concurrency : int
        Uploads each API process validates and converts at once (the others
        wait their turn, already received): conversion holds the GIL, and
        more at once would starve the process's reads (:mod:`app.operations.heavy`).
    upload_stale_after_s : float
        Age (s) after which an upload directory is swept at start-up on a file
        system without ``flock`` (some network file systems). Elsewhere every
        upload no live API process owns (a process holds a ``flock`` on its
        uploads) is swept at start-up, whatever its age.
    min_free_bytes : int
        Free space the run store keeps in reserve, bytes (default 1 GiB). An
        upload that would leave less is refused with 507 (checked against its
        declared size before it is received, while it is written and before the
        canonical file is written), and ``/health`` reports the store as
        ``low_space`` (status ``degraded``) below it.
    worker_poll_interval_s : float
        Pause of an idle worker between two looks at the queue, s.
    worker_heartbeat_s : float
        Interval at which a busy worker refreshes the heartbeat of its job, s.
    worker_stale_after_s : float
        A running job whose heartbeat is older than this (s) belongs to a dead
        worker and is claimed again.
    health_stuck_after_s : float
        ``/health`` reports a running job as stuck (status ``degraded``) when
        no worker has reported progress on it for this long, s.
    worker_chunk_processes : int
        Processes a worker uses to run the chunks of one job in parallel
        (default 1: in the worker process itself). Set it to the number of
        cores to process a single long run faster.
    shared_store : str, optional
        Production mode on hosts without a common file system: fsspec URL
        (``s3://bucket/prefix`` with s3fs installed, ``file:///mnt/shared/…``)
        shared by the API and worker hosts. The API publishes run files there;
        workers fetch run files from there into their own run store and keep
        chunk results there (:mod:`app.core.sharedstore`). Default: none (the
        run store directory is the only store; share it between hosts by a
        network file system, or run on one host).
    anonymous_principal : str
        Name of the principal every request runs as until authentication is on.
    anonymous_role : str
        Role of that principal (viewer, engineer or admin).
    log_level : str
        Python logging level name for the service loggers.
    log_format : str
        ``text`` (default) or ``json``: one JSON object per log line (time,
        level, logger, message, pid, exception), uvicorn's logs too.
    max_page_size : int
        Largest page a list endpoint returns.
    max_profile_rows : int
        Largest number of rows a JSON profile query returns (exports stream
        and are not limited).
    env : str
        ``development`` (default) or ``production``. Production refuses to
        start with the default secret key, with ``auth_disabled`` or while a
        user with printed demo credentials is active.
    secret_key : str
        Server secret (>= 32 characters in production): keys the CSRF tokens.
    auth_disabled : bool
        Every request runs as the anonymous principal (``anonymous_principal``,
        ``anonymous_role``) without authentication. Development and tests
        only; refused in production.
    session_ttl_s : float
        Lifetime of a browser session after login, s (default 12 h).
    cookie_secure : bool
        Send the session cookies with the ``Secure`` flag (HTTPS only);
        always on in production.
    login_rate_limit, login_rate_window_s : int, float
        At most ``login_rate_limit`` login attempts per (client address, user
        name) within ``login_rate_window_s`` seconds (per API process); a
        browser holding the user's device cookie counts per device instead.
    login_address_rate_limit : int
        At most this many login attempts per client address over all user
        names within ``login_rate_window_s`` (per API process; not for
        browsers holding the user's device cookie).
    login_name_failure_limit, login_name_failure_window_s : int, float
        Failed logins of one user name from all addresses within the window
        (counted in the audit log: shared by all API processes) after which
        the name's logins are refused, except from browsers that logged in as
        that user before (device cookie). Brute force gets at most this many
        guesses per window; the user keeps logging in from their browser.
    upload_rate_limit, upload_rate_window_s : int, float
        At most ``upload_rate_limit`` uploads per principal (API key or user)
        within ``upload_rate_window_s`` seconds (per API process).
    profile_cache_bytes : int
        Memory each API process keeps for encoded profile answers of published
        jobs (immutable; LRU), bytes; 0 turns the cache off.
    display_cache_bytes : int
        Memory each API process keeps for the display query's columns of
        published jobs' profiles (numpy arrays per job and wheel, LRU), bytes:
        zooms are sliced from them instead of read from the database (about
        19 MB per wheel of a 100 km run for three columns); 0 turns it off.
    profile_concurrency : int
        Profile answers each API process computes at once; further requests
        wait their turn without holding up uploads, logins and other requests.
    assets_import_max_rows : int
        Most assets one import may write (default 200 000, the reader's limit); more: 413.
    assets_import_max_lines : int
        Most (line, track) pairs one import may replace (default 1000); more: 413. The
        transaction that makes an import live writes one row per pair.
    assets_import_batch_rows : int
        Rows an import writes (and replaced rows it deletes) per transaction: the longest it
        holds the write lock (2000 rows: ≈ 0.03 s on SQLite).
    db_lock_wait_s : float
        How long a request waits for the database's write lock (SQLite: the busy timeout, its
        retries within this deadline), s; past it the answer is 503 with ``Retry-After``
        (``"field": "database"``), never a 500.
    max_reference_bytes : int
        Largest accepted reference data file (subsidence, maintenance,
        superstructure), bytes.
    parse_isolated : bool
        Parse uploaded run files, geometries and reference files in a child
        process with a time and memory budget (default true; see
        docs/security.md, "Parsers").
    parse_seconds : float
        Wall-clock budget of one parse, s, plus the file size divided by
        ``parse_min_bytes_per_s`` (default 120 s).
    parse_min_bytes_per_s : float
        Slowest accepted parse rate, bytes/s (default 1 MB/s; a 26 MB MDF4
        file ingests at about 10–20 MB/s on one busy core).
    parse_memory_bytes : int
        Growth of a parse child's data segment, bytes (default 4 GiB).
    analytics_min_speed_kmh : float
        Profile bins slower than this (km/h) are left out of the analytics.
    analytics_reference_speed_kmh : float
        Default reference speed of the speed-normalised indicator, km/h.
    analytics_edge_trim_m : float
        The first and last metres of every run's profile left out of the
        analytics (filter end transients).
    analytics_speed_tolerance : float
        The matched-speed rule, wherever runs are compared: two passes are at
        matched speed when ``|ln(v / v0)| <= ln(1 + tol)`` (within a factor
        1 + tol either way; 0.1 = ±10 %; :mod:`app.analysis.speed_match`). The
        reference amplitude at speed v is estimated from such passes and exists
        only where they are; two runs' segments are compared, and a condition
        change is tested against earlier runs, only at matched speed.
    analytics_section_margin_m : float
        Bins within this distance of a change of superstructure type get no
        stiffness index and do not enter the reference curves, m.
    condition_step_z, condition_trend_z : float
        Scores (repeatability units, wheels combined) beyond which the
        condition store flags a sudden change (step) or a gradual trend.
    condition_agree_z : float
        A wheel agrees with a flag when its own score reaches this.
    condition_min_history : int
        Fewest speed-matched earlier runs a change test needs.
    condition_history_runs : int
        Most recent speed-matched earlier runs the step test compares each
        segment with.
    condition_history_scan_runs : int
        Most recent earlier runs of the line looked at to find them.
    condition_trend_window_days : float
        Days of history the trend test regresses over.
    condition_level_block_m : float
        Length of the blocks whose median change is taken as a run's level
        (calibration, temperature), m.
    condition_max_shift_m : float
        Largest alignment shift of a run onto its line's reference, m.
    condition_min_shift_confidence : float
        Alignments less clear than this are not applied.
    places_level_limits : dict of str to [float, float, float]
        Tier limits of a place's ``|index|`` (speed-conditioned stiffness
        index, ln units) per superstructure class: alert, intervention,
        immediate action (JSON: ``{"": [...], "b91_pads": [...]}``; ``""`` is
        every other class). Alert ≈ 3.3 σ of the class's healthy index, above
        every healthy segment measured; intervention and immediate 1.5 and 2.5
        times it (EN 13848-5's ratios). docs/places.md.
    places_change_limits : [float, float, float]
        Tier limits of a place's change against its own history (ln units):
        above healthy steps between runs at different speeds (≤ 0.10), below
        a 20 % change (0.22).
    places_step_z, places_trend_z : float
        Scores (wheels combined) a place's step and trend evidence need.
    places_min_rate_per_year : float
        Rate (ln units a year) a trend needs to be evidence of a place.
    places_watch_days : float
        A trend alone makes a place (tier watch) where it reaches the alert
        limit within so many days.
    places_trend_window_days : float
        Days of history a place's trend test regresses over.
    places_min_history : int
        Earlier runs with a value the step test of a place needs.
    places_history_runs : int
        Most recent earlier runs read for a run's places (baseline, repeatability).
    places_gap_m : float
        Exceeding 10 m segments at most this far apart merge into one place, m.
    places_curve_min_locations : int
        Distinct locations (10 m of one rail) a speed needs for the line's
        reference curve there (400 m of track both rails: no false places at a
        braking end); fewer: no index at that speed.
    places_curve_runs : int
        Newest earlier runs (with the run) the line's reference curves of the
        places are fitted on at each publish (enough passes over a fleet's
        speed spread; a longer history costs seconds a run and changes the
        curves little).
    places_match_tolerance_m : float
        Widening of the extents when a run's places are matched to the known
        places of the line, m.
    places_min_confirmations : int
        Runs that must find a place before it is listed (a one-run exceedance
        is that run's noise).
    places_confirm_tier : str
        A place of this tier or higher is listed at once (``alert``,
        ``intervention`` or ``immediate``).
    places_drop_after : int
        Consecutive runs covering a place without finding it after which it
        is not active (off the work list until found again).
    places_tier_down_runs : int
        Consecutive lower runs before a place's tier falls (no alert
        ping-pong at a limit).
    places_hold_change : float
        Departure from its baseline (ln units) that still holds a known place
        a run's tests did not flag.
    places_explain_days : float
        A place appearing this many days or fewer after a maintenance action
        over it is the action's effect (kept, never listed), days.
    places_section_m : float
        Length of the sections classed A … E by the index's level and spread, m.
    places_section_limits : [float, float, float, float]
        rms limits of the section classes A/B, B/C, C/D, D/E (ln units).
    places_class_scheme : dict, optional
        The railway's own class scheme: each section class A … E mapped to one of its classes,
        with their names per language (JSON; :mod:`app.places.class_scheme`), e.g.
        ``{"name": {"en": "Condition class", "de": "Zustandsklasse"}, "classes": [{"code": "1",
        "of": ["A"], "name": {"en": "as new", "de": "neuwertig"}}, …]}``. The API, CSV, the
        Condition page and the planning report show it; checked when the service starts.
        Default: none (classes A … E).
    places_asset_buffer_m : float
        Assets (switches, bridges, …) within this distance of a place label it, m.
    places_muted_asset_types : str
        Asset types (comma separated, e.g. ``weld,insulated_joint``) whose
        places are muted on the work list (labelled, never dropped). Default none.
    places_alerts : bool
        Send the places' alerts (a new place, a tier change, a place back:
        webhook event ``condition.places``) to the webhooks; the flags'
        alerts (``condition.flags``) go whatever this says.
    places_effect_around_m, places_effect_margin_m : float
        An extent against its surroundings (an action's effect on
        ``/condition/maintenance-effect``, a trend's ``relative``): its condition
        index against the track within ``around`` m of its centre, outside the
        extent widened by ``margin`` m.
    webhook_timeout_s : float
        Total time of one webhook request, s: name resolution, connection,
        TLS, sending and the receiver's answer together, however slowly the
        receiver trickles bytes.
    webhook_max_answer_bytes : int
        Most bytes of a receiver's answer body read (and discarded), bytes.
    webhook_concurrency : int
        Deliveries a worker process sends at once (one per webhook at a time):
        a slow receiver holds one of them, not the others.
    webhook_allowed_networks : str
        Networks (CIDR, comma separated: ``10.20.0.0/16,192.168.5.7/32``) that
        webhook receivers may be in although private, loopback or otherwise
        not public (on-premises receivers). Default: none (public addresses
        only). See docs/security.md ("Webhooks: SSRF policy").
    webhook_secret_grace_s : float
        After a secret is rotated (``PATCH /webhooks/{id}`` with ``secret``),
        deliveries carry a signature with the previous secret too for this
        long, s, so receivers can switch over.
    webhook_max_attempts : int
        Attempts of a delivery before it is given up.
    webhook_retry_base_s, webhook_retry_max_s : float
        Back-off after the n-th failed attempt: ``base · 2^(n−1)`` seconds, at most ``max``.
    webhook_poll_s : float
        Pause of a worker's delivery loop when nothing is due, s.
    profile_retention_days : int, optional
        Keep the 25 cm profile rows of runs measured in the last this many
        days; the workers remove older ones every ``profile_sweep_interval_s``
        (segment condition rows are kept for ever). Default: none (keep all).
    profile_sweep_interval_s : float
        Seconds between two retention sweeps of a worker.
    places_followup_interval_s : float
        Pause of a worker's places follow-up loop after a round with nothing
        due, s (the publish step's own follow-up runs at once; the loop
        completes what a killed worker left and the retries).
    places_followup_grace_s : float
        The loop leaves a run published less than this long ago to the
        worker that published it (it runs the run's follow-up at once), s.
    places_max_attempts : int
        Failed places updates of a run after which it is given up (kept and
        reported; its line's later runs go on).
    places_retry_base_s, places_retry_max_s : float
        Back-off of a failed places update: base doubling per attempt, at most max, s.
    oidc_issuer : str, optional
        Issuer URL of an OpenID Connect provider for corporate sign-in (Keycloak:
        ``https://<host>/realms/<realm>``; Microsoft Entra ID:
        ``https://login.microsoftonline.com/<tenant id>/v2.0``). Its discovery document is
        read from ``<issuer>/.well-known/openid-configuration``. Default: none (local users
        and API keys only). See docs/security.md ("Corporate sign-in").
    oidc_provider_name : str
        The provider's name on the login page ("Sign in with <name>").
    oidc_client_id : str, optional
        trackvkf's client id at the provider (needed with ``oidc_issuer``).
    oidc_client_secret : str, optional
        Its client secret (a confidential client); none: a public client (PKCE alone).
    oidc_token_auth_method : str
        How trackvkf authenticates at the token endpoint: ``client_secret_basic``
        (default), ``client_secret_post`` or ``none`` (a public client).
    oidc_scopes : str
        Scopes asked for (space separated; must include ``openid``).
    oidc_username_claim : str
        The ID token claim that names the user in trackvkf (``preferred_username``;
        Entra ID: ``preferred_username`` or ``email``); without it the ``email``, then the
        ``sub`` claim.
    oidc_groups_claim : str
        The claim that carries the user's groups or roles: a list of strings (``groups``;
        Entra ID app roles: ``roles``; a dotted path reaches into objects, Keycloak realm
        roles: ``realm_access.roles``).
    oidc_role_groups : dict of str to str
        Groups → trackvkf role (viewer, engineer, admin), JSON:
        ``{"track-admins": "admin", "track-engineers": "engineer"}``. A user gets the
        highest role of their groups; a user in none of them is refused unless
        ``oidc_default_role`` is set.
    oidc_default_role : str, optional
        Role of a signed-in user in none of the mapped groups. Default: none (refused).
    oidc_redirect_uri : str, optional
        The callback URL registered at the provider (``https://<host>/login/oidc/callback``).
        Default: derived from the request (set it behind a reverse proxy).
    oidc_post_logout_redirect_uri : str, optional
        Where the provider sends the browser after sign-out (register it there too).
        Default: the login page, derived from the request.
    oidc_api_audience : str, optional
        Accept the provider's JWT access tokens as ``Authorization: Bearer`` on the API
        when their ``aud`` holds this value (the provider's API/application id URI of
        trackvkf). Default: none (provider tokens are not accepted by the API; sign in with
        the browser or use an API key).
    oidc_timeout_s : float
        Time limit of one request to the provider (discovery, keys, token), s.
    oidc_metadata_ttl_s : float
        How long each API process keeps the provider's discovery document and keys, s (an
        unknown key id fetches the keys again at once, at most every 10 s).
    oidc_leeway_s : float
        Clock difference tolerated on the tokens' ``exp``, ``iat`` and ``nbf``, s.
    map_tile_url : str, optional
        Raster tile URL template (``https://tiles.example/{z}/{x}/{y}.png``) of
        a basemap under the map page's line geometry. Default: none (the page
        draws the geometry alone and requests nothing outside the server).
    map_tile_attribution : str
        Attribution text shown with the basemap.
    """

    model_config = SettingsConfigDict(
        env_prefix="TRACKVKF_", env_file=".env", env_file_encoding="utf-8", extra="ignore"
    )

    database_url: str = "sqlite:///./var/trackvkf.db"
    run_store: Path = Path("./var/runs")
    max_upload_bytes: int = Field(default=8 * _GIB, gt=0)
    upload_block_bytes: int = Field(default=1024 * 1024, ge=4096)
    max_metadata_bytes: int = Field(default=1024 * 1024, ge=1024)
    upload_ingest_concurrency: int = Field(default=1, ge=1, le=64)
    upload_stale_after_s: float = Field(default=6 * 3600.0, gt=0)
    min_free_bytes: int = Field(default=_GIB, ge=0)
    worker_poll_interval_s: float = Field(default=1.0, gt=0)
    worker_heartbeat_s: float = Field(default=2.0, gt=0)
    worker_stale_after_s: float = Field(default=30.0, gt=0)
    worker_chunk_processes: int = Field(default=1, ge=1, le=64)
    health_stuck_after_s: float = Field(default=600.0, gt=0)
    shared_store: str | None = None
    anonymous_principal: str = "local"
    anonymous_role: str = "admin"
    log_level: str = "INFO"
    log_format: str = Field(default="text", pattern="^(text|json)$")
    max_page_size: int = Field(default=500, ge=1)
    max_profile_rows: int = Field(default=200_000, ge=1)
    env: str = "development"
    secret_key: str = DEFAULT_SECRET_KEY
    auth_disabled: bool = False
    session_ttl_s: float = Field(default=12 * 3600.0, gt=0)
    cookie_secure: bool = False
    login_rate_limit: int = Field(default=10, ge=1)
    login_rate_window_s: float = Field(default=60.0, gt=0)
    login_address_rate_limit: int = Field(default=30, ge=1)
    login_name_failure_limit: int = Field(default=50, ge=1)
    login_name_failure_window_s: float = Field(default=3600.0, gt=0)
    upload_rate_limit: int = Field(default=60, ge=1)
    upload_rate_window_s: float = Field(default=3600.0, gt=0)
    assets_import_max_rows: int = Field(default=200_000, ge=1, le=200_000)
    assets_import_max_lines: int = Field(default=1000, ge=1, le=100_000)
    assets_import_batch_rows: int = Field(default=2000, ge=100, le=100_000)
    db_lock_wait_s: float = Field(default=15.0, gt=0, le=600)
    max_reference_bytes: int = Field(default=256 * 1024 * 1024, gt=0)
    parse_isolated: bool = True
    parse_seconds: float = Field(default=120.0, gt=0)
    parse_min_bytes_per_s: float = Field(default=1_000_000.0, gt=0)
    parse_memory_bytes: int = Field(default=4 * _GIB, ge=64 * 1024 * 1024)
    profile_cache_bytes: int = Field(default=64 * 1024 * 1024, ge=0)
    display_cache_bytes: int = Field(default=256 * 1024 * 1024, ge=0)
    profile_concurrency: int = Field(default=2, ge=1, le=64)
    analytics_min_speed_kmh: float = Field(default=25.0, ge=0)
    analytics_reference_speed_kmh: float = Field(default=100.0, gt=0)
    analytics_edge_trim_m: float = Field(default=50.0, ge=0)
    analytics_speed_tolerance: float = Field(default=0.1, gt=0, le=1)
    analytics_section_margin_m: float = Field(default=50.0, ge=0)
    condition_step_z: float = Field(default=4.5, gt=0)
    condition_trend_z: float = Field(default=4.5, gt=0)
    condition_agree_z: float = Field(default=2.0, gt=0)
    condition_min_history: int = Field(default=8, ge=2)
    condition_history_runs: int = Field(default=30, ge=2, le=1000)
    condition_history_scan_runs: int = Field(default=60, ge=2, le=2000)
    condition_trend_window_days: float = Field(default=180.0, gt=0)
    condition_level_block_m: float = Field(default=1000.0, gt=0)
    condition_max_shift_m: float = Field(default=50.0, gt=0)
    condition_min_shift_confidence: float = Field(default=0.2, ge=0, le=1)
    places_level_limits: dict[str, list[float]] = Field(
        default_factory=lambda: {"": [0.25, 0.375, 0.625], "b91_pads": [0.30, 0.45, 0.75]})
    places_change_limits: list[float] = Field(default_factory=lambda: [0.10, 0.30, 0.50])
    places_step_z: float = Field(default=4.5, gt=0)
    places_trend_z: float = Field(default=4.5, gt=0)
    places_min_rate_per_year: float = Field(default=0.25, gt=0)
    places_watch_days: float = Field(default=180.0, gt=0)
    places_trend_window_days: float = Field(default=180.0, gt=0)
    places_min_history: int = Field(default=5, ge=2)
    places_history_runs: int = Field(default=30, ge=2, le=1000)
    places_gap_m: float = Field(default=10.0, ge=0)
    places_curve_min_locations: int = Field(default=80, ge=0)
    places_curve_runs: int = Field(default=20, ge=1, le=1000)
    places_match_tolerance_m: float = Field(default=10.0, ge=0)
    places_min_confirmations: int = Field(default=2, ge=1)
    places_confirm_tier: str = "intervention"
    places_drop_after: int = Field(default=2, ge=1)
    places_tier_down_runs: int = Field(default=2, ge=1)
    places_hold_change: float = Field(default=0.10, gt=0)
    places_explain_days: float = Field(default=60.0, ge=0)
    places_section_m: float = Field(default=200.0, gt=0)
    places_section_limits: list[float] = Field(default_factory=lambda: [0.05, 0.10, 0.17, 0.25])
    places_class_scheme: dict[str, Any] | None = None
    places_asset_buffer_m: float = Field(default=20.0, ge=0)
    places_muted_asset_types: str = Field(default="", max_length=500)
    places_alerts: bool = True
    places_effect_around_m: float = Field(default=1000.0, gt=0)
    places_effect_margin_m: float = Field(default=50.0, ge=0)
    webhook_timeout_s: float = Field(default=5.0, gt=0, le=120)
    webhook_max_answer_bytes: int = Field(default=64 * 1024, ge=0, le=16 * 1024 * 1024)
    webhook_concurrency: int = Field(default=4, ge=1, le=64)
    webhook_allowed_networks: str = Field(default="", max_length=4000)
    webhook_secret_grace_s: float = Field(default=24 * 3600.0, ge=0)
    webhook_max_attempts: int = Field(default=8, ge=1, le=100)
    webhook_retry_base_s: float = Field(default=5.0, gt=0)
    webhook_retry_max_s: float = Field(default=3600.0, gt=0)
    webhook_poll_s: float = Field(default=1.0, gt=0)
    profile_retention_days: int | None = Field(default=None, ge=1)
    profile_sweep_interval_s: float = Field(default=3600.0, gt=0)
    places_followup_interval_s: float = Field(default=10.0, gt=0)
    places_followup_grace_s: float = Field(default=30.0, ge=0)
    places_max_attempts: int = Field(default=10, ge=1, le=1000)
    places_retry_base_s: float = Field(default=5.0, gt=0)
    places_retry_max_s: float = Field(default=3600.0, gt=0)
    oidc_issuer: str | None = Field(default=None, max_length=500)
    oidc_provider_name: str = Field(default="corporate account", min_length=1, max_length=80)
    oidc_client_id: str | None = Field(default=None, max_length=255)
    oidc_client_secret: str | None = Field(default=None, max_length=1000)
    oidc_token_auth_method: str = Field(
        default="client_secret_basic", pattern="^(client_secret_basic|client_secret_post|none)$")
    oidc_scopes: str = Field(default="openid profile email", max_length=500)
    oidc_username_claim: str = Field(default="preferred_username", min_length=1, max_length=100)
    oidc_groups_claim: str = Field(default="groups", min_length=1, max_length=200)
    oidc_role_groups: dict[str, str] = Field(default_factory=dict)
    oidc_default_role: str | None = None
    oidc_redirect_uri: str | None = Field(default=None, max_length=500)
    oidc_post_logout_redirect_uri: str | None = Field(default=None, max_length=500)
    oidc_api_audience: str | None = Field(default=None, max_length=500)
    oidc_timeout_s: float = Field(default=10.0, gt=0, le=120)
    oidc_metadata_ttl_s: float = Field(default=3600.0, gt=0)
    oidc_leeway_s: float = Field(default=60.0, ge=0, le=600)
    map_tile_url: str | None = Field(default=None, max_length=500)
    map_tile_attribution: str = Field(default="", max_length=300)

    @field_validator("anonymous_role")
    @classmethod
    def _check_role(cls, value: str) -> str:
        if value not in ("viewer", "engineer", "admin"):
            raise ValueError(f"anonymous_role must be viewer, engineer or admin, got {value!r}")
        return value

    @field_validator("oidc_role_groups")
    @classmethod
    def _check_role_groups(cls, value: dict[str, str]) -> dict[str, str]:
        for group, role in value.items():
            if role not in ("viewer", "engineer", "admin"):
                raise ValueError(f"oidc_role_groups[{group!r}] must be viewer, engineer or admin, got {role!r}")
        return value

    @field_validator("oidc_default_role")
    @classmethod
    def _check_default_role(cls, value: str | None) -> str | None:
        if value is not None and value not in ("viewer", "engineer", "admin"):
            raise ValueError(f"oidc_default_role must be viewer, engineer or admin, got {value!r}")
        return value

    @field_validator("oidc_scopes")
    @classmethod
    def _check_scopes(cls, value: str) -> str:
        if "openid" not in value.split():
            raise ValueError(f"oidc_scopes must include openid, got {value!r}")
        return " ".join(value.split())

    @field_validator("oidc_issuer", "oidc_redirect_uri", "oidc_post_logout_redirect_uri")
    @classmethod
    def _check_url(cls, value: str | None, info) -> str | None:
        if value is None or not value.strip():
            return None
        value = value.strip()
        if not value.startswith(("https://", "http://")):
            raise ValueError(f"{info.field_name} must be an http(s) URL, got {value!r}")
        return value  # the issuer exactly as the provider writes it into its tokens' "iss"

    @model_validator(mode="after")
    def _check_oidc(self) -> Settings:
        if self.oidc_api_audience and not self.oidc_issuer:
            raise ValueError("oidc_api_audience: needs oidc_issuer (whose tokens to accept)")
        if self.oidc_issuer and not self.oidc_client_id:
            raise ValueError("oidc_client_id: needed with oidc_issuer")
        if self.oidc_issuer and self.oidc_token_auth_method != "none" and not self.oidc_client_secret:
            raise ValueError(
                f"oidc_client_secret: needed with oidc_token_auth_method={self.oidc_token_auth_method} "
                "(or set oidc_token_auth_method=none for a public client)")
        return self

    @field_validator("webhook_allowed_networks")
    @classmethod
    def _check_networks(cls, value: str) -> str:
        from app.core.url_policy import parse_networks

        parse_networks(value)  # ValueError naming the entry
        return value

    @field_validator("places_level_limits")
    @classmethod
    def _check_level_limits(cls, value: dict[str, list[float]]) -> dict[str, list[float]]:
        for name, lim in value.items():
            _check_increasing(f"places_level_limits[{name!r}]", lim, 3)
        return value

    @field_validator("places_change_limits")
    @classmethod
    def _check_change_limits(cls, value: list[float]) -> list[float]:
        return _check_increasing("places_change_limits", value, 3)

    @field_validator("places_section_limits")
    @classmethod
    def _check_section_limits(cls, value: list[float]) -> list[float]:
        return _check_increasing("places_section_limits", value, 4)

    @field_validator("places_confirm_tier")
    @classmethod
    def _check_confirm_tier(cls, value: str) -> str:
        if value not in ("alert", "intervention", "immediate"):
            raise ValueError(f"places_confirm_tier must be alert, intervention or immediate, got {value!r}")
        return value

    @field_validator("places_muted_asset_types")
    @classmethod
    def _check_muted(cls, value: str) -> str:
        # the known types are checked where the places' settings are read (app.places.config)
        return ",".join(t.strip() for t in value.split(",") if t.strip())

    @field_validator("env")
    @classmethod
    def _check_env(cls, value: str) -> str:
        value = value.strip().lower()
        if value not in ("development", "production"):
            raise ValueError(f"env must be development or production, got {value!r}")
        return value

    @field_validator("worker_stale_after_s")
    @classmethod
    def _check_stale(cls, value: float, info) -> float:
        heartbeat = info.data.get("worker_heartbeat_s")
        if heartbeat is not None and value <= 2 * heartbeat:
            raise ValueError(
                f"worker_stale_after_s ({value}) must exceed twice worker_heartbeat_s ({heartbeat})"
            )
        return value

    @property
    def oidc_enabled(self) -> bool:
        """Whether corporate sign-in (OpenID Connect) is configured."""
        return bool(self.oidc_issuer)

    @property
    def is_production(self) -> bool:
        """Whether ``TRACKVKF_ENV=production``."""
        return self.env == "production"

    def check_production(self) -> None:
        """Refuse unsafe settings in production mode (no-op in development).

        Raises
        ------
        ProductionConfigError
            Naming the setting: the default or a short ``secret_key``, or
            ``auth_disabled``.
        """
        if not self.is_production:
            return
        if self.secret_key == DEFAULT_SECRET_KEY or len(self.secret_key) < 32:
            raise ProductionConfigError(
                "TRACKVKF_SECRET_KEY: production mode needs a secret key of at least 32 "
                "characters other than the development default "
                "(e.g. python -c 'import secrets; print(secrets.token_urlsafe(48))')"
            )
        if self.oidc_issuer and not self.oidc_issuer.startswith("https://"):
            raise ProductionConfigError(
                "TRACKVKF_OIDC_ISSUER: production mode needs an https:// issuer")
        if self.auth_disabled:
            raise ProductionConfigError(
                "TRACKVKF_AUTH_DISABLED: authentication cannot be disabled in production mode"
            )

    @property
    def is_sqlite(self) -> bool:
        """Whether the database URL selects SQLite (embedded mode)."""
        return self.database_url.startswith("sqlite")


def _check_increasing(name: str, value: list[float], n: int) -> list[float]:
    import math

    if len(value) != n or not all(math.isfinite(v) for v in value) \
            or not all(0 < a < b for a, b in zip(value, value[1:], strict=False)) or not value[0] > 0:
        raise ValueError(f"{name}: must be {n} finite increasing numbers > 0, got {value!r}")
    return [float(v) for v in value]


@lru_cache(maxsize=1)
def get_settings() -> Settings:
    """Return the process-wide settings read from the environment (cached)."""
    return Settings()
