"""The results page's tables, generated (issue #37, "tables that cannot drift").

``bsp-reproduce TABLE ... --publish docs/results`` copies a finished table's results into
``docs/results/TABLE-BUDGET.json`` (:func:`publish`: what the rendering needs, the
per-seed summaries, the findings, the protocol; the per-seed, per-recording sums go to the
sibling ``TABLE-BUDGET.per_recording.json.xz``, the full table to ``TABLE-BUDGET.md``).
``python3 -m bsp_fast.reproduction.readme`` rewrites every section of the results page,
``docs/results.md`` (issue #54: the README links it), between
``<!-- results:TABLE:begin -->`` and ``<!-- results:TABLE:end -->`` (``results:TABLE/BUDGET``
for another budget than quick) from those files and the table file (its budget,
findings and deviations), each section's text rendered by
:mod:`bsp_fast.reporting.results_page`; ``--check`` only says which sections differ
(exit 1).
A table without a published file gets a section that says so and points to its older
renderings (``docs/results/TABLE-BUDGET-*seeds.md``) as history, with no numbers.
(The module keeps its name, ``readme``, and its functions theirs: the command and the
API are those the README's sections were rendered with.)
"""
from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

from ..atomic import write_bytes, write_text
from ..reporting.results_page import section_text
from .protocol import portable_options, table_hash
from .table_files import load_table

__all__ = ["FORMAT", "SUMS_SUFFIX", "MARKER", "PAGE", "default_page", "published_path",
           "publish", "read_sums", "load_published", "render_section", "render_readme",
           "differing_sections", "main"]

FORMAT = 1
#: the per-recording sums beside a published table: TABLE-BUDGET.per_recording.json.xz
SUMS_SUFFIX = "per_recording.json.xz"
#: a section's markers; the budget is quick unless named (``results:lifting/full``)
MARKER = re.compile(r"<!-- results:(?P<key>(?P<table>[\w.-]+)(?:/(?P<budget>\w+))?):begin -->\n"
                    r"(?P<body>.*?)<!-- results:(?P=key):end -->", re.S)
_ROW_KEYS = ("label", "report", "initial_of", "crop_box", "data_suffix")


def published_path(results_dir, table: str, budget: str) -> Path:
    return Path(results_dir) / f"{table}-{budget}.json"


def portable(path) -> str:
    """``path`` as a published file names it: relative to the working directory (the
    repository the experiments run from) when inside it, else its last component (a
    run folder's ``TABLE-BUDGET``), never this machine's absolute path."""
    return _rel(path, Path.cwd())


def portable_command(script: str, argv) -> str:
    """The command line of an ``experiments/`` script with its path arguments (existing
    or absolute ones) :func:`portable`."""
    import os

    return " ".join(["python3", script, *(portable(a) if os.path.isabs(a) or
                                          os.path.exists(a) else a for a in argv)])


def _rel(path, base: Path):
    """``path`` relative to the table's run folder (a published file names no machine's
    paths)."""
    if not path:
        return path
    try:
        return str(Path(path).resolve().relative_to(base.resolve()))
    except ValueError:
        return Path(path).name


def _per_recording(tab: dict, doc: dict) -> dict:
    """``{row: {seed: the run's test_per_recording.json}}``, only the table's metrics
    (and classification's constant answer, which a ``fails`` finding reads)."""
    keep = set(tab["metrics"]) | {"f1_constant"}
    out = {}
    for name, r in doc["results"].items():
        if r.get("source") == "initial":
            continue  # its sums are its source row's "initial" section
        for seed, s in r["seeds"].items():
            if not s.get("per_recording"):
                continue
            d = s["per_recording"]  # read back from a published table (.restore), or a file
            d = dict(d) if isinstance(d, dict) else json.loads(
                Path(d).read_text(encoding="utf-8"))
            for section in ("test", "initial"):
                if d.get(section):
                    d[section] = dict(d[section], metrics={
                        k: v for k, v in d[section]["metrics"].items() if k in keep})
            out.setdefault(name, {})[seed] = d
    return out


def _portable_protocol(protocol: dict) -> dict:
    """The protocol record without a machine's paths: the table file's and the datasets'
    names (:func:`.protocol.portable_options`)."""
    runs = {n: dict(r, options=portable_options(r.get("options") or {})) if isinstance(r, dict)
            else r for n, r in (protocol.get("runs") or {}).items()}
    return dict(protocol, table_file=Path(protocol["table_file"]).name,
                options=portable_options(protocol.get("options") or {}), runs=runs)


def publish(tab: dict, run_folder, results_dir) -> Path:
    """Copies the finished table of ``run_folder`` (``OUT/TABLE-BUDGET``: its results.json,
    results.md and the runs' per-recording sums) into ``results_dir``; returns the JSON's
    path. ValueError when the folder holds no results or results without a protocol
    record (made before the protocol was registered)."""
    base = Path(run_folder)
    src = base / "results.json"
    if not src.is_file():
        raise ValueError(f"{src}: no results to publish (run the table first)")
    doc = json.loads(src.read_text(encoding="utf-8"))
    if not doc.get("protocol"):
        raise ValueError(f"{src}: no protocol record (made before bsp-reproduce recorded "
                         "the table file's hash); run the table again to publish it")
    results = {}
    for name, r in doc["results"].items():
        r = dict(r, seeds={k: dict(s, run=_rel(s.get("run"), base), per_recording=None)
                           for k, s in r["seeds"].items()})
        results[name] = r
    budget = doc["budget"]
    stem = f"{tab['table']}-{budget}"
    data = doc.get("data")
    if data and Path(data).is_absolute():  # a machine's path: the folder's name only
        data = Path(data).name
    protocol = _portable_protocol(doc["protocol"])
    sums = _per_recording(tab, doc)
    out = {"format": FORMAT, "table": tab["table"], "budget": budget, "title": tab["title"],
           "task": tab["task"], "metrics": tab["metrics"],
           "budget_rule": tab.get("budget_rule"), "budget_options": tab["budgets"][budget],
           "rows": [{"name": r["name"], **{k: r[k] for k in _ROW_KEYS if k in r}}
                    for r in tab["rows"]],
           "finding_specs": tab["findings"], "data": data, "seeds": doc["seeds"],
           "split_seeds": doc.get("split_seeds", False), "protocol": protocol,
           "results": results, "findings": doc["findings"],
           "per_recording": f"{stem}.{SUMS_SUFFIX}" if sums else None}
    results_dir = Path(results_dir)
    results_dir.mkdir(parents=True, exist_ok=True)
    write_text(results_dir / f"{stem}.json", json.dumps(out, indent=1, ensure_ascii=False))
    if sums:  # the numbers only, for an independent re-computation
        write_bytes(results_dir / f"{stem}.{SUMS_SUFFIX}", _compressed(sums))
    if (base / "results.md").is_file():
        write_text(results_dir / f"{stem}.md", (base / "results.md").read_text(encoding="utf-8"))
    return results_dir / f"{stem}.json"


def _compressed(sums: dict) -> bytes:
    import lzma

    # the sums name every test recording per seed and score every clip: xz keeps a
    # 10-seed table at 415 recordings near 2 MB instead of 14
    return lzma.compress(json.dumps(sums, separators=(",", ":")).encode("utf-8"),
                         preset=9)


def read_sums(path) -> dict:
    """A published table's per-recording sums: the JSON file its ``per_recording`` names,
    xz-compressed when the name ends in ``.xz`` (tables published before 2026-11-29 in git's
    history are plain JSON). ValueError naming the file when it cannot be read."""
    import lzma

    path = Path(path)
    try:
        data = path.read_bytes()
        return json.loads(lzma.decompress(data) if path.suffix == ".xz" else data)
    except (OSError, ValueError, lzma.LZMAError) as e:
        raise ValueError(f"{path}: cannot read the table's sums ({e})") from e


def load_published(path) -> dict:
    """A published table (``TABLE-BUDGET.json``) read back as a ``results.json``: each
    seed's ``per_recording`` holds its sums from the sibling file the table names
    (:func:`read_sums`, already read), so that :mod:`.evidence` recomputes intervals and
    re-run differences from a published table whose run folder is gone (another
    machine's). ValueError when the file is not a published table of this format or its
    sums are missing."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as e:
        raise ValueError(f"{path}: cannot read a published table ({e})") from e
    if not isinstance(doc, dict) or doc.get("format") != FORMAT or "results" not in doc:
        raise ValueError(f"{path}: not a published table of format {FORMAT} "
                         "(bsp-reproduce ... --publish writes them)")
    if not doc.get("per_recording"):
        raise ValueError(f"{path}: published without per-recording sums")
    sums = read_sums(path.parent / Path(doc["per_recording"]).name)
    for name, r in doc["results"].items():
        src = r.get("run_of") or name  # a row read from another row's trivial baseline
        for seed, s in r["seeds"].items():
            s["per_recording"] = sums.get(src, {}).get(seed)
    return doc


# ---------------------------------------------------------------------- the page
def render_section(table: str, budget: str, results_dir, readme_dir) -> str:
    """The text between one section's markers (starting and ending with a newline): what
    the section needs read here (the table file, its published results, its protocol
    hash today, its full table and older renderings) and rendered by
    :func:`bsp_fast.reporting.results_page.section_text`."""
    results_dir = Path(results_dir)
    tab = load_table(table)
    path = published_path(results_dir, table, budget)
    doc = None
    if path.is_file():
        doc = json.loads(path.read_text(encoding="utf-8"))
        if doc.get("format") != FORMAT:
            raise ValueError(f"{path}: format {doc.get('format')!r}, this renderer reads "
                             f"{FORMAT}; publish it again (bsp-reproduce ... --publish)")
    now = table_hash(tab["path"])
    full = path.with_suffix(".md")
    history = [] if doc is not None else sorted(
        results_dir.glob(f"{tab['table']}-{budget}-*seeds*.md"))
    return section_text(tab, budget, doc=doc, published=path, now=now,
                        full=full if full.is_file() else None, history=history,
                        page_dir=readme_dir)


def render_readme(text: str, results_dir, readme_dir) -> tuple:
    """``(new text, [section keys])``: every marked section rendered."""
    keys = []

    def one(m):
        keys.append(m["key"])
        body = render_section(m["table"], m["budget"] or "quick", results_dir, readme_dir)
        return f"<!-- results:{m['key']}:begin -->{body}<!-- results:{m['key']}:end -->"
    return MARKER.sub(one, text), keys


def differing_sections(text: str, results_dir, readme_dir) -> list:
    """The keys of the sections whose text differs from their rendering."""
    new, _ = render_readme(text, results_dir, readme_dir)
    old = {m["key"]: m["body"] for m in MARKER.finditer(text)}
    return [m["key"] for m in MARKER.finditer(new) if old.get(m["key"]) != m["body"]]


#: the generated page, relative to the source tree (and to the working directory)
PAGE = Path("docs") / "results.md"


def default_page() -> Path:
    """``docs/results.md`` of the working directory when it has one (a checkout, with the
    package installed from it), else of the source tree this module sits in."""
    for base in (Path.cwd(), Path(__file__).resolve().parents[3]):
        if (base / PAGE).is_file():
            return base / PAGE
    return Path(__file__).resolve().parents[3] / PAGE


def main(argv=None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m bsp_fast.reproduction.readme",
        description="Rewrite the result sections of docs/results.md (between <!-- "
                    "results:TABLE:begin --> and <!-- results:TABLE:end -->) from "
                    "docs/results/TABLE-BUDGET.json and the table files. Exit codes: 0 done "
                    "(or, with --check, up to date), 1 --check found sections that differ, "
                    "2 bad input.")
    p.add_argument("--page", dest="page", default=None, metavar="FILE",
                   help="the page to rewrite (default: docs/results.md of the working "
                        "directory, else of the source tree)")
    p.add_argument("--results", default=None, metavar="DIR",
                   help="published results (default: results/ beside the page, "
                        "docs/results)")
    p.add_argument("--check", action="store_true",
                   help="change nothing; list the sections that differ from their rendering")
    ns = p.parse_args(argv)
    page = Path(ns.page) if ns.page else default_page()
    results = Path(ns.results) if ns.results else page.parent / "results"
    try:
        text = page.read_text(encoding="utf-8")
        if ns.check:
            bad = differing_sections(text, results, page.parent)
            for key in bad:
                print(f"{page}: section results:{key} differs from its rendering")
            return 1 if bad else 0
        new, keys = render_readme(text, results, page.parent)
    except (OSError, ValueError) as exc:
        print(f"readme: {exc}", file=sys.stderr)
        return 2
    if not keys:
        print(f"readme: {page} has no <!-- results:TABLE:begin --> section", file=sys.stderr)
        return 2
    if new != text:
        write_text(page, new)
    print(f"{page}: {len(keys)} section(s) rendered ({', '.join(keys)})"
          + ("" if new != text else "; unchanged"))
    return 0

if __name__ == "__main__":
    sys.exit(main())
