"""docs/vkf.md documents the public numerical API with runnable examples: run them.

Every fenced ``python`` block of the page is executed, in order, in one namespace (the
streaming example continues the first one); the blocks assert their own results, and the
checks below assert them again from the namespace so that a block whose ``assert`` was
edited away still fails here.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

DOC = Path(__file__).resolve().parents[2] / "docs" / "vkf.md"
_BLOCK = re.compile(r"^```python\n(.*?)^```$", re.MULTILINE | re.DOTALL)


def python_blocks(text: str) -> list[str]:
    """Source of every fenced ``python`` block of a Markdown text, in order."""
    return _BLOCK.findall(text)


def test_python_blocks_are_found() -> None:
    text = "intro\n```python\nx = 1\n```\n```text\nnot code\n```\n```python\ny = x + 1\n```\n"
    assert python_blocks(text) == ["x = 1\n", "y = x + 1\n"]


def test_docs_examples_run_and_recover_the_known_envelopes() -> None:
    blocks = python_blocks(DOC.read_text(encoding="utf-8"))
    assert len(blocks) == 2, "docs/vkf.md: the example and the streaming example"
    namespace: dict = {"__name__": "vkf_docs_example"}
    for i, source in enumerate(blocks):
        exec(compile(source, f"{DOC}:python block {i + 1}", "exec"), namespace)
    # the first example: known envelopes of both orders recovered from the noisy signal
    assert namespace["err1"] < 0.03
    assert namespace["err2"] < 0.03
    assert abs(namespace["phase2"] - 0.5) < 0.05
    assert namespace["pad"] > 0
    # the streaming example: memory-mapped in and out, equal to the single solve
    assert namespace["stream_vs_whole"] < 1e-4
    res = namespace["res"]
    assert res.amplitude.shape == (2, namespace["y"].size)
    assert np.all(np.isfinite(res.amplitude))
