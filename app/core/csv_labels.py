"""The header labels of the CSV exports: each column's words and unit in the reader's language.

A CSV export's header is the API's field names by default (``header=fields``: what a data system
reads). With ``header=labels`` (what the pages' CSV links ask for: a person opening the file in a
spreadsheet) the header row is each column's label in the request's language with its unit in
brackets, e.g. German ``km von [km]``, ``Änderung [ln-Einheiten]``. The cells and the column order
stay the same either way.

:data:`COLUMN_LABELS` is the one table of column → (label message, unit) of every export; the one
writer (:func:`app.core.csv_export.csv_lines`) applies it. A column missing from it is an error
(tests check that every column of every export has a label).
"""

from __future__ import annotations

import re
from collections.abc import Sequence

from app.core.errors import ApiError
from app.core.i18n import N_, Msg, _, translations

__all__ = ["HEADER_MODES", "COLUMN_LABELS", "SEGMENT_STATISTICS", "check_header", "column_label", "header_labels"]

#: what a CSV export's ``header`` parameter may ask for: the API's field names, or the labels
HEADER_MODES: tuple[str, ...] = ("fields", "labels")

# units: symbols stay as they are in every language; worded units are messages
_KM, _M, _MM, _PCT, _KMH, _MS, _MS2, _KN = "km", "m", "mm", "%", "km/h", "m/s", "m/s²", "kN"
_LN = N_("ln units")
_LN_YEAR = N_("ln units/year")
_PCT_YEAR = N_("%/year")
_MM_YEAR = N_("mm/year")
_DAYS = N_("days")

#: column → (label message, unit or None) of every CSV export (a profile's segment statistics
#: ``<col>_mean``, ``_max``, ``_p95`` are ``<col>``'s label with the statistic's name)
COLUMN_LABELS: dict[str, tuple[str, str | None]] = {
    # shared
    "id": (N_("id"), None),
    "line_id": (N_("line"), None),
    "track": (N_("track"), None),
    "km_from": (N_("km from"), _KM),
    "km_to": (N_("km to"), _KM),
    "length_m": (N_("length"), _M),
    # places (app.places.worklist)
    "peak": (N_("peak index"), _LN),
    "peak_percent": (N_("peak amplitude vs typical track"), _PCT),
    "peak_km": (N_("peak at"), _KM),
    "direction": (N_("direction"), None),
    "reading": (N_("reading"), None),
    "speed_kmh": (N_("speed"), _KMH),
    "tier": (N_("tier"), None),
    "confirmed": (N_("confirmed"), None),
    "evidence": (N_("evidence"), None),
    "wheels": (N_("wheels"), None),
    "runs_confirming": (N_("runs confirming"), None),
    "first_seen": (N_("first seen"), None),
    "last_confirmed": (N_("last confirmed"), None),
    "tendency": (N_("tendency"), None),
    "rate_per_year": (N_("rate"), _LN_YEAR),
    "rate_low": (N_("rate, low end of 95 % interval"), _LN_YEAR),
    "rate_high": (N_("rate, high end of 95 % interval"), _LN_YEAR),
    "amplitude_percent_per_year": (N_("amplitude change"), _PCT_YEAR),
    "amplitude_percent_low": (N_("amplitude change, low end of 95 % interval"), _PCT_YEAR),
    "amplitude_percent_high": (N_("amplitude change, high end of 95 % interval"), _PCT_YEAR),
    "next_tier": (N_("next tier"), None),
    "projected_date": (N_("projected date"), None),
    "days_to_next_tier": (N_("time to next tier"), _DAYS),
    "projected_date_early": (N_("projected date, early"), None),
    "projected_date_late": (N_("projected date, late"), None),
    "days_to_next_tier_early": (N_("time to next tier, early"), _DAYS),
    "days_to_next_tier_late": (N_("time to next tier, late"), _DAYS),
    "no_projection": (N_("why no projection"), None),
    "status": (N_("status"), None),
    "status_comment": (N_("status comment"), None),
    "status_by": (N_("status set by"), None),
    "status_at": (N_("status set at"), None),
    "actions": (N_("maintenance"), None),
    "assets": (N_("assets"), None),
    "active": (N_("active"), None),
    "muted": (N_("muted"), None),
    "muted_reason": (N_("why muted"), None),
    "method_version": (N_("method version"), None),
    "peak_sd": (N_("peak index, standard deviation"), _LN),
    "change": (N_("change"), _LN),
    "change_sd": (N_("change, standard deviation"), _LN),
    "severity": (N_("severity"), _LN),
    "severity_sd": (N_("severity, standard deviation"), _LN),
    # sections (app.places.sections)
    "class": (N_("class"), None),
    "scheme_class": (N_("class of the railway's scheme"), None),
    "scheme_class_name": (N_("class name"), None),
    "level": (N_("level"), _LN),
    "spread": (N_("spread"), _LN),
    "rms": (N_("rms"), _LN),
    "fill": (N_("fraction with data"), None),
    # rail findings (app.condition.rail_findings)
    "type": (N_("type"), None),
    "km": (N_("position"), _KM),
    "depth_mm": (N_("dip depth"), _MM),
    "runs_seen": (N_("runs seen"), None),
    "runs_passed": (N_("runs passed"), None),
    "steady": (N_("seen by half the runs or more"), None),
    "last_seen": (N_("last seen"), None),
    "depth_trend_mm_per_year": (N_("dip depth trend"), _MM_YEAR),
    "depth_trend_significant": (N_("trend significant"), None),
    "depth_trend_since": (N_("trend since the rail work of"), None),
    "asset_type": (N_("asset type"), None),
    "asset_name": (N_("asset name"), None),
    # a run's profile (app.profiles.export): its 25 cm bins, or segments of them (below)
    "wheel": (N_("wheel"), None),
    "bin": (N_("bin"), None),
    "n_samples": (N_("samples"), None),
    "n_bins": (N_("bins"), None),
    "speed_mean": (N_("speed"), _MS),
    "sleeper_amp": (N_("sleeper-passage amplitude"), _MS2),
    "sleeper_2_amp": (N_("sleeper-passage 2nd harmonic amplitude"), _MS2),
    "sleeper_3_amp": (N_("sleeper-passage 3rd harmonic amplitude"), _MS2),
    "sleeper_rms": (N_("sleeper-passage rms"), _MS2),
    **{f"order_amp_{n:02d}": (_("wheel order {n} amplitude", n=n), _MS2) for n in range(1, 12)},
    "residual_rms": (N_("residual rms"), _MS2),
    "sleeper_force_amp": (N_("sleeper-passage force amplitude"), _KN),
    "sleeper_amp_raw": (N_("sleeper-passage amplitude, raw"), _MS2),
    "sleeper_amp_sd": (N_("sleeper-passage amplitude, standard deviation"), _MS2),
    "sleeper_amp_sd_shared": (N_("sleeper-passage amplitude, standard deviation shared along the track"), _MS2),
    "track_impact_mm": (N_("track impact depth"), _MM),
    "sleeper_step": (N_("sleeper-passage amplitude, step estimate"), _MS2),
    "stiffness_index": (N_("stiffness index"), _LN),
    "stiffness_index_se": (N_("stiffness index, standard error"), _LN),
    "reference_amp": (N_("reference amplitude"), _MS2),
}
#: the statistics of a profile's segments: a column ``<col>_mean`` is labelled ``<col>``'s label, mean
SEGMENT_STATISTICS: dict[str, str] = {"mean": N_("mean"), "max": N_("maximum"), "p95": N_("95th percentile")}
_SEGMENT = re.compile(r"^(.+)_(mean|max|p95)$")


def check_header(value: str | None) -> str:
    """The ``header`` parameter checked: ``fields`` (the default) or ``labels``; anything else
    answers 422 naming ``header``."""
    if value is None:
        return "fields"
    if value not in HEADER_MODES:
        raise ApiError(422, "header", _("must be one of {choices}, got {status}",
                                        choices=", ".join(HEADER_MODES), status=value[:40]))
    return value


def column_label(column: str, lang: str) -> str:
    """The label of ``column`` in ``lang``, its unit in brackets: ``"km von [km]"``.

    Raises
    ------
    KeyError
        When the column has no label in :data:`COLUMN_LABELS` (a new column needs one).
    """
    t = translations(lang)
    statistic = None
    m = _SEGMENT.match(column)
    if column not in COLUMN_LABELS and m and m.group(1) in COLUMN_LABELS:  # a profile segment's statistic
        column, statistic = m.group(1), t.gettext(SEGMENT_STATISTICS[m.group(2)])
    msgid, unit = COLUMN_LABELS[column]
    label = msgid.in_language(lang) if isinstance(msgid, Msg) else t.gettext(msgid)
    if statistic:
        label = f"{label}, {statistic}"
    return f"{label} [{t.gettext(unit)}]" if unit else label


def header_labels(columns: Sequence[str], lang: str) -> list[str]:
    """The labels of ``columns`` in ``lang`` (:func:`column_label`), in their order."""
    return [column_label(c, lang) for c in columns]
