"""The registered protocol of bsp-reproduce (#37, items 3-4): the table file's hash (of its
parsed content without deviations), the code and the time recorded in results.json; runs of
another hash refused (exit 2, nothing written) unless --allow-changed, which is recorded
and printed; deviations checked and printed; exploratory findings labelled, never bold,
outside the confirmatory family; a published table rendered into a README section.

One smoke run of a one-row table (a small SimpleTransformer, 1 epoch of 2 batches) serves
every test that needs runs; the other changes only read or refuse it."""
from __future__ import annotations

import contextlib
import datetime as dt
import hashlib
import io
import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
import yaml

from bsp_fast import reproduction as R
from bsp_fast.data.testing import write_clip_file
from bsp_fast.reproduction import protocol as P
from bsp_fast.reproduction import readme as RM
from bsp_fast.reporting.results_page import findings_table

pytestmark = pytest.mark.usefixtures("one_torch_thread")

ROOT = Path(__file__).resolve().parents[2]
HAS_GIT = (ROOT / ".git").exists() and shutil.which("git") is not None


def _git(*args) -> str:
    return subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True,
                          check=True).stdout.strip()


def _tiny_doc(name: str = "tiny_ae") -> dict:
    """The autoencoder table cut to one row and a small model, with a confirmatory and an
    exploratory finding."""
    doc = yaml.safe_load((ROOT / "experiments" / "autoencoder.yaml").read_text())
    doc.pop("deviations", None)
    doc["table"] = name
    doc["common"]["hp"] = {"num_layers": 1, "dim_feedforward": 32}
    doc["rows"] = doc["rows"][:1]
    doc["findings"] = [
        {"kind": "at_least", "metric": "pck_0.05", "row": "clean", "value": 0.95,
         "text": "clean inputs are learnt almost perfectly"},
        {"kind": "at_least", "metric": "pck_0.05", "row": "clean", "value": 0.0,
         "text": "clean PCK above zero", "exploratory": True}]
    return doc


def _write(path: Path, doc: dict) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def _main(argv) -> tuple:
    """``(exit code, stdout, stderr)`` of bsp-reproduce."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = R.main([str(a) for a in argv])
    return code, out.getvalue(), err.getvalue()


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    """The tiny table run once at the smoke budget and published."""
    root = tmp_path_factory.mktemp("protocol")
    data = root / "l30.h5"
    write_clip_file(data, clips=(24, 12, 12), clip_length=30, seed=2)
    table = _write(root / "experiments" / "tiny_ae.yaml", _tiny_doc())
    argv = [table, "--data", data, "--budget", "smoke", "--out", root / "runs"]
    code, text, err = _main(argv + ["--publish", root / "docs" / "results"])
    assert code == 0, err
    base = root / "runs" / "tiny_ae-smoke"
    return {"root": root, "table": table, "argv": argv, "text": text, "base": base,
            "results": json.loads((base / "results.json").read_text()),
            "results_dir": root / "docs" / "results"}


# ---------------------------------------------------------------------- the hash
def test_hash_is_of_the_parsed_content_without_deviations(tmp_path):
    a = tmp_path / "a.yaml"
    a.write_text("b: 1\na: [x, 2]\n")
    # by hand: the canonical JSON of {"b": 1, "a": ["x", 2]}
    want = hashlib.sha256(b'{"a":["x",2],"b":1}').hexdigest()
    assert P.table_hash(a) == want
    a.write_text("# a comment\na:\n  - x\n  - 2\nb: 1   # layout and comments do not count\n"
                 "deviations:\n  - {what: w}\n")
    assert P.table_hash(a) == want
    a.write_text("b: 2\na: [x, 2]\n")
    assert P.table_hash(a) != want


@pytest.mark.skipif(not HAS_GIT, reason="not a git checkout")
def test_code_version_is_the_checkout_commit():
    import bsp_fast

    code = P.code_version()
    if ROOT not in Path(bsp_fast.__file__).resolve().parents:  # installed (make test)
        assert code == {"version": bsp_fast.__version__}
        return
    assert code["commit"] == _git("rev-parse", "HEAD")
    assert code["dirty"] == bool(_git("status", "--porcelain", "--untracked-files=no"))


# ---------------------------------------------------------------------- deviations
GOOD = {"what": "quick epochs 15 -> 25", "when": "2026-11-23", "commit": "38006fb",
        "why": "under-trained", "seen_test_numbers": True}


@pytest.mark.parametrize("change, message", [
    ({"why": None}, r"deviation 1: missing \['why'\]"),
    ({"who": "me"}, r"deviation 1: unknown \['who'\]"),
    ({"when": "23/11/2026"}, "deviation 1: when must be a date"),
    ({"commit": 1234567}, "deviation 1: commit must be a commit id .*quoted"),
    ({"commit": "not-hex"}, "deviation 1: commit must be a commit id"),
    ({"seen_test_numbers": "maybe"}, "deviation 1: seen_test_numbers must be yes or no"),
    ({"what": " "}, "deviation 1: what must be a non-empty text"),
])
def test_deviations_are_checked_on_load(tmp_path, change, message):
    entry = {k: v for k, v in {**GOOD, **change}.items() if v is not None}
    path = _write(tmp_path / "t.yaml", dict(_tiny_doc(), deviations=[entry]))
    with pytest.raises(ValueError, match=f"{path}: {message}"):
        R.load_table(path)


def test_deviations_and_exploratory_fields_load(tmp_path):
    doc = _tiny_doc()
    entry = dict(GOOD, when=dt.date(2026, 11, 23))  # as YAML reads an unquoted date
    path = _write(tmp_path / "t.yaml", dict(doc, deviations=[entry]))
    assert R.load_table(path)["deviations"] == [GOOD]  # a YAML date, as text
    _write(path, dict(doc, deviations={"what": "x"}))
    with pytest.raises(ValueError, match="deviations must be a list"):
        R.load_table(path)
    doc["findings"][1]["exploratory"] = "yes please"
    _write(path, doc)
    with pytest.raises(ValueError, match="finding 'clean PCK above zero': exploratory must be "
                                         "true or false"):
        R.load_table(path)


# (0447a88 and 65ff54b: the float32 pin of the quick budgets, the registered designs and
# the pose rows moved to the full budget, issue 57)
RECORDED = {"autoencoder": ["38006fb", "0904e51", "0447a88"],
            "classification": ["0904e51", "f2d3e8e", "0447a88"],
            "lifting": ["0904e51", "f2d3e8e", "2363a0b", "0447a88"],
            "pose_estimation": ["0904e51", "f053164", "047d609", "b175e10", "8ed698f",
                                 "c341cd6", "346e0a0", "0217f14", "7ea171e", "65ff54b"]}


@pytest.mark.parametrize("table", R.TABLES)
def test_the_known_deviations_are_recorded(table):
    tab = R.load_table(table)
    assert [d["commit"] for d in tab["deviations"]] == RECORDED[table]
    assert all(d["seen_test_numbers"] for d in tab["deviations"])
    exploratory = [f["text"] for f in tab["findings"] if f.get("exploratory")]
    assert exploratory == (["ours: the crop model beats the average skeleton (PCK@0.05, any "
                            "margin)"] if table == "pose_estimation" else [])
    if not HAS_GIT:
        return
    for d in tab["deviations"]:  # the date is the commit's, and it changed this table file
        assert _git("show", "-s", "--format=%cd", "--date=short", d["commit"]) == d["when"]
        assert f"experiments/{table}.yaml" in _git("show", "--stat", "--format=", d["commit"])
        seen = _git("show", "-s", "--format=%ct", d["seen_in"])  # numbers seen: earlier
        assert int(seen) < int(_git("show", "-s", "--format=%ct", d["commit"]))


# ---------------------------------------------------------------------- a run, recorded
def test_results_record_the_hash_commit_and_time(finished):
    prot = finished["results"]["protocol"]
    want = P.table_hash(finished["table"])
    assert (prot["hash"], prot["hashed"], prot["mixed"], prot["options"],
            prot["allow_changed"]) == (want, P.HASHED, {}, {}, False)
    assert prot["code"] == P.code_version()
    made = dt.datetime.strptime(prot["utc"], "%Y-%m-%dT%H:%M:%SZ").replace(tzinfo=dt.timezone.utc)
    assert dt.timedelta(0) <= dt.datetime.now(dt.timezone.utc) - made < dt.timedelta(hours=1)
    assert prot["runs"]["clean/seed-22742"]["hash"] == want
    ledger = json.loads((finished["base"] / P.LEDGER).read_text())
    assert ledger["runs"]["clean/seed-22742"] == prot["runs"]["clean/seed-22742"]
    assert f"Registered protocol: `tiny_ae.yaml` sha256 {want[:12]}" in finished["text"]


def test_exploratory_findings_are_labelled_never_bold_and_outside_the_family(finished):
    found = finished["results"]["findings"]
    assert [f["exploratory"] for f in found] == [False, True]
    row = next(ln for ln in finished["text"].splitlines() if "clean PCK above zero" in ln)
    assert row.startswith("| exploratory (added after results were seen") and "**" not in row
    tab = R.load_table(finished["table"])
    assert P.confirmatory(tab) == [0]
    pose = R.load_table("pose_estimation")
    # the "any margin" one (3) is out
    assert P.confirmatory(pose) == [0, 1, 2] + list(range(4, 23))
    # the README's findings table: a decided confirmatory mark bold, an exploratory not
    marks = [dict(f, status="reproduced", rule=None) for f in found]
    lines = findings_table(marks).splitlines()[2:]
    assert lines[0].endswith("| **reproduced** |")
    assert lines[1].endswith("| reproduced |") and "**" not in lines[1]
    assert "exploratory (added after results were seen" in lines[1]


def _synthetic_seeds(tmp_path, tab) -> dict:
    """5 seeds of two rows on 12 recordings, 'clean' about 0.1 above 'noisy'."""
    rng = np.random.default_rng(3)
    den = rng.integers(200, 400, 12).astype(float)
    recs = [f"v{i}/p0" for i in range(12)]
    results = {}
    for row, level in (("clean", 0.8), ("noisy", 0.7)):
        seeds = {}
        for seed in range(5):
            num = np.clip(level + rng.normal(0, 0.03) + rng.normal(0, 0.02, 12), 0, 1) * den
            part = {"recordings": recs, "metrics": {"pck_0.05": {"num": num.tolist(),
                                                                  "den": den.tolist()}}}
            path = tmp_path / f"{row}-{seed}.json"
            path.write_text(json.dumps({"test": part, "initial": part,
                                        "empty": {"pck_0.05": None}}))
            value = float(num.sum() / den.sum())
            seeds[str(seed)] = {"metrics": {"pck_0.05": value}, "initial": {"pck_0.05": value},
                                "per_recording": str(path), "epochs": 1, "best_epoch": 1,
                                "seconds": {}}
        results[row] = {"seeds": seeds, "source": "test"}
    return {"budget": "quick", "seeds": list(range(5)), "split_seeds": False,
            "results": results}


def test_holm_family_leaves_out_exploratory_findings(tmp_path):
    """Holm runs over the confirmatory findings (protocol.confirmatory); an exploratory one
    does not enlarge that family and is adjusted only among the exploratory ones."""
    doc = _tiny_doc()
    doc["rows"].append({"name": "noisy", "label": "noisy", "options": {"noise": 5, "mjp": 0.2944}})
    compare = {"kind": "compare", "metric": "pck_0.05", "a": "clean", "b": "noisy",
               "relation": ">"}
    doc["findings"] = [dict(compare, text="clean beats noisy"),
                       {"kind": "at_least", "metric": "pck_0.05", "row": "clean",
                        "value": 0.5, "text": "clean above 50 %"},
                       dict(compare, text="clean beats noisy, chosen later", exploratory=True)]
    tab = R.load_table(_write(tmp_path / "t.yaml", doc))
    res = _synthetic_seeds(tmp_path, tab)
    from bsp_fast.reproduction import evidence

    evidence.summarise(tab, res)
    found = evidence.evaluate_findings(tab, res)
    p = [f["p"][0] for f in found]
    # Holm over the confirmatory two, by hand: smaller p times 2, the larger at least that
    lo, hi = sorted(p[:2])
    adj = {lo: min(1.0, 2 * lo), hi: min(1.0, max(2 * lo, hi))}
    assert [f["p_holm"][0] for f in found[:2]] == pytest.approx([adj[p[0]], adj[p[1]]])
    assert found[2]["p_holm"][0] == pytest.approx(p[2])  # alone in its own family


# ---------------------------------------------------------------------- changes
def test_deviations_appended_later_keep_the_hash_and_are_printed(finished, tmp_path):
    doc = _tiny_doc()
    doc["deviations"] = [dict(GOOD, what="an example deviation, appended after the runs")]
    table = _write(tmp_path / "tiny_ae.yaml", doc)
    assert P.table_hash(table) == P.table_hash(finished["table"])
    argv = list(finished["argv"])
    argv[0] = table
    code, text, err = _main(argv)
    assert code == 0, err
    assert "[clean seed 22742] reusing" in text  # no training
    assert ("- 2026-11-23, commit 38006fb, after test numbers were seen: an example "
            "deviation, appended after the runs Why: under-trained") in text
    saved = (finished["base"] / "results.md").read_text()
    assert "Deviations from the registered protocol:" in saved


def test_a_test_set_is_recorded_by_its_folder_not_the_machines_path(tmp_path):
    """A run recorded with --set test_data=/a/path continues (and is published) under the
    folder's name: the same registered test set on another disk is the same protocol."""
    tab = R.load_table("lifting")
    base = tmp_path / "lifting-quick"
    base.mkdir()
    old = {"hash": P.table_hash(tab["path"]), "options": {"test_data": "/tmp/x/medium-t1"},
           "code": {}, "utc": "2026-11-29T00:00:00Z"}
    (base / P.LEDGER).write_text(json.dumps({"runs": {"lstm/seed-1": old}}))
    prot, _ = P.guard(base, tab, "quick", ["lstm/seed-1"], {"test_data": "/other/medium-t1"})
    assert prot["options"] == {"test_data": "medium-t1"} and prot["mixed"] == {}
    with pytest.raises(P.ProtocolChanged):
        P.guard(base, tab, "quick", ["lstm/seed-1"], {"test_data": "/tmp/x/medium-t2"})
    published = RM._portable_protocol(dict(prot, table_file=str(tab["path"]),
                                           runs={"lstm/seed-1": old}))
    assert (published["options"], published["runs"]["lstm/seed-1"]["options"],
            published["table_file"]) == ({"test_data": "medium-t1"},
                                         {"test_data": "medium-t1"}, "lifting.yaml")


def test_a_changed_table_refuses_to_mix_unless_allowed(finished, tmp_path):
    base, old = finished["base"], P.table_hash(finished["table"])
    doc = _tiny_doc()
    doc["budgets"]["smoke"]["batch_size"] = 8  # a protocol change after results exist
    table = _write(tmp_path / "tiny_ae.yaml", doc)
    new = P.table_hash(table)
    argv = list(finished["argv"])
    argv[0] = table
    # options given over the table file's are part of the protocol; the loader's are not
    code, text, err = _main(finished["argv"] + ["--set", "workers=0"])
    assert code == 0 and "[clean seed 22742] reusing" in text, err
    code, _, err = _main(finished["argv"] + ["--set", "lr=0.01"])
    assert code == 2 and f'now {old[:12]}, options {{"lr": 0.01}}' in err
    files = [base / "results.json", base / "results.md", base / "configs" / "clean-seed-22742.yaml",
             base / P.LEDGER]
    before = [p.read_bytes() for p in files]
    code, text, err = _main(argv)
    assert code == 2
    assert "another version of the table file" in err and old[:12] in err
    assert new[:12] in err and "--allow-changed" in err and "clean/seed-22742" in err
    assert [p.read_bytes() for p in files] == before  # nothing written
    code, text, err = _main(argv + ["--allow-changed"])
    assert code == 0, err
    prot = json.loads((base / "results.json").read_text())["protocol"]
    assert (prot["hash"], prot["mixed"], prot["allow_changed"]) == (
        new, {"clean/seed-22742": {"hash": old, "options": {}}}, True)
    assert prot["runs"]["clean/seed-22742"]["hash"] == old  # the run keeps the hash it was made under
    assert f"**Mixed protocols (--allow-changed):** 1 run(s) were made under protocol hash " \
           f"{old[:12]}" in text
    ledger = json.loads((base / P.LEDGER).read_text())
    assert ledger["allowed_changes"][-1]["runs"] == {"clean/seed-22742": {"hash": old, "options": {}}}
    assert ledger["allowed_changes"][-1]["hash"] == new
    # runs made before runs were recorded (no ledger) are refused too
    (base / P.LEDGER).unlink()
    code, _, err = _main(finished["argv"])
    assert code == 2 and "protocol hash none" in err


# ---------------------------------------------------------------------- publish, render
def test_published_table_renders_into_its_readme_section(finished, monkeypatch):
    results_dir, base = finished["results_dir"], finished["base"]
    doc = json.loads((results_dir / "tiny_ae-smoke.json").read_text())
    assert str(finished["root"]) not in json.dumps(doc)  # no machine's paths
    assert doc["protocol"]["hash"] == P.table_hash(finished["table"])
    assert doc["per_recording"] == "tiny_ae-smoke.per_recording.json.xz"
    sums = RM.read_sums(results_dir / doc["per_recording"])
    run = json.loads((base / "clean" / "seed-22742" / "test_per_recording.json").read_text())
    assert sums["clean"]["22742"]["test"]["metrics"]["pck_0.05"] == \
        run["test"]["metrics"]["pck_0.05"]
    assert set(sums["clean"]["22742"]["test"]["metrics"]) <= set(doc["metrics"]) | {"f1_constant"}
    monkeypatch.setenv("BSP_EXPERIMENTS", str(finished["table"].parent))
    readme = finished["root"] / "README.md"
    readme.write_text("intro\n<!-- results:tiny_ae/smoke:begin -->\n<!-- "
                      "results:tiny_ae/smoke:end -->\nbetween\n<!-- results:autoencoder:begin "
                      "-->\nstale\n<!-- results:autoencoder:end -->\nend\n")
    assert RM.differing_sections(readme.read_text(), results_dir, readme.parent) == [
        "tiny_ae/smoke", "autoencoder"]
    assert RM.main(["--page", str(readme), "--results", str(results_dir), "--check"]) == 1
    assert RM.main(["--page", str(readme), "--results", str(results_dir)]) == 0
    text = readme.read_text()
    assert text.startswith("intro\n") and "\nbetween\n" in text and text.endswith("\nend\n")
    assert RM.main(["--page", str(readme), "--results", str(results_dir), "--check"]) == 0
    section = text.split("results:tiny_ae/smoke:begin -->")[1].split("<!-- results:tiny_ae")[0]
    value = doc["results"]["clean"]["metrics"]["pck_0.05"]
    row = next(ln for ln in section.splitlines() if ln.startswith("| clean |"))
    assert f"| {100 * value:.1f} |" in row  # the cell is the published number
    assert "smoke budget: plumbing only" in section
    assert "| exploratory (added after results were seen" in section
    assert f"sha256 {doc['protocol']['hash'][:12]}" in section
    assert "[docs/results/tiny_ae-smoke.md](docs/results/tiny_ae-smoke.md)" in section
    # a table without a published file: says so, no numbers, the history linked
    other = text.split("results:autoencoder:begin -->")[1]
    assert "**Not run under the registered protocol yet**" in other
    assert "38006fb" in other  # its deviations
    # a hand edit inside a section is found and named
    readme.write_text(text.replace(row, row.replace(f"{100 * value:.1f}", "99.9")))
    assert RM.differing_sections(readme.read_text(), results_dir, readme.parent) == [
        "tiny_ae/smoke"]
    # a changed table file is said under its published results
    doc_t = _tiny_doc()
    doc_t["budgets"]["smoke"]["batch_size"] = 4
    _write(finished["table"], doc_t)
    try:
        again = RM.render_section("tiny_ae", "smoke", results_dir, readme.parent)
    finally:
        _write(finished["table"], _tiny_doc())
    assert "**The table file has changed since these results**" in again


@pytest.fixture(scope="module")
def two_seeds(finished):
    """The tiny table with two seeds, published (the runs of "another machine")."""
    root = finished["root"] / "two-seeds"
    # --jobs 1: the seeds trained in this process (worker processes: test_reproduce_worker)
    code, _, err = _main(finished["argv"][:-2] + ["--out", root / "runs", "--seeds", "2",
                                                  "--jobs", "1", "--publish", root / "results"])
    assert code == 0, err
    return root


def test_published_table_reads_back_and_its_findings_recompute(finished, two_seeds):
    """``load_published``: a table whose run folder is gone (another machine's) read back
    from its published files; the findings recomputed from them equal the published ones."""
    from bsp_fast.reproduction.evidence import evaluate_findings
    from bsp_fast.reproduction.table_files import load_table

    path = two_seeds / "results" / "tiny_ae-smoke.json"
    doc = RM.load_published(path)
    for seed in ("22742", "22743"):
        run = json.loads((two_seeds / "runs" / "tiny_ae-smoke" / "clean" / f"seed-{seed}" /
                          "test_per_recording.json").read_text())
        got = doc["results"]["clean"]["seeds"][seed]["per_recording"]["test"]
        assert got["recordings"] == run["test"]["recordings"]
        assert got["metrics"]["pck_0.05"] == run["test"]["metrics"]["pck_0.05"]
    again = evaluate_findings(load_table(finished["table"]), doc)
    published = json.loads(path.read_text())["findings"]
    keys = ("text", "status", "difference", "interval", "p")
    assert [[f.get(k) for k in keys] for f in again] == \
        [[f.get(k) for k in keys] for f in published]
    assert {f["status"] for f in published} - {"rows not run"}  # findings were computed
    for bad, why in (("{}", "not a published table"), ("[1", "cannot read")):
        (finished["root"] / "bad.json").write_text(bad)
        with pytest.raises(ValueError, match=why):
            RM.load_published(finished["root"] / "bad.json")


def test_with_published_trains_only_the_missing_seeds(finished, two_seeds):
    """Another machine: ``--seeds 3 --with-published`` trains the third seed only, takes
    the two published ones with their own protocol records, and publishes all three with
    the published numbers unchanged."""
    other = finished["root"] / "other-machine"
    published = json.loads((two_seeds / "results" / "tiny_ae-smoke.json").read_text())
    argv = finished["argv"][:-2] + ["--out", other / "runs", "--seeds", "3", "--jobs", "1"]
    code, text, err = _main(argv + ["--with-published", two_seeds / "results",
                                    "--publish", other / "results"])
    assert code == 0, err
    assert text.count("read from the published tiny_ae-smoke.json") == 2
    base = other / "runs" / "tiny_ae-smoke" / "clean"
    assert sorted(p.name for p in base.iterdir()) == ["seed-22744"]  # the one trained here
    res = json.loads((other / "runs" / "tiny_ae-smoke" / "results.json").read_text())
    assert res["protocol"]["restored"] == ["clean/seed-22742", "clean/seed-22743"]
    for seed in ("22742", "22743"):
        old = published["results"]["clean"]["seeds"][seed]
        new = res["results"]["clean"]["seeds"][seed]
        assert new["metrics"] == old["metrics"] and new["run"] is None
        record = res["protocol"]["runs"][f"clean/seed-{seed}"]
        assert record["code"] == published["protocol"]["runs"][f"clean/seed-{seed}"]["code"]
        assert record["restored_from"].startswith("tiny_ae-smoke.json (protocol ")
    assert "**Read from published results (--with-published):** 2 run(s)" in \
        (other / "runs" / "tiny_ae-smoke" / "results.md").read_text()
    again = json.loads((other / "results" / "tiny_ae-smoke.json").read_text())
    assert list(again["results"]["clean"]["seeds"]) == ["22742", "22743", "22744"]
    sums = RM.read_sums(other / "results" / "tiny_ae-smoke.per_recording.json.xz")
    old_sums = RM.read_sums(two_seeds / "results" / "tiny_ae-smoke.per_recording.json.xz")
    assert sums["clean"]["22742"] == old_sums["clean"]["22742"] and "22744" in sums["clean"]
    # a second call reuses the run trained here and reads the other two again
    code, text, err = _main(argv + ["--with-published", two_seeds / "results"])
    assert code == 0 and "[clean seed 22744] reusing" in text, err
    # other data than the published table's: refused before anything is written
    (finished["root"] / "x.h5").write_bytes(b"")
    code, _, err = _main(argv[:argv.index("--data") + 1] + [finished["root"] / "x.h5"]
                         + argv[argv.index("--data") + 2:]
                         + ["--with-published", two_seeds / "results"])
    assert code == 2 and "was trained on data 'l30.h5'" in err


def test_bf16_rows_on_a_cpu_without_native_bf16_are_said_once(finished, tmp_path,
                                                               monkeypatch):
    """A row set to bf16-mixed on a CPU without AVX512-BF16/AMX trains many times slower:
    bsp-reproduce says so once, before training, naming the rows; not on a CPU with it."""
    from bsp_fast.training import precision

    argv = finished["argv"][:-2] + ["--set", "precision=bf16-mixed"]
    monkeypatch.setattr(precision, "native_bf16", lambda accelerator: False)
    code, text, err = _main(argv + ["--out", tmp_path / "avx2"])
    assert code == 0, err
    assert text.count("note: rows clean are set to bf16-mixed") == 1
    assert "--set precision=32 trains them in float32" in text
    monkeypatch.setattr(precision, "native_bf16", lambda accelerator: True)
    code, text, err = _main(argv + ["--out", tmp_path / "bf16"])
    assert code == 0 and "note: rows" not in text, err


def test_max_seeds_caps_a_costly_row_and_needs_its_reason(tmp_path):
    """A row's ``max_seeds`` (issue #37: rows over 30 CPU min per seed may keep 3) trains
    only its first seeds; the other rows get all of ``--seeds``; no reason, no table."""
    from bsp_fast.reproduction.runner import row_seeds

    doc = yaml.safe_load((ROOT / "experiments" / "lifting.yaml").read_text())
    doc["rows"][0].update(max_seeds={"quick": 3}, max_seeds_why="33 CPU min per seed")
    tab = R.load_table(_write(tmp_path / "capped.yaml", doc))
    got = {r["name"]: row_seeds(r, [7, 8, 9, 10, 11], "quick") for r in tab["rows"]}
    assert got["poseformer"] == [7, 8, 9] and got["lstm"] == [7, 8, 9, 10, 11]
    assert row_seeds(tab["rows"][0], [7, 8, 9, 10, 11], "smoke") == [7, 8, 9, 10, 11]
    assert row_seeds(tab["rows"][0], [7], "quick") == [7]  # a table of one seed
    del doc["rows"][0]["max_seeds_why"]
    with pytest.raises(ValueError, match="max_seeds_why"):
        R.load_table(_write(tmp_path / "no_reason.yaml", doc))
    doc["rows"][0].update(max_seeds={"quick": 0}, max_seeds_why="x")
    with pytest.raises(ValueError, match="max_seeds must map"):
        R.load_table(_write(tmp_path / "zero.yaml", doc))
