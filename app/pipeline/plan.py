"""Step 1 of the pipeline: cut a run into chunks with the overlap the VKF needs."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from app.analysis.chunking import Chunk, plan_chunk_layout
from app.analysis.recipe import CHUNK_JOIN_TOL, order_overlap, wheel_recipe
from app.analysis.settings import ProcessingSettings
from app.io import WHEELS, open_run

__all__ = ["ChunkSpec", "plan_chunks"]

#: a chunk task of a run: the engine's chunk layout (JSON via to_dict/from_dict)
ChunkSpec = Chunk


def plan_chunks(run_path: Path, settings: ProcessingSettings) -> list[ChunkSpec]:
    """Cut a run into chunks with the overlap the VKF needs.

    Chunks of ``settings.chunk_seconds`` (cores) are padded by the overlap of
    the order recipes of all wheels (:func:`app.analysis.recipe.order_overlap`
    with :data:`~app.analysis.recipe.CHUNK_JOIN_TOL`) at the speeds around the
    chunk, and joined by a raised-cosine crossfade at each seam.

    Parameters
    ----------
    run_path : Path
        Canonical run file (HDF5).
    settings : ProcessingSettings

    Returns
    -------
    list of ChunkSpec
        Cores tile ``[0, n_samples)``; JSON-serialisable via ``to_dict``.
    """
    with open_run(run_path) as run:
        n, fs = run.n_samples, run.fs
        speed = run.speed()
        recipes = [wheel_recipe(run.metadata, wheel, settings) for wheel in WHEELS]
    core = max(int(round(settings.chunk_seconds * fs)), 1)

    def overlap(a: int, b: int) -> int:
        return order_overlap(fs, np.abs(speed[a:b]), recipes, tol=CHUNK_JOIN_TOL)

    return plan_chunk_layout(n, core, overlap)
