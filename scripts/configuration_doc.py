"""Write docs/configuration.md from the settings groups (app/settings.py, GROUPS).

    .venv/bin/python scripts/configuration_doc.py          # regenerate
    .venv/bin/python scripts/configuration_doc.py --check  # exit 1 if the file is stale
"""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from app.core.config_doc import render_configuration_doc  # noqa: E402
from app.settings import GROUPS  # noqa: E402

TARGET = ROOT / "docs" / "configuration.md"


def main(argv: list[str]) -> int:
    text = render_configuration_doc(GROUPS)
    if "--check" in argv:
        if not TARGET.is_file() or TARGET.read_text(encoding="utf-8") != text:
            print(f"{TARGET.relative_to(ROOT)} is stale: run .venv/bin/python scripts/configuration_doc.py",
                  file=sys.stderr)
            return 1
        return 0
    TARGET.write_text(text, encoding="utf-8")
    print(f"wrote {TARGET.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
