#!/usr/bin/env python3
"""How many confirmatory comparisons each table decides, before and after its re-run under
the registered design (issue #57), beside what the power table predicted for both designs.

*Before* is the table as last published under another protocol hash (the newest version of
``docs/results/TABLE-quick.json`` in git whose hash differs from the one published now),
*after* the table published now; both are recomputed here with the current statistics from
their published per-recording sums (``evidence.summarise`` and ``evaluate_findings``), so
the two differ by their runs only. A comparison is decided when its mark is reproduced or
not reproduced (Holm-adjusted p below 0.05 and no rule holding it inconclusive). The
predictions count the comparisons at 80 % power or more in the table file's
``design.power`` (``power_now``: at the published sizes; ``power``: at the registered
design; experiments/design_power.py).

    python experiments/decided_fraction.py [--results docs/results] [--write] [TABLE ...]
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

TABLES = ("autoencoder", "lifting", "classification", "classification_batch1")
DECIDED = ("reproduced", "not reproduced")
POWER = 0.8


def decided(path: Path) -> dict:
    """``{"comparisons", "decided", "seeds", "recordings", "hash", "undecided"}`` of one
    published table, its findings recomputed from its sums."""
    from bsp_fast.reproduction import evidence as E
    from bsp_fast.reproduction import readme as RM
    from bsp_fast.reproduction.protocol import confirmatory
    from bsp_fast.reproduction.table_files import load_table

    doc = RM.load_published(path)
    tab = load_table(doc["table"])
    found = E.evaluate_findings(tab, E.summarise(tab, doc))
    marks = [(found[i]["text"], m) for i in confirmatory(tab) for m in found[i].get("marks", [])]
    seeds = sorted({len(r["seeds"]) for r in doc["results"].values()})
    return {"comparisons": len(marks), "decided": sum(m in DECIDED for _, m in marks),
            "undecided": sorted({t for t, m in marks if m not in DECIDED}),
            "seeds": seeds, "recordings": max(f.get("recordings") or 0 for f in found),
            "hash": doc["protocol"]["hash"][:12]}


def _git(root: Path, *args) -> bytes:
    return subprocess.run(["git", "-C", str(root), *args], check=True,
                          capture_output=True).stdout


def before(results: Path, table: str, into: Path) -> tuple:
    """``(path, commit)``: the newest committed version of the table published under
    another protocol hash than now, with its sums, written into ``into``; or (None, None)."""
    root = Path(_git(results, "rev-parse", "--show-toplevel").decode().strip())
    rel = (results / f"{table}-quick.json").resolve().relative_to(root)
    now = json.loads((results / rel.name).read_text(encoding="utf-8"))["protocol"]["hash"]
    for commit in _git(root, "log", "--format=%H", "--", str(rel)).decode().split():
        doc = json.loads(_git(root, "show", f"{commit}:{rel}"))
        if doc["protocol"]["hash"] == now:
            continue
        sums = rel.with_name(Path(doc["per_recording"]).name)
        (into / sums.name).write_bytes(_git(root, "show", f"{commit}:{sums}"))
        out = into / rel.name
        out.write_text(json.dumps(doc), encoding="utf-8")
        return out, commit[:7]
    return None, None


def predicted(table: str) -> dict:
    """Comparisons at 80 % power or more at the published and at the registered design."""
    from bsp_fast.reproduction.table_files import load_table

    found = load_table(table).get("design", {}).get("power", {}).get("findings", [])
    return {"published": sum(f["power_now"] >= POWER for f in found),
            "registered": sum(f["power"] >= POWER for f in found), "of": len(found)}


def table_row(results: Path, table: str) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        old, commit = before(results, table, Path(tmp))
        was = decided(old) if old else None
    return {"table": table, "before": was, "before_commit": commit,
            "after": decided(results / f"{table}-quick.json"), "predicted": predicted(table)}


def _design(d: dict) -> str:
    seeds = "/".join(str(s) for s in d["seeds"])
    return f"{seeds} seeds x {d['recordings']} recordings, hash {d['hash']}"


def render(rows: list) -> str:
    lines = ["| table | before: decided | before: design | predicted (published design) "
             "| after: decided | after: design | predicted (registered design) "
             "| undecided after |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        b, a, p = r["before"], r["after"], r["predicted"]
        lines.append(" | ".join([
            f"| {r['table']}", f"{b['decided']} of {b['comparisons']}" if b else "–",
            f"{_design(b)} ({r['before_commit']})" if b else "–",
            f"{p['published']} of {p['of']}", f"{a['decided']} of {a['comparisons']}",
            _design(a), f"{p['registered']} of {p['of']}",
            "; ".join(a["undecided"]).replace("|", "/") or "none"]) + " |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("tables", nargs="*", default=list(TABLES))
    p.add_argument("--results", type=Path, default=Path("docs/results"))
    p.add_argument("--write", action="store_true",
                   help="also write RESULTS/decided_fraction.{md,json}")
    args = p.parse_args(argv)
    rows = [table_row(args.results, t) for t in args.tables]
    text = render(rows)
    print(text)
    if args.write:
        from bsp_fast.atomic import write_text
        write_text(args.results / "decided_fraction.json", json.dumps(rows, indent=1))
        write_text(args.results / "decided_fraction.md", __doc__.split("\n\n")[0] + "\n\n"
                   + "Generated by `python3 experiments/decided_fraction.py --write`.\n\n" + text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
