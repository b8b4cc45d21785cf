"""Spectrogram of a km window of a run (paper figure fig3): the route (:mod:`app.spectrogram`)."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Query

from app.api.deps import DbDep, RunId, StoreDep, Wheel, km_query, wheel_param
from app.spectrogram import spectrogram_answer

__all__ = ["router"]

router = APIRouter(tags=["spectrogram"])


@router.get(
    "/runs/{run_id}/spectrogram",
    summary="Spectrogram of a km window: raw ABA, extracted orders, order tracks",
    responses={422: {"description": "Bad window or wheel"}},
)
def get_spectrogram(
    run_id: RunId,
    db: DbDep,
    store: StoreDep,
    wheel: Wheel,
    km_from: Annotated[float, km_query("Window start, km")],
    km_to: Annotated[float, km_query("Window end, km")],
    revolutions: Annotated[
        float, Query(ge=1, le=64, description="Wheel revolutions per STFT frame (resolution f1/revolutions)")
    ] = 8.0,
) -> dict[str, Any]:
    """PSD (dB re 1 (m/s²)²/Hz) of the raw axle-box acceleration of one wheel over a
    window of at most 500 m, the PSD of the sum of the VKF-extracted orders (same
    settings as the run's processing job), the tracked order frequencies (Hz) and
    the speed (km/h) per frame, with the km of every frame."""
    return spectrogram_answer(db, store, run_id, wheel=wheel_param(wheel), km_from=km_from, km_to=km_to,
                              revolutions=revolutions)
