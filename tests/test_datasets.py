"""The tests' data set cache (tests/datasets.py): built once per key, read back as built, a failed
build leaves nothing, another code digest's data sets are removed."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.datasets import DatasetCache, code_digest

CALLS: list[str] = []


def _build(root: Path) -> dict:
    CALLS.append(str(root))
    (root / "data.txt").write_text("made by the build")
    return {"file": root / "data.txt", "n": len(CALLS)}


def _other_build(root: Path) -> int:
    return 7


def _failing(root: Path) -> None:
    (root / "half.txt").write_text("half written")
    raise RuntimeError("the build failed")


def test_a_data_set_is_built_once_and_read_back_as_built(tmp_path: Path) -> None:
    CALLS.clear()
    cache = DatasetCache(tmp_path / "cache")
    first = cache.get("demo", {"a": 1}, _build)
    again = DatasetCache(tmp_path / "cache").get("demo", {"a": 1}, _build)  # a later session
    assert first == again and len(CALLS) == 1
    assert first["file"].read_text() == "made by the build"
    assert first["file"].parent == cache.path("demo", {"a": 1}, _build)
    assert first["file"].parent.parent == tmp_path / "cache" / code_digest()


def test_the_key_holds_kind_spec_and_build(tmp_path: Path) -> None:
    CALLS.clear()
    cache = DatasetCache(tmp_path)
    cache.get("demo", {"a": 1}, _build)
    cache.get("demo", {"a": 2}, _build)
    cache.get("other", {"a": 1}, _build)
    assert len(CALLS) == 3
    assert cache.key("demo", {"a": 1}, _build) != cache.key("demo", {"a": 1}, _other_build)
    assert cache.key("demo", {"a": 1, "b": 2}, _build) == cache.key("demo", {"b": 2, "a": 1}, _build)
    with pytest.raises(ValueError, match="kind"):
        cache.key("../x", {}, _build)


def test_a_failed_build_leaves_nothing_and_is_retried(tmp_path: Path) -> None:
    cache = DatasetCache(tmp_path)
    with pytest.raises(RuntimeError, match="build failed"):
        cache.get("broken", {}, _failing)
    assert not (cache.directory / cache.key("broken", {}, _failing)).exists()
    with pytest.raises(RuntimeError, match="build failed"):
        cache.get("broken", {}, _failing)


def test_data_sets_of_another_code_digest_are_removed(tmp_path: Path) -> None:
    stale = tmp_path / "0123456789abcdef" / "demo-x"
    stale.mkdir(parents=True)
    cache = DatasetCache(tmp_path)
    assert cache.get("small", {}, _other_build) == 7
    assert not stale.parent.exists()
    assert sorted(p.name for p in tmp_path.iterdir() if p.is_dir()) == [code_digest()]
