"""The profiles' settings group (``TRACKVKF_MAX_PROFILE_ROWS``, ``TRACKVKF_PROFILE_*``, ``TRACKVKF_DISPLAY_CACHE_BYTES``):
how 25 cm profiles are served, cached and kept (:mod:`app.profiles`)."""

from __future__ import annotations

from pydantic import Field

from app.core.config import SettingsGroup

__all__ = ["ProfileSettings"]


class ProfileSettings(SettingsGroup):
    """Profiles: answers, caches and retention of the 25 cm profile rows.

    Attributes
    ----------
    max_profile_rows : int
        Largest number of rows a JSON profile query returns (exports stream
        and are not limited).
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
    profile_retention_days : int, optional
        Keep the 25 cm profile rows of runs measured in the last this many
        days; the workers remove older ones every ``profile_sweep_interval_s``
        (segment condition rows are kept for ever). Default: none (keep all).
    profile_sweep_interval_s : float
        Seconds between two retention sweeps of a worker.
    """

    max_profile_rows: int = Field(default=200_000, ge=1)
    profile_cache_bytes: int = Field(default=64 * 1024 * 1024, ge=0)
    display_cache_bytes: int = Field(default=256 * 1024 * 1024, ge=0)
    profile_concurrency: int = Field(default=2, ge=1, le=64)
    profile_retention_days: int | None = Field(default=None, ge=1)
    profile_sweep_interval_s: float = Field(default=3600.0, gt=0)
