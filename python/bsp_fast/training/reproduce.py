"""``bsp-reproduce TABLE --data DATASET_DIR``: runs every row of one of the report's tables
(``experiments/TABLE.yaml``) through :func:`bsp_fast.train`, then prints our numbers next to
the report's and marks each of the report's findings (orderings, effect directions) as
reproduced or not, computed from the numbers. See docs/reproduce.md.

A table file holds ``common`` options, ``budgets`` (smoke / quick / full option sets),
``rows`` (a name, a label, the row's own options, optionally the report's values) and
``findings``. Each row's resolved options are written as a plain ``bsp-train --config`` file
(``OUT/TABLE-BUDGET/configs/ROW.yaml``) and the run is trained from that file.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

from . import config as C
from ..atomic import write_text
from .runs import RunError, read_run

__all__ = ["TABLES", "BUDGETS", "load_table", "row_options", "reproduce", "evaluate_findings",
           "format_report", "main"]

TABLES = ("lifting", "classification", "autoencoder", "pose_estimation")
BUDGETS = ("smoke", "quick", "full")
KINDS = ("order", "compare", "drop", "fails", "robuster", "at_least", "beats_initial")
RELATIONS = (">", ">=", "<", "<=")
YES, NO, NA = "reproduced", "not reproduced", "n/a"


# ---------------------------------------------------------------------- table files
def experiments_dir() -> Path:
    """``$BSP_EXPERIMENTS``, else ``./experiments``, else the repository's ``experiments/``."""
    if os.environ.get("BSP_EXPERIMENTS"):
        return Path(os.environ["BSP_EXPERIMENTS"])
    here = Path.cwd() / "experiments"
    if here.is_dir():
        return here
    return Path(__file__).resolve().parents[3] / "experiments"


def load_table(table) -> dict:
    """A table by name (one of :data:`TABLES`) or a path to its YAML file, checked."""
    import yaml

    path = Path(table)
    if path.suffix not in (".yaml", ".yml"):
        if str(table) not in TABLES:
            raise ValueError(f"unknown table {table!r}; allowed: {', '.join(TABLES)} "
                             "(or a path to a table YAML)")
        path = experiments_dir() / f"{table}.yaml"
    if not path.is_file():
        raise ValueError(f"{path}: no such table file")
    doc = yaml.safe_load(path.read_text(encoding="utf-8"))
    for key in ("table", "task", "metrics", "common", "budgets", "rows", "findings"):
        if not isinstance(doc, dict) or key not in doc:
            raise ValueError(f"{path}: missing key {key!r}")
    names = [r["name"] for r in doc["rows"]]
    for r in doc["rows"]:
        extra = r.get("budgets") or {}
        if not isinstance(extra, dict) or set(extra) - set(doc["budgets"]):
            raise ValueError(f"{path}: row {r['name']!r}: budgets must be a mapping with keys "
                             f"from {list(doc['budgets'])}, got {extra!r}")
    if len(set(names)) != len(names):
        raise ValueError(f"{path}: duplicate row names in {names}")
    for f in doc["findings"]:
        if f.get("kind") not in KINDS:
            raise ValueError(f"{path}: finding kind {f.get('kind')!r}; allowed: {', '.join(KINDS)}")
        if f.get("relation", ">") not in RELATIONS:
            raise ValueError(f"{path}: relation {f['relation']!r}; allowed: {', '.join(RELATIONS)}")
        for name in _rows_of(f):
            if name not in names:
                raise ValueError(f"{path}: finding {f.get('text')!r} names unknown row {name!r}")
        if f.get("metric") not in doc["metrics"]:
            raise ValueError(f"{path}: finding {f.get('text')!r}: metric {f.get('metric')!r} "
                             f"is not one of {list(doc['metrics'])}")
    doc["path"] = str(path)
    from .seeds import check_budget_rule

    check_budget_rule(doc)
    return doc


def _rows_of(f: dict) -> list:
    out = []
    for key in ("rows", "a", "b", "base", "other", "row"):
        v = f.get(key)
        out += v if isinstance(v, list) else ([v] if v is not None else [])
    return out


def row_options(table: dict, row: dict, budget: str, data, run_dir, overrides=None) -> dict:
    """bsp-train options of one row: common < budget < row < the row's own options for this
    budget (``budgets: {quick: {...}}`` in the row, e.g. fewer epochs for a model that is
    100x slower than the others) < ``overrides``."""
    if budget not in table["budgets"]:
        raise ValueError(f"budget {budget!r} not in {table['path']}; allowed: "
                         + ", ".join(table["budgets"]))
    opts = dict(table["common"])
    opts.update(table["budgets"][budget] or {})
    opts.update(row.get("options") or {})
    opts.update((row.get("budgets") or {}).get(budget) or {})
    opts.update(overrides or {})
    opts.update(data=str(data), out=str(run_dir))
    return C.normalise(opts, f"{table['table']} row {row['name']!r}")


# ---------------------------------------------------------------------- running
def _write_config(opts: dict, path: Path) -> None:
    import yaml

    path.parent.mkdir(parents=True, exist_ok=True)
    write_text(path, "# bsp-reproduce: one row, usable as bsp-train --config\n"
               + yaml.safe_dump(opts, sort_keys=False))


def reproduce(table, data, budget: str = "quick", out="runs", rows=None, overrides=None,
              force: bool = False, quiet: bool = True, dry_run: bool = False, log=print) -> dict:
    """Runs the rows of ``table`` (all, or the names in ``rows``) and returns
    ``{"table", "budget", "dir", "results": {row: {"metrics", "initial", "epochs", ...}}}``.
    A row whose run directory already holds a ``metrics.json`` is reused unless ``force``."""
    tab = table if isinstance(table, dict) else load_table(table)
    if budget not in BUDGETS:
        raise ValueError(f"budget must be one of {list(BUDGETS)}, got {budget!r}")
    names = [r["name"] for r in tab["rows"]]
    wanted = list(names) if not rows else list(rows)
    bad = [r for r in wanted if r not in names]
    if bad:
        raise ValueError(f"unknown row(s) {bad} of table {tab['table']!r}; allowed: "
                         + ", ".join(names))
    by_name = {r["name"]: r for r in tab["rows"]}
    for name in list(wanted):  # rows read from another row's run need that run
        src = by_name[name].get("initial_of")
        if src and src not in wanted:
            wanted.append(src)
    base = Path(out) / f"{tab['table']}-{budget}"
    plan = []
    for row in tab["rows"]:
        if row["name"] in wanted and not row.get("initial_of"):
            run_dir = base / row["name"]
            opts = row_options(tab, row, budget, data, run_dir, overrides)
            C.validate(C.defaults() | opts)  # unknown models / hyper-parameters fail first
            plan.append((row, run_dir, opts))
    results = {}
    for row, run_dir, opts in plan:
        cfg_path = base / "configs" / f"{row['name']}.yaml"
        _write_config(opts, cfg_path)
        if dry_run:
            log(f"bsp-train --config {cfg_path}")
            continue
        if (run_dir / "metrics.json").is_file() and not force:
            log(f"[{row['name']}] reusing {run_dir} (--force to train again)")
        else:
            log(f"[{row['name']}] training: bsp-train --config {cfg_path}")
            from .train import train

            t0 = time.perf_counter()
            train(config=str(cfg_path), force=True, quiet=quiet)
            log(f"[{row['name']}] done in {time.perf_counter() - t0:.0f} s")
        run = read_run(run_dir)
        m = run["metrics"]
        results[row["name"]] = {"metrics": m.get("test", {}), "initial": (m.get("initial") or {}).get("test", {}),
                                "baseline": (m.get("initial") or {}).get("baseline"),
                                "epochs": m.get("epochs"), "best_epoch": m.get("best_epoch"),
                                "seconds": m.get("seconds", {}), "run": str(run_dir),
                                "noise": run["config"].get("noise"), "mjp": run["config"].get("mjp")}
    for row in tab["rows"]:
        src = row.get("initial_of")
        if row["name"] in wanted and src and src in results:
            r = results[src]
            results[row["name"]] = {"metrics": dict(r["initial"]), "initial": dict(r["initial"]),
                                    "baseline": r["baseline"], "epochs": None, "best_epoch": None,
                                    "seconds": {}, "run": r["run"] + " (initial metrics)",
                                    "noise": r["noise"], "mjp": r["mjp"]}
    return {"table": tab["table"], "budget": budget, "dir": str(base), "results": results}


# ---------------------------------------------------------------------- findings
def _better(tab, metric) -> int:
    """+1 when higher is better, -1 when lower is, 0 when neither."""
    return {"higher": 1, "lower": -1}.get(tab["metrics"][metric].get("better"), 0)


def _fmt(tab, metric, value) -> str:
    if value is None:
        return "–"
    fmt = tab["metrics"][metric].get("format", ".3f")
    return f"{100 * value:.1f}" if fmt == "pct" else format(value, fmt)


def _rel(a, b, relation, margin=0.0) -> bool:
    d = a - b
    return {">": d > margin, ">=": d >= -margin, "<": d < -margin, "<=": d <= margin}[relation]


def _finding(tab, f, values: dict, initial: dict) -> tuple:
    """(ours, report, status) of one finding; ``values[source][row]`` is the metric of a row
    (source ``ours`` or ``report``); ``initial[row]`` the trivial baseline's (ours only)."""
    metric, sign = f["metric"], _better(tab, f["metric"])
    fm = lambda v: _fmt(tab, metric, v)  # noqa: E731
    pp = " p.p." if tab["metrics"][metric].get("format") == "pct" else ""
    out = {}
    for src in ("ours", "report"):
        v = values[src]
        need = _rows_of(f)
        if f["kind"] in ("fails", "beats_initial", "at_least"):
            # a threshold or a trivial baseline is ours to test; the report column says
            # what the report stated (report_text)
            if src == "report" or (f["kind"] != "at_least"
                                   and any(initial.get(r) is None for r in need)):
                out[src] = ("", None)
                continue
        if any(v.get(r) is None for r in need):
            out[src] = ("", None)
            continue
        k = f["kind"]
        if k == "order":
            rs = f["rows"]
            ok = all(sign * (v[a] - v[b]) > 0 for a, b in zip(rs, rs[1:]))
            text = rs[0] + " " + fm(v[rs[0]])
            for a, b in zip(rs, rs[1:]):
                op = "<" if v[a] < v[b] else (">" if v[a] > v[b] else "=")
                text += f" {op} {b} {fm(v[b])}"
        elif k == "compare":
            ok = _rel(v[f["a"]], v[f["b"]], f.get("relation", ">="), f.get("margin", 0.0))
            text = f"{f['a']} {fm(v[f['a']])} vs {f['b']} {fm(v[f['b']])}"
        elif k == "drop":
            drop = sign * (v[f["base"]] - v[f["other"]])
            ok = drop > 0
            text = f"{fm(v[f['base']])} -> {fm(v[f['other']])} (loss {fm(drop)}{pp})"
        elif k == "robuster":
            la = sign * (v[f["a"][0]] - v[f["a"][1]])
            lb = sign * (v[f["b"][0]] - v[f["b"][1]])
            ok = la < lb
            text = f"loss {fm(la)}{pp} vs {fm(lb)}{pp}"
        elif k == "at_least":
            ok = v[f["row"]] >= f["value"]
            text = f"{f['row']} {fm(v[f['row']])} (threshold {fm(f['value'])})"
        elif k == "fails":
            r = f["row"]
            ok = v[r] <= initial[r] + f.get("margin", 0.0)
            what = "best constant" if f.get("baseline") == "constant" else "majority class"
            text = f"{fm(v[r])} vs {what} {fm(initial[r])}"
        else:  # beats_initial
            ok = all(sign * (v[r] - initial[r]) > 0 for r in f["rows"])
            text = "; ".join(f"{r} {fm(v[r])} vs {fm(initial[r])}" for r in f["rows"])
        out[src] = (text, ok)
    if f["kind"] == "drop" and f.get("report") is not None and out["report"][1] is None:
        out["report"] = (f"loss about {fm(f['report'])}{pp}", True)
    ours, ok = out["ours"]
    report = out["report"][0] or f.get("report_text", "stated in the report")
    status = NA if ok is None else (YES if ok else NO)
    return ours or "rows not run", report, status


def constant_f1(initial: dict):
    """F1 of the better constant classifier on a split, from the majority-class baseline's
    metrics there: always "crossing" scores 2p / (1 + p) with p the crossing share, which
    is at least the majority class's F1 (0 when the majority does not cross). A classifier
    that only learnt to say "crossing" reaches this without looking at the poses."""
    acc, f1 = initial.get("accuracy"), initial.get("f1")
    if acc is None or f1 is None:
        return None
    p = acc if f1 > 0 else 1.0 - acc
    return 2 * p / (1 + p)


def evaluate_findings(tab: dict, results: dict) -> list:
    """``[{"text", "ours", "report", "status"}]`` for the findings of ``tab`` on the
    ``results`` of :func:`reproduce`; status ``reproduced``, ``not reproduced`` or ``n/a``
    (a row it needs was not run). Nothing is hard-coded: the numbers decide."""
    out = []
    for f in tab["findings"]:
        m = f["metric"]
        values = {"ours": {r: results[r]["metrics"].get(m) for r in results},
                  "report": {r["name"]: (r.get("report") or {}).get(m) for r in tab["rows"]}}
        initial = {r: results[r]["initial"].get(m) for r in results}
        if f.get("baseline") == "constant":
            initial = {r: constant_f1(results[r]["initial"]) for r in results}
        ours, report, status = _finding(tab, f, values, initial)
        out.append({"text": f["text"], "ours": ours, "report": report, "status": status})
    return out


# ---------------------------------------------------------------------- output
def _md(header, rows) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(lines)


def format_report(tab: dict, res: dict) -> str:
    """Markdown: our table with the report's values beside it, then the findings."""
    metrics = list(tab["metrics"])
    reported = [m for m in metrics if any(m in (r.get("report") or {}) for r in tab["rows"])]
    settings = tab["task"] in ("classification", "autoencoder")
    header = ["row", "model"] + (["σ (px)", "MJP"] if settings else [])
    header += [tab["metrics"][m]["label"] for m in metrics]
    header += [f"report {tab['metrics'][m]['label']}" for m in reported]
    header += [f"trivial {tab['metrics'][metrics[0]]['label']}", "epochs (best/run)"]
    rows = []
    for row in tab["rows"]:
        r = res["results"].get(row["name"])
        if r is None:
            continue
        cells = [row["name"], row.get("label", row["name"])]
        if settings:
            cells += [f"{r['noise'] or 0:g}", f"{r['mjp'] or 0:g}"
                      if not isinstance(r["mjp"], list) else "per joint"]
        cells += [_fmt(tab, m, r["metrics"].get(m)) for m in metrics]
        cells += [_fmt(tab, m, (row.get("report") or {}).get(m)) for m in reported]
        cells.append(_fmt(tab, metrics[0], r["initial"].get(metrics[0])))
        cells.append("–" if r["epochs"] is None else f"{r['best_epoch']}/{r['epochs']}")
        rows.append(cells)
    found = evaluate_findings(tab, res["results"])
    text = [f"### {tab['title']} — budget {res['budget']}", "", _md(header, rows), "",
            _md(["finding (report)", "ours", "report", "status"],
                [[f["text"], f["ours"], f["report"], f["status"]] for f in found])]
    return "\n".join(text) + "\n"


# ---------------------------------------------------------------------- CLI
def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="bsp-reproduce",
        description="Run every row of one of the report's tables (experiments/TABLE.yaml) with "
                    "bsp-train, then print our table beside the report's numbers with each of the "
                    "report's findings marked reproduced / not reproduced (from the numbers).",
        epilog="tables: " + ", ".join(TABLES) + ". Budgets: smoke (1 epoch, 2 batches: plumbing "
               "only), quick (2-core CPU, < 30 min per table on bsp-synth data), full (the "
               "report's epochs, GPU). Exit codes: 0 done, 1 a run failed or bad data, 2 bad "
               "arguments. docs: docs/reproduce.md")
    p.add_argument("table", metavar="TABLE", help="table name or path to a table YAML")
    p.add_argument("--data", required=True, metavar="DATASET_OR_H5",
                   help="CARLA-BSP dataset directory (e.g. from bsp-synth) or a bsp-convert "
                        "HDF5 file")
    p.add_argument("--budget", default="quick", choices=BUDGETS,
                   help="option set of the table file to train with (default: quick)")
    p.add_argument("--out", default="runs", metavar="DIR",
                   help="runs go to DIR/TABLE-BUDGET/ROW, configs to DIR/TABLE-BUDGET/configs "
                        "(default: runs)")
    p.add_argument("--rows", metavar="A,B", help="only these rows (comma-separated names)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a bsp-train option for every row (repeatable; YAML values), "
                        "e.g. --set workers=2 --set accelerator=gpu")
    p.add_argument("--force", action="store_true",
                   help="train rows again even when their run directory has metrics.json "
                        "(default: reuse finished rows)")
    p.add_argument("--dry-run", action="store_true",
                   help="write the per-row bsp-train configs and print the commands only")
    p.add_argument("--verbose", action="store_true", help="bsp-train's progress bars and tables")
    from .seeds import add_options

    add_options(p)  # --seeds, --split-seeds, --jobs
    return p


def main(argv=None) -> int:
    ns = build_parser().parse_args(argv)
    try:
        tab = load_table(ns.table)
        overrides = C.parse_hp(ns.set)
        rows = [r.strip() for r in ns.rows.split(",") if r.strip()] if ns.rows else None
        if ns.seeds != 1 or ns.split_seeds:
            from .evidence import main_seeds

            return main_seeds(tab, ns, rows, overrides)
        res = reproduce(tab, ns.data, ns.budget, ns.out, rows=rows, overrides=overrides,
                        force=ns.force, quiet=not ns.verbose, dry_run=ns.dry_run)
    except (C.ConfigError, ValueError) as exc:
        print(f"bsp-reproduce: {exc}", file=sys.stderr)
        return 2
    except RunError as exc:
        print(f"bsp-reproduce: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("bsp-reproduce: interrupted (finished rows are kept and reused)", file=sys.stderr)
        return 130
    if ns.dry_run:
        return 0
    text = format_report(tab, res)
    print(text)
    base = Path(res["dir"])
    for name, content in (("results.md", text),
                          ("results.json", json.dumps(
                              {**res, "findings": evaluate_findings(tab, res["results"])},
                              indent=1, default=str))):
        write_text(base / name, content)
    print(f"wrote {base / 'results.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
