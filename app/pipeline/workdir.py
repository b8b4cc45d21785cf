"""The whole pipeline in one process over a work directory (the ``process`` command, tests)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from app.analysis.settings import ProcessingSettings
from app.core.runstore import chunk_file_name
from app.pipeline.assemble import RunResults, assemble
from app.pipeline.chunk import process_chunk
from app.pipeline.plan import plan_chunks

__all__ = ["chunk_file_name", "run_pipeline"]


def run_pipeline(
    run_path: Path,
    settings: ProcessingSettings,
    work_dir: Path,
    progress: Callable[[float], None] | None = None,
    should_cancel: Callable[[], bool] | None = None,
) -> RunResults:
    """Plan, process (skipping chunk files that exist) and assemble a run.

    Parameters
    ----------
    run_path : Path
        Canonical run file.
    settings : ProcessingSettings
    work_dir : Path
        Directory for chunk files ``chunk-00000.npz`` …
    progress : callable, optional
        Called with the fraction of chunks done (0–1).
    should_cancel : callable, optional
        Polled between sub-blocks.
    """
    cancel = should_cancel or (lambda: False)
    chunks = plan_chunks(run_path, settings)
    work_dir = Path(work_dir)
    paths = []
    for i, chunk in enumerate(chunks):
        path = work_dir / chunk_file_name(chunk.index)
        if not path.exists():
            process_chunk(run_path, settings, chunk, path, cancel)
        paths.append(path)
        if progress is not None:
            progress((i + 1) / len(chunks))
    return assemble(run_path, settings, paths)
