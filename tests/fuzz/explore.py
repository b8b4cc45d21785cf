"""Run one format's fuzz corpus and print a summary (development aid, not a test).

    .venv/bin/python -m tests.fuzz.explore mdf4|tdms|hdf5|geojson
"""

from __future__ import annotations

import collections
import sys
import tempfile
from pathlib import Path

from tests.fuzz import corpus


def main(fmt: str) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        result = corpus.run(fmt, Path(tmp))
    kinds = collections.Counter(o.kind for _, o in result.outcomes)
    print(fmt, len(result.outcomes), dict(kinds), f"{result.seconds:.1f} s",
          f"max {max(o.seconds for _, o in result.outcomes):.2f} s")
    same = sum(o.kind == "accepted" and o.detail == result.base_digests[m.name.split("/")[0]]
               for m, o in result.outcomes)
    value = sum(m.value_only for m, _ in result.outcomes)
    watchdog = sum("[watchdog]" in o.detail for _, o in result.outcomes)
    print(f"  value-only mutants {value}; accepted with the base's data {same}; "
          f"accepted with other data {kinds['accepted'] - same}; refused by the watchdog {watchdog}")
    for m, o, why in result.failures():
        print("FAIL", m.name, o.kind, why, o.detail[-400:].replace("\n", " | "))


if __name__ == "__main__":
    main(sys.argv[1])
