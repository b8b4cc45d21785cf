"""Issue 24: a fuzz corpus of structure-aware mutations of valid MDF4, TDMS, HDF5 and GeoJSON
files, each parsed with a time limit per file. No exception but a 4xx refusal, no hang, no crash,
no accepted corrupt file (see :mod:`tests.fuzz.corpus` for the oracle).
"""

from __future__ import annotations

import collections
import os
import signal
import time
from pathlib import Path

import pytest

from app.io.errors import RunFileError
from tests.fuzz import corpus
from tests.fuzz import mutations as mu
from tests.fuzz.harness import Outcome, run_corpus

#: Least number of mutants per format (the corpus is deterministic; this guards against shrinking).
MIN_MUTANTS = {"mdf4": 650, "tdms": 150, "hdf5": 100, "geojson": 120}


@pytest.mark.timeout(600)
@pytest.mark.parametrize("fmt", corpus.FORMATS)
def test_fuzz_corpus(fmt: str, tmp_path: Path) -> None:
    result = corpus.run(fmt, tmp_path)
    kinds = collections.Counter(o.kind for _, o in result.outcomes)
    report = [f"{m.name}: {o.kind} ({why}) {o.detail[-300:]}" for m, o, why in result.failures()]
    assert report == [], f"{fmt}: {dict(kinds)}\n" + "\n".join(report)
    assert len(result.outcomes) >= MIN_MUTANTS[fmt]
    assert kinds["refused"] >= len(result.outcomes) // 10, kinds  # not a vacuous run
    slowest = max(o.seconds for _, o in result.outcomes)
    assert slowest < corpus.PER_FILE_S


# --- the harness and the oracle can fail ------------------------------------------------------


def _misbehave(path: Path) -> str:
    what = path.read_text()
    if what == "hang":
        time.sleep(3600)
    if what == "crash":
        os.kill(os.getpid(), signal.SIGSEGV)
    if what == "refuse":
        raise RunFileError("file", "refused")
    if what == "bug":
        raise KeyError("a bug")
    return what


def test_harness_reports_hangs_crashes_and_errors_and_goes_on(tmp_path: Path) -> None:
    files = []
    for k, what in enumerate(["ok", "hang", "ok", "crash", "refuse", "bug", "ok"]):
        files.append(tmp_path / f"{k}.txt")
        files[-1].write_text(what)
    t0 = time.perf_counter()
    out = run_corpus(_misbehave, files, per_file_s=1.0)
    assert [o.kind for o in out] == ["accepted", "hang", "accepted", "crash", "refused", "error", "accepted"]
    assert time.perf_counter() - t0 < 30


def test_oracle_flags_structural_changes_accepted_with_other_data() -> None:
    m_struct = mu.Mutant("base/flip-struct@1", b"x", False)
    m_value = mu.Mutant("base/flip-value@2", b"y", True)
    result = corpus.Result(
        [m_struct, m_value],
        [(m_struct, Outcome("accepted", "other", 0.1)), (m_value, Outcome("accepted", "other", 0.1))],
        {"base": "digest of the base"},
        0.2,
    )
    assert [(m.name, why) for m, _, why in result.failures()] == [
        ("base/flip-struct@1", "accepted with other data after a structural change")
    ]
    same = corpus.Result([m_struct], [(m_struct, Outcome("accepted", "digest of the base", 0.1))],
                         {"base": "digest of the base"}, 0.1)
    assert same.failures() == []
