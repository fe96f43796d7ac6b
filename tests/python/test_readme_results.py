"""The result sections of docs/results.md (the README's until issue 54) are generated (#37,
"tables that cannot drift"): each section between its markers is exactly what `python3 -m
bsp_fast.reproduction.readme` renders from docs/results/*.json and the table files, every
report table has one, and no typed number about the tables is left outside them."""
import re
from pathlib import Path

from bsp_fast import reproduction as R
from bsp_fast.reproduction import readme as RM

ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "docs" / "results.md"


def _sections(text: str) -> dict:
    return {m["key"]: m["body"] for m in RM.MARKER.finditer(text)}


def test_every_report_table_has_a_generated_section():
    from bsp_fast.reproduction.table_files import table_names

    keys = list(_sections(PAGE.read_text(encoding="utf-8")))
    # the report's four tables, and tables of our own (classification_batch1), each once
    assert set(R.TABLES) <= set(keys) <= set(table_names()) and len(set(keys)) == len(keys), keys


def test_results_page_sections_are_their_rendering():
    text = PAGE.read_text(encoding="utf-8")
    bad = RM.differing_sections(text, ROOT / "docs" / "results", PAGE.parent)
    assert not bad, ("docs/results.md sections differ from their rendering: "
                     + ", ".join(f"results:{k}" for k in bad)
                     + "; run: python3 -m bsp_fast.reproduction.readme")


def test_every_published_mark_recomputes_from_its_published_sums():
    """The marks the results page renders are what the current code computes from the published
    per-recording sums (``load_published``), for every published table: a change to the
    statistics that would move a mark fails here until the table is published again
    (``--with-published`` does that without the run folders)."""
    import json

    from bsp_fast.reproduction.evidence import evaluate_findings
    from bsp_fast.reproduction.table_files import load_table

    keys = ("text", "status", "difference", "interval", "p")
    published = sorted((ROOT / "docs" / "results").glob("*-quick.json"))
    checked = 0
    for path in published:
        doc = json.loads(path.read_text(encoding="utf-8"))
        if doc.get("format") != RM.FORMAT or not doc.get("per_recording"):
            continue  # not a table (coverage simulation, cross-table comparisons)
        again = evaluate_findings(load_table(doc["table"]), RM.load_published(path))
        assert [[f.get(k) for k in keys] for f in again] == \
            [[f.get(k) for k in keys] for f in doc["findings"]], path.name
        checked += 1
    assert checked >= 6  # the four tables, classification at batch 1, the ablations


def test_unpublished_tables_show_no_numbers_and_link_their_history():
    for key, body in _sections(PAGE.read_text(encoding="utf-8")).items():
        if (ROOT / "docs" / "results" / f"{key}-quick.json").is_file():
            continue
        assert "**Not run under the registered protocol yet**" in body, key
        shown = body.split("Registered protocol:")[0]  # before the registered settings
        older = (ROOT / "docs" / "results").glob(f"{key}-quick-*seeds*.md")
        history = sorted(p.name for p in older)
        assert history and all(f"(results/{h})" in shown for h in history), key
        assert not re.search(r"\d+\.\d", shown), (key, shown)  # no measured value


def test_reproduction_prose_has_no_typed_results():
    """Outside the generated sections, the results page's reproduction chapter states no
    measured value (a mean, an interval, a difference): those are rendered. (Its last
    section, a first baseline trained by hand, is not a reproduction.)"""
    text = PAGE.read_text(encoding="utf-8")
    start = text.index("## Reproducing the report\n")
    chapter = text[start:text.index("\n## A first baseline by hand", start)]
    prose = RM.MARKER.sub("", chapter)
    prose = re.sub(r"```.*?```", "", prose, flags=re.S)  # commands
    assert not re.findall(r"[±\[]\s*[−+-]?\d|\d+\.\d+ ?(?:mm|%|p\.p\.)", prose)


def test_the_command_writes_the_results_page_by_default(tmp_path, monkeypatch):
    """``python -m bsp_fast.reproduction.readme`` (no options) rewrites docs/results.md of
    the checkout it runs in, with docs/results beside it, not the README."""
    page = tmp_path / "docs" / "results.md"
    page.parent.mkdir()
    page.write_text(PAGE.read_text(encoding="utf-8"), encoding="utf-8")
    (tmp_path / "docs" / "results").symlink_to(ROOT / "docs" / "results")
    monkeypatch.chdir(tmp_path)
    assert RM.default_page() == tmp_path / "docs" / "results.md"
    assert RM.main(["--check"]) == 0
    page.write_text(page.read_text(encoding="utf-8").replace("Full table: [results/",
                                                             "Full table: [elsewhere/"),
                    encoding="utf-8")
    assert RM.main(["--check"]) == 1
    assert RM.main([]) == 0
    assert page.read_text(encoding="utf-8") == PAGE.read_text(encoding="utf-8")
