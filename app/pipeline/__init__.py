"""Processing pipeline of a run: plan chunks → process each chunk → assemble.

The three steps are plain functions over files so that any queue can run
them (the local job loop and the Procrastinate tasks of :mod:`worker`, the
``process`` command):

* :func:`plan_chunks` (:mod:`app.pipeline.plan`) cuts the run into chunks of
  ``settings.chunk_seconds`` with the overlap the VKF needs (from its impulse
  response at the slowest speed of the chunk) and a raised-cosine crossfade
  at each seam.
* :func:`process_chunk` (:mod:`app.pipeline.chunk`) runs the VKF for every
  wheel and writes **additive** per-bin sums (crossfade-weighted) to one
  chunk file (:mod:`app.pipeline.chunkfile`), atomically. Running it twice
  writes the same file.
* :func:`assemble` (:mod:`app.pipeline.assemble`) adds the chunk sums and
  turns them into the 25 cm profile rows and the wheel out-of-roundness
  results. It is deterministic and idempotent; it reads no raw signal.
  The fan-out assembles the wheels apart (:func:`wheel_assembly`) and ends
  as :func:`assemble` does, with :func:`finish_assembly` (the run's track
  impacts bridged, the step estimate, the wheel flats, the provenance).

:func:`run_pipeline` (:mod:`app.pipeline.workdir`) runs all three in one
process over a work directory.

The orders, their bandwidths, the chunk overlap and the phase reference are
those of the railway order recipe, :mod:`app.analysis.recipe` (which the
spectrogram of a km window uses too).
"""

from app.pipeline.assemble import (
    ENGINE_VERSION,
    TRACK_COLUMNS,
    RunResults,
    WheelAssembly,
    assemble,
    assemble_wheel,
    finish_assembly,
    results_meta,
    run_warnings,
    wheel_assembly,
)
from app.pipeline.chunk import PipelineCancelled, process_chunk
from app.pipeline.plan import ChunkSpec, plan_chunks
from app.pipeline.workdir import run_pipeline

__all__ = [
    "ChunkSpec",
    "RunResults",
    "PipelineCancelled",
    "plan_chunks",
    "process_chunk",
    "assemble",
    "assemble_wheel",
    "WheelAssembly",
    "wheel_assembly",
    "finish_assembly",
    "results_meta",
    "run_warnings",
    "TRACK_COLUMNS",
    "run_pipeline",
    "ENGINE_VERSION",
]
