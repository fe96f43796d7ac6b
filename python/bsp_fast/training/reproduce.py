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
import sys
import time
from pathlib import Path

from . import config as C
from ..atomic import write_text
from .noisy_boxes import noisy_box_metrics
from .runs import RunError, read_run, resumable
from .figures import draw_figures
from .findings import NA, NO, YES, evaluate_findings, format_value
from .table_files import (BUDGETS, KINDS, RELATIONS, TABLES, experiments_dir, experiments_dirs,
                          load_table, prepare_row_data, row_options, settings_cells,
                          table_header, table_names, wanted_rows)
from .tasks.classification import constant_f1

# (table files and findings live in .table_files and .findings; their names stay here)
__all__ = ["TABLES", "BUDGETS", "KINDS", "RELATIONS", "YES", "NO", "NA", "experiments_dir",
           "experiments_dirs", "load_table", "row_options", "reproduce", "evaluate_findings",
           "format_report", "main", "constant_f1", "format_value"]



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
    wanted = wanted_rows(tab, rows)
    base = Path(out) / f"{tab['table']}-{budget}"
    plan = []
    for row in tab["rows"]:
        if row["name"] in wanted and not row.get("initial_of"):
            run_dir = base / row["name"]
            opts = row_options(tab, row, budget, data, run_dir, overrides)
            C.validate(C.defaults() | opts)  # unknown models / hyper-parameters fail first
            opts = prepare_row_data(tab, row, opts, convert=not dry_run)
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
            stopped = None if force else resumable(run_dir)
            if stopped is not None:  # interrupted or killed: continue, not restart
                log(f"[{row['name']}] continuing the interrupted run {stopped}")
                train(resume=str(stopped), quiet=quiet)
            else:
                train(config=str(cfg_path), force=True, quiet=quiet)
            log(f"[{row['name']}] done in {time.perf_counter() - t0:.0f} s")
        run = read_run(run_dir)
        m = run["metrics"]
        test = dict(m.get("test", {}))
        test.update(noisy_box_metrics(tab, run_dir, force, quiet, log))
        results[row["name"]] = {"metrics": test, "initial": (m.get("initial") or {}).get("test", {}),
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


# ---------------------------------------------------------------------- output
def _md(header, rows) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(lines)


def format_report(tab: dict, res: dict) -> str:
    """Markdown: our table with the report's values beside it, then the findings."""
    from .cost_columns import COST_HEADER, cost_cells

    header, metrics, reported, settings = table_header(tab, "epochs (best/run)")
    header += COST_HEADER
    rows = []
    for row in tab["rows"]:
        r = res["results"].get(row["name"])
        if r is None:
            continue
        cells = [row["name"], row.get("label", row["name"])]
        if settings:
            cells += settings_cells(r)
        cells += [format_value(tab, m, r["metrics"].get(m)) for m in metrics]
        cells += [format_value(tab, m, (row.get("report") or {}).get(m)) for m in reported]
        cells.append(format_value(tab, metrics[0], r["initial"].get(metrics[0])))
        cells.append("–" if r["epochs"] is None else f"{r['best_epoch']}/{r['epochs']}")
        cells += ["–"] * len(COST_HEADER) if r["epochs"] is None else \
            cost_cells([r["run"]], [r["seconds"]])
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
        epilog="tables: " + ", ".join(table_names()) + ". Budgets: smoke (1 epoch, 2 batches: plumbing "
               "only), quick (2-core CPU on bsp-synth data; costs in each table file), full (the "
               "report's epochs, GPU). Exit codes: 0 done, 1 a run failed or bad data, 2 bad "
               "arguments. docs: docs/reproduce.md")
    p.add_argument("table", metavar="TABLE", nargs="?",
                   help="table name (installed with bsp_fast) or path to a table YAML")
    p.add_argument("--table", dest="table_file", metavar="FILE.yaml",
                   help="your own table file instead of TABLE (docs/reproduce.md, table files)")
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
    p.add_argument("--breakdown", action="store_true",
                   help="also the test breakdown of every row (bsp-eval --breakdown: per joint, "
                        "size or distance bin, profile, missing joints), mean ± std over seeds: "
                        "breakdown.md, breakdown.json and bar figures beside results.md")
    from .seeds import add_options

    add_options(p)  # --seeds, --split-seeds, --jobs
    return p


def main(argv=None) -> int:
    parser = build_parser()
    ns = parser.parse_args(argv)
    if (ns.table is None) == (ns.table_file is None):
        parser.error("give a TABLE name or --table FILE.yaml (one of them)")
    if ns.table_file is not None and Path(ns.table_file).suffix not in (".yaml", ".yml"):
        parser.error(f"--table {ns.table_file}: a table file ends in .yaml or .yml")
    from .lifecycle import Interrupted, signals

    try:
        tab = load_table(ns.table or ns.table_file)
        overrides = C.parse_hp(ns.set)
        rows = [r.strip() for r in ns.rows.split(",") if r.strip()] if ns.rows else None
        # SIGTERM/SIGINT: Interrupted here; the runs in worker processes get SIGTERM and
        # save, a run in this process saves at the end of its batch
        with signals():
            if ns.seeds != 1 or ns.split_seeds:
                from .evidence import main_seeds

                return main_seeds(tab, ns, rows, overrides)
            res = reproduce(tab, ns.data, ns.budget, ns.out, rows=rows, overrides=overrides,
                            force=ns.force, quiet=not ns.verbose, dry_run=ns.dry_run)
    except Interrupted as exc:
        print(f"bsp-reproduce: interrupted ({exc}); finished rows are kept and reused, an "
              "interrupted row continues where it stopped when the same command is run "
              "again", file=sys.stderr)
        return exc.code
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
    figures = draw_figures(tab, res)  # the table's own figures (``figures:``)
    for name, content in (("results.md", text),
                          ("results.json", json.dumps(
                              {**res, "findings": evaluate_findings(tab, res["results"]),
                               "figures": [str(f) for f in figures]},
                              indent=1, default=str))):
        write_text(base / name, content)
    if ns.breakdown:
        from .table_breakdown import table_breakdown

        figures += table_breakdown(tab, res, ns.force)
    print(f"wrote {base / 'results.md'}" + "".join(f", {f}" for f in figures))
    return 0


if __name__ == "__main__":
    sys.exit(main())
