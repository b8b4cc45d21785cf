"""Parsing in a child process with a time and memory budget (app.io.isolation)."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import numpy as np
import pytest

from app.io import RunFileError, ingest
from app.io.isolation import (
    Callback,
    ParseBudget,
    ParseBudgetExceeded,
    ingest_bounded,
    parse_geojson_bounded,
    run_bounded,
)
from tests.io import recorder_bytes as rb
from tests.io.conftest import base_meta

BUDGET = ParseBudget(seconds=30.0, memory_bytes=1 << 30)


def sleep_forever() -> None:
    while True:
        time.sleep(1)


def spin_forever() -> None:
    while True:
        pass


def segfault() -> None:
    os.kill(os.getpid(), signal.SIGSEGV)


def allocate(n_bytes: int) -> int:
    return int(np.ones(n_bytes // 8).sum())


def a_bug() -> None:
    return {}["missing"]


def ask_parent(lookup) -> str:  # noqa: ANN001
    return lookup("4711", "1") + "!"


def test_ingest_in_a_child_gives_what_ingest_gives(tmp_path: Path) -> None:
    src = rb.write_mdf4(tmp_path / "run.mf4", compression=1)
    here = ingest(src, None, base_meta(), tmp_path / "a.h5", channel_map=rb.CHANNEL_MAP)
    there = ingest_bounded(src, None, base_meta(), tmp_path / "b.h5", budget=BUDGET,
                           channel_map=rb.CHANNEL_MAP)
    assert there == here
    assert (tmp_path / "a.h5").read_bytes() != b"" and (tmp_path / "b.h5").stat().st_size > 0


def test_refusal_in_the_child_is_raised_unchanged(tmp_path: Path) -> None:
    bad = tmp_path / "bad.mf4"
    data = bytearray(rb.write_mdf4(tmp_path / "run.mf4").read_bytes())
    dg = rb.first(rb.mdf4_blocks(bytes(data)), "DG")
    rb.set_link(data, dg, 0, dg.offset)
    bad.write_bytes(bytes(data))
    with pytest.raises(RunFileError) as exc:
        ingest_bounded(bad, None, base_meta(), tmp_path / "o.h5", budget=BUDGET, channel_map=rb.CHANNEL_MAP)
    assert exc.value.field == "file" and "cycle" in exc.value.message
    assert not isinstance(exc.value, ParseBudgetExceeded)


@pytest.mark.parametrize("fn", [sleep_forever, spin_forever])
def test_a_parse_past_its_budget_is_killed_and_refused(fn) -> None:  # noqa: ANN001
    t0 = time.monotonic()
    with pytest.raises(ParseBudgetExceeded) as exc:
        run_bounded(fn, budget=ParseBudget(1.0, 1 << 30), what="the test file")
    assert exc.value.field == "file" and "budget of 1 s" in exc.value.message
    assert time.monotonic() - t0 < 10


def test_a_crash_is_refused_naming_the_signal() -> None:
    with pytest.raises(RunFileError) as exc:
        run_bounded(segfault, budget=BUDGET, what="the test file")
    assert exc.value.field == "file" and "SIGSEGV" in exc.value.message


def test_memory_past_the_budget_is_refused() -> None:
    assert run_bounded(allocate, (8 << 20,), budget=ParseBudget(30.0, 256 << 20), what="x") == 1 << 20
    with pytest.raises(RunFileError) as exc:
        run_bounded(allocate, (2 << 30,), budget=ParseBudget(30.0, 256 << 20), what="the test file")
    assert exc.value.field == "file" and "256 MiB of memory" in exc.value.message


def test_an_unexpected_exception_is_a_refusal_and_logged(caplog) -> None:  # noqa: ANN001
    with pytest.raises(RunFileError) as exc:
        run_bounded(a_bug, budget=BUDGET, what="the test file")
    assert exc.value.field == "file" and "KeyError" in exc.value.message
    assert any("KeyError" in r.getMessage() for r in caplog.records)


def test_callbacks_run_in_the_parent() -> None:
    seen = []

    def lookup(line: str, track: str) -> str:
        seen.append((os.getpid(), line, track))
        return f"{line}/{track}"

    out = run_bounded(ask_parent, (), {"lookup": Callback("lookup")}, budget=BUDGET, what="x",
                      callbacks={"lookup": lookup})
    assert out == "4711/1!" and seen == [(os.getpid(), "4711", "1")]


def test_geojson_in_a_child(tmp_path: Path) -> None:
    import json

    from tests.fuzz.mutations import geojson_base

    lines = parse_geojson_bounded(json.dumps(geojson_base()).encode(), budget=BUDGET)
    assert [(g.line_id, g.track) for g in lines] == [("4010", "1"), ("4010", "2")]
    with pytest.raises(RunFileError) as exc:
        parse_geojson_bounded(b"[" * 100_000, budget=BUDGET)
    assert exc.value.field == "file"


def test_budget_scales_with_the_file() -> None:
    b = ParseBudget.for_file(26_000_000, base_s=120, min_bytes_per_s=1e6, memory_bytes=1 << 32)
    assert b.seconds == pytest.approx(146.0) and b.memory_bytes == 1 << 32
    with pytest.raises(ValueError):
        ParseBudget.for_file(1, base_s=0, min_bytes_per_s=1, memory_bytes=1)


def test_a_failing_callback_is_the_parents_error_not_the_files() -> None:
    def lookup(line: str, track: str) -> str:
        raise ConnectionError("the database is gone")

    with pytest.raises(ConnectionError):
        run_bounded(ask_parent, (), {"lookup": Callback("lookup")}, budget=BUDGET, what="x",
                    callbacks={"lookup": lookup})
