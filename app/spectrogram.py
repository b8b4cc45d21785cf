"""Spectrogram of a km window of a run (paper figure fig3), computed from the run file.

The raw axle-box acceleration of one wheel over a window of at most :data:`MAX_WINDOW_M`, the
sum of the VKF-extracted orders (with the settings of the run's processing job), the tracked
order frequencies and the speed per frame (:func:`app.analysis.spectrogram.window_spectrograms`),
answered by ``GET /runs/{id}/spectrogram`` (:func:`spectrogram_answer`).
"""

from __future__ import annotations

import math
from typing import Any

from app.analysis.settings import ProcessingSettings, SettingError
from app.analysis.units import KMH_PER_MPS
from app.core.errors import ApiError, not_found
from app.core.i18n import Msg, _
from app.core.jsonable import finite_list
from app.core.runstore import RunStore
from app.db import crud, results_reader
from app.db.session import Database
from app.io import WHEELS, RunFile, open_run

__all__ = ["MAX_WINDOW_M", "sample_range", "spectrogram_answer"]

#: longest km window of one spectrogram request, m
MAX_WINDOW_M = 500.0


def _first_at_or_after(run: RunFile, target_m: float, axle: str) -> int:
    """First sample whose track position (signed along the run) reaches ``target_m``.

    The position along the run is assumed non-decreasing (a train that does
    not reverse); found by bisection with one-sample reads.
    """
    sign = 1.0 if run.metadata.km_increasing else -1.0
    lo, hi = 0, run.n_samples
    while lo < hi:
        mid = (lo + hi) // 2
        if sign * float(run.track_m(mid, mid + 1, axle=axle)[0]) < sign * target_m:
            lo = mid + 1
        else:
            hi = mid
    return lo


def sample_range(run: RunFile, km_from: float, km_to: float, axle: str) -> tuple[int, int]:
    """Samples ``[start, stop)`` in which ``axle`` is between ``km_from`` and ``km_to``."""
    a_m, b_m = 1000.0 * km_from, 1000.0 * km_to
    if not run.metadata.km_increasing:
        a_m, b_m = b_m, a_m
    start = _first_at_or_after(run, a_m, axle)
    stop = _first_at_or_after(run, b_m, axle)
    return start, stop


def _settings_of(db, run_id: int) -> tuple[ProcessingSettings, str]:
    with db.read() as session:
        run = crud.get_run(session, run_id)
        if run is None:
            raise not_found("run", run_id)
        job = results_reader.results_job(session, run_id) or crud.latest_job(session, run_id)
        path = run.file_path
        raw = dict(job.settings or {}) if job is not None else None
    try:
        settings = ProcessingSettings.from_stored(raw) if raw is not None else ProcessingSettings()
    except (TypeError, ValueError):
        settings = ProcessingSettings()
    return settings, path


def spectrogram_answer(db: Database, store: RunStore, run_id: int, *, wheel: str, km_from: float, km_to: float,
                       revolutions: float) -> dict[str, Any]:
    """PSD (dB re 1 (m/s²)²/Hz) of the raw axle-box acceleration of one wheel over a
    window of at most 500 m, the PSD of the sum of the VKF-extracted orders (same
    settings as the run's processing job), the tracked order frequencies (Hz) and
    the speed (km/h) per frame, with the km of every frame."""
    # here, not at the module's top: the VKF engine (numba, scipy.signal) loads with the first spectrogram,
    # not with every API process
    from app.analysis.recipe import order_overlap, wheel_recipe
    from app.analysis.spectrogram import window_spectrograms

    w = wheel
    if not (math.isfinite(km_from) and math.isfinite(km_to)):
        raise ApiError(422, "km_from", _("must be finite numbers"))
    if km_to <= km_from:
        raise ApiError(422, "km_to", _("({km_to}) must be greater than km_from ({km_from})", km_to=km_to, km_from=km_from))
    length_m = 1000.0 * (km_to - km_from)
    if length_m > MAX_WINDOW_M + 1e-6:
        raise ApiError(
            422, "km_to", _("window is {length_m:.0f} m; at most {MAX_WINDOW_M:.0f} m per spectrogram", length_m=length_m, MAX_WINDOW_M=MAX_WINDOW_M)
        )
    settings, file_path = _settings_of(db, run_id)
    try:
        run = open_run(store.local_file(file_path))
    except Exception as exc:  # noqa: BLE001 - the run file is missing or unreadable
        raise ApiError(409, "run", _("run {run_id}: run file not readable ({exc})", run_id=run_id, exc=exc)) from None
    with run:
        channel = f"Z{w}"
        if w not in WHEELS or not run.has(channel):
            raise ApiError(404, "wheel", _("run {run_id} has no channel {channel}", run_id=run_id, channel=channel))
        axle = w[0]
        start, stop = sample_range(run, km_from, km_to, axle)
        if stop - start < 64:
            first = float(run.km(0, 1, axle=axle)[0])
            last = float(run.km(run.n_samples - 1, run.n_samples, axle=axle)[0])
            raise ApiError(
                422, "km_from",
                _("window {km_from}–{km_to} km holds no data of wheel {w} (the run covers {min:.3f}–{max:.3f} km)", km_from=km_from, km_to=km_to, w=w, min=min(first, last), max=max(first, last)),
            )
        recipe = wheel_recipe(run.metadata, w, settings)  # the orders the pipeline tracks
        d_w, d_s = recipe.wheel_diameter, recipe.sleeper_spacing
        pad = order_overlap(run.fs, run.speed(start, stop), [recipe])
        pad = min(pad, 4 * (stop - start))
        lo, hi = max(0, start - pad), min(run.n_samples, stop + pad)
        y = run.read(channel, lo, hi)
        speed = run.speed(lo, hi)
        try:
            spec = window_spectrograms(
                y, run.fs, speed, core=(start - lo, stop - lo), wheel_diameter=d_w,
                sleeper_spacing=d_s, settings=settings, revolutions=revolutions,
            )
        except ValueError as exc:
            text = str(exc)
            field = text.split(":", 1)[0] if text.startswith("speed") else "window"
            raise ApiError(422, field, Msg(exc.message, **exc.params) if isinstance(exc, SettingError) else text) from None
        km_frames = run.km(start, stop, axle=axle)[spec.frame_index]
        fs = run.fs
    return {
        "run_id": run_id,
        "wheel": w,
        "channel": channel,
        "km_from": km_from,
        "km_to": km_to,
        "fs_hz": fs,
        "settings": settings.to_dict(),
        "wheel_diameter_m": d_w,
        "sleeper_spacing_m": d_s,
        "resolution_hz": spec.resolution_hz,
        "units": {"psd": "dB re 1 (m/s^2)^2/Hz", "freq": "Hz", "km": "km", "speed": "km/h"},
        "km": finite_list(km_frames, 6),
        "time_s": finite_list(spec.time_s + start / fs, 4),
        "freq_hz": finite_list(spec.freq_hz, 4),
        "raw_db": [finite_list(row, 2) for row in spec.raw_db],
        "components_db": [finite_list(row, 2) for row in spec.components_db],
        "speed_kmh": finite_list(spec.speed * KMH_PER_MPS, 3),
        "orders": [
            {"label": label, "freq_hz": finite_list(f, 4)}
            for label, f in zip(spec.order_labels, spec.order_freq_hz, strict=True)
        ],
    }

