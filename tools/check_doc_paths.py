#!/usr/bin/env python3
"""Checks that every file or folder a Markdown page names in `backticks` exists.

    python tools/check_doc_paths.py docs/architecture.md [more pages]

A name counts as a path when it has a '/' or ends in a source/doc suffix (placeholders
such as `cpp/src/<stage>/` are skipped). It is looked up from the repository root, then
under cpp/include/ (`bsp/csv/csv.hpp`), cpp/include/bsp/ and cpp/src/ (tables name
`stage/file`), python/ and python/bsp_fast/ (module tables name `data/`), then, for a bare
file name, anywhere under cpp/, python/ and tests/. Meant for pages whose code-formatted
names with a '/' are files (docs/architecture.md), not HDF5 dataset paths.
Exit status 1 lists the missing ones.
"""
from __future__ import annotations

import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SUFFIXES = (".py", ".cpp", ".hpp", ".md", ".toml", ".txt", ".yaml")


def candidates(text: str) -> list[str]:
    names = []
    for token in re.findall(r"`([^`\s]+)`", text):
        token = token.rstrip(".,:;")
        # build/...: made by the build, not in a fresh clone
        if token.startswith(("bsp_fast.", "bsp::", "-", "$", "build/")) \
                or any(c in token for c in "(*<="):
            continue
        if "/" in token or token.endswith(SUFFIXES):
            names.append(token)
    return names


def exists(name: str) -> bool:
    if name.startswith("../"):
        return False
    bases = (ROOT, ROOT / "cpp" / "include", ROOT / "cpp" / "include" / "bsp",
             ROOT / "cpp" / "src", ROOT / "python", ROOT / "python" / "bsp_fast")
    for base in bases:
        if (base / name).exists():
            return True
    if "/" not in name:
        return any(any((ROOT / top).rglob(name)) for top in ("cpp", "python", "tests"))
    return False


def main(argv=None) -> int:
    pages = list(sys.argv[1:] if argv is None else argv) or ["docs/architecture.md"]
    missing = []
    for page in pages:
        for name in candidates((ROOT / page).read_text(encoding="utf-8")):
            if not exists(name):
                missing.append(f"{page}: {name}")
    for m in missing:
        print(m)
    return 1 if missing else 0


if __name__ == "__main__":
    sys.exit(main())
