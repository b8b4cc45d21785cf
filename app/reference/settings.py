"""The reference data's settings group (``TRACKVKF_MAX_REFERENCE_BYTES``, :mod:`app.reference.service`)."""

from __future__ import annotations

from pydantic import Field

from app.core.config import SettingsGroup

__all__ = ["ReferenceSettings"]


class ReferenceSettings(SettingsGroup):
    """Reference data: subsidence, maintenance and superstructure files.

    Attributes
    ----------
    max_reference_bytes : int
        Largest accepted reference data file (subsidence, maintenance,
        superstructure), bytes.
    """

    max_reference_bytes: int = Field(default=256 * 1024 * 1024, gt=0)
