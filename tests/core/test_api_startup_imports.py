"""Every API process (uvicorn, each of its workers) starts without the processing engine: the VKF
(numba), scipy.signal (which loads scipy.stats) and the weld scan load where a request first needs
them (a spectrogram: tests/pipeline/test_one_recipe.py), not at start-up. A start-up import of them
costs every service ≈ 1.3 s of CPU."""

from __future__ import annotations

import subprocess
import sys

#: modules the API's start-up must not load (the processing engine and scipy's heavy sub-packages)
ENGINE = ("numba", "scipy.signal", "scipy.stats", "scipy.interpolate", "scipy.spatial", "app.analysis.vkf",
          "app.pipeline", "app.condition.writer")


def test_the_api_starts_without_the_processing_engine():
    code = ("import sys; from app.main import create_app; create_app(); "
            f"print(' '.join(m for m in {ENGINE!r} if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120)
    assert out.stdout.split() == [], f"loaded at the API's start-up: {out.stdout.strip()}"

