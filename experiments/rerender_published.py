#!/usr/bin/env python3
"""Every published table re-rendered with the current statistics from its published sums
(#56, item 6; no training): for each ``docs/results/TABLE-BUDGET.json`` with its
``.per_recording.json.xz``, the cells' intervals and the findings are recomputed
(``evidence.summarise`` and ``evaluate_findings`` on ``readme.load_published``), written
back into the JSON and its ``.md``, and every mark that changes is listed.

    python experiments/rerender_published.py [--results docs/results] [--dry-run]
        [--changes docs/results/rerender_changes.md]
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


def rerender(path: Path) -> tuple:
    """``(new doc, res, found, tab)`` of one published table, recomputed."""
    from bsp_fast.reproduction import evidence as E
    from bsp_fast.reproduction import readme as RM
    from bsp_fast.reproduction.table_files import load_table

    doc = json.loads(path.read_text(encoding="utf-8"))
    tab = load_table(doc["table"])
    res = E.summarise(tab, RM.load_published(path))
    found = E.evaluate_findings(tab, res)
    for name, r in doc["results"].items():
        new = res["results"][name]
        for key in ("metrics", "std", "initial", "interval", "interval_seeds"):
            r[key] = new[key]
    doc["findings"] = [dict(f, exploratory=old.get("exploratory")) if "exploratory" in old
                       else f for f, old in zip(found, doc["findings"])]
    return doc, res, found, tab


def changes(table: str, old: list, new: list) -> list:
    """Rows of the change list: each finding whose mark (or its rule) changed."""
    out = []
    for o, n in zip(old, new):
        if (o["status"], o.get("rule")) != (n["status"], n.get("rule")):
            out.append([table, o["text"], o["status"], n["status"] + (
                f" (rule: {n['rule']})" if n.get("rule") else ""), n["ours"]])
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--results", type=Path, default=Path("docs/results"))
    p.add_argument("--dry-run", action="store_true", help="list the changes, write nothing")
    p.add_argument("--changes", type=Path, default=None, help="also write the list here")
    args = p.parse_args(argv)
    from bsp_fast.atomic import write_text
    from bsp_fast.reproduction import readme as RM
    from bsp_fast.reporting.reproduced import format_table

    rows, total = [], 0
    for path in sorted(args.results.glob("*.json")):
        doc = json.loads(path.read_text(encoding="utf-8"))
        if not isinstance(doc, dict) or doc.get("format") != RM.FORMAT \
                or not doc.get("per_recording") or "findings" not in doc:
            continue
        old = doc["findings"]
        new_doc, res, found, tab = rerender(path)
        total += len(found)
        rows += changes(doc["table"], old, found)
        if not args.dry_run:
            write_text(path, json.dumps(new_doc, indent=1, ensure_ascii=False))
            md = path.with_suffix(".md")
            if md.is_file():
                write_text(md, format_table(tab, res, found))
    lines = [f"{len(rows)} of {total} published marks change:", "",
             "| table | finding | before | now | ours, now |", "|---|---|---|---|---|"]
    lines += ["| " + " | ".join(str(c).replace("|", "/") for c in r) + " |" for r in rows]
    text = "\n".join(lines) + "\n"
    if args.changes:
        write_text(args.changes, text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
