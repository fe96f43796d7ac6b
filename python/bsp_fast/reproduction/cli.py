"""``bsp-reproduce TABLE --data DATASET_DIR``: runs every row of one of the report's tables
(``experiments/TABLE.yaml``) through :func:`bsp_fast.train` (:mod:`.runner`), then prints
our numbers next to the report's and marks each of the report's findings (orderings,
effect directions) as reproduced, not reproduced or inconclusive, computed from the
numbers (:mod:`.report`). See docs/reproduce.md.

A table file holds ``common`` options, ``budgets`` (smoke / quick / full option sets),
``rows`` (a name, a label, the row's own options, optionally the report's values) and
``findings``. Each run's resolved options are written as a plain ``bsp-train --config``
file (``OUT/TABLE-BUDGET/configs/ROW.yaml``) and the run is trained from that file. Runs
made under another version of the table file are not mixed in (:mod:`.protocol`) unless
``--allow-changed``; ``--publish DIR`` copies the finished table into ``DIR`` for the
README (:mod:`.readme`).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..command_line import ArgumentParser
from ..training import config as C
from ..command_line import run_command, unknown
from ..training.overrides import NOT_OVERRIDES
from ..training.runs import RunError
from .runner import add_options, run_table
from .table_files import BUDGETS, load_table, table_names

__all__ = ["build_parser", "main"]


# ---------------------------------------------------------------------- CLI
def build_parser() -> argparse.ArgumentParser:
    p = ArgumentParser(
        prog="bsp-reproduce",
        description="Run every row of one of the report's tables (experiments/TABLE.yaml) with "
                    "bsp-train, then print our table beside the report's numbers with each of the "
                    "report's findings marked reproduced / not reproduced (from the numbers).",
        epilog="tables: " + ", ".join(table_names()) + ". Budgets: smoke (1 epoch, 2 batches: plumbing "
               "only), quick (2-core CPU on bsp-synth data; costs in each table file), full (the "
               "report's epochs, GPU). Exit codes: 0 done, 1 a run failed or bad data, 2 bad "
               "arguments or runs of another protocol in --out. docs: docs/reproduce.md")
    p.add_argument("table", metavar="TABLE",
                   help="a table's name (installed with bsp_fast, listed below) or the path "
                        "to your own table YAML (docs/reproduce.md, table files)")
    p.add_argument("--data", required=True, metavar="DATASET_OR_H5",
                   help="CARLA-BSP dataset directory (e.g. from bsp-synth) or a bsp-convert "
                        "HDF5 file")
    p.add_argument("--mix-data", action="append", default=[], metavar="NAME=FILE",
                   help="a clip file of a mixing table's source (repeatable; the mixed "
                        "table's jaad and pie: docs/interop.md, Mixed training)")
    p.add_argument("--budget", default="quick", choices=BUDGETS,
                   help="option set of the table file to train with (default: quick)")
    p.add_argument("--out", default="runs", metavar="DIR",
                   help="runs go to DIR/TABLE-BUDGET/ROW, configs to DIR/TABLE-BUDGET/configs "
                        "(default: runs)")
    p.add_argument("--rows", metavar="A,B", help="only these rows (comma-separated names)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a bsp-train option for every row (repeatable; YAML values; "
                        "any bsp-train option but "
                        + ", ".join(n for n in NOT_OVERRIDES if n != "hp") + "), e.g. "
                        "--set workers=2 --set accelerator=gpu --set max_steps=10")
    p.add_argument("--force", action="store_true",
                   help="train rows again even when their run directory has metrics.json "
                        "(default: reuse finished rows)")
    p.add_argument("--dry-run", action="store_true",
                   help="write the per-row bsp-train configs and print the commands only")
    p.add_argument("--verbose", action="store_true", help="bsp-train's progress bars and tables")
    p.add_argument("--allow-changed", action="store_true",
                   help="reuse or continue runs made under another version of the table file "
                        "(its protocol hash) or other --set options (both recorded in "
                        "OUT/TABLE-BUDGET/protocol.json); the "
                        "mix is recorded in results.json and printed under the table "
                        "(default: refuse, exit 2, nothing written)")
    _output_options(p)
    add_options(p)  # --seeds, --split-seeds, --jobs
    return p


def _output_options(p) -> None:
    """What a call writes besides the table: --publish, --with-published, --breakdown,
    --estimate."""
    p.add_argument("--publish", metavar="DIR",
                   help="after the report, copy the finished table into DIR (e.g. docs/results): "
                        "TABLE-BUDGET.json, .per_recording.json.xz and .md, which "
                        "python -m bsp_fast.reproduction.readme renders into docs/results.md")
    p.add_argument("--with-published", metavar="DIR",
                   help="with --seeds: take the runs that have no run folder here from the "
                        "table published in DIR (e.g. docs/results; trained on another "
                        "machine), their numbers as published and each under its own protocol "
                        "record; nothing is retrained for them (docs/reproduce.md)")
    p.add_argument("--breakdown", action="store_true",
                   help="also the test breakdown of every row (bsp-eval --breakdown: per joint, "
                        "size or distance bin, profile, missing joints), mean ± std over seeds: "
                        "breakdown.md, breakdown.json and bar figures beside results.md")
    p.add_argument("--estimate", action="store_true",
                   help="train nothing: time a short probe of every row on this machine and "
                        "print its CPU minutes per seed and the table's total against the "
                        "8 CPU hours a quick table must fit on an AVX2-only core (seeds: "
                        "--seeds N, else the table file's registered count; "
                        "docs/reproduce.md, 'Estimate')")


def parse_set(items) -> dict:
    """``--set KEY=VALUE`` items as bsp-train options (``-`` or ``_``), each converted by
    its own declaration; a name that is not an override is refused with a "did you
    mean"."""
    allowed = {o.name: o for o in C.OPTIONS if o.name not in NOT_OVERRIDES or o.name == "hp"}
    out = {}
    for key, value in C.parse_hp(items).items():
        if key in NOT_OVERRIDES and key != "hp":
            raise C.ConfigError(f"--set {key}: not a per-row override; bsp-reproduce sets it "
                                "itself (the table's rows, --seeds, --data, --out, --force)")
        if key not in allowed:
            raise C.ConfigError(f"--set {key}: " + unknown("bsp-train option", key, allowed))
        try:
            out[key] = allowed[key].convert(value)
        except C.ConfigError as exc:
            raise C.ConfigError(f"--set {key}: {exc}") from None
    return out


def main(argv=None) -> int:
    parser = build_parser()
    ns = parser.parse_args(argv)
    if ns.publish and ns.dry_run:
        parser.error("--publish copies a finished table: not with --dry-run")
    return run_command("bsp-reproduce", _main, ns)


def _main(ns) -> int:
    # every argument and input checked before PyTorch is imported
    tab = load_table(ns.table)
    overrides = parse_set(ns.set)
    if ns.mix_data:  # an input, like --data: the files the table's mixes read
        overrides["mix_data"] = {**overrides.get("mix_data", {}),
                                 **C.BY_NAME["mix_data"].convert(ns.mix_data)}
    if not Path(ns.data).exists():
        raise RunError(f"--data {ns.data}: no such dataset directory or HDF5 file")
    if ns.estimate:
        from .estimate import main_estimate

        return main_estimate(tab, ns.data, ns.budget, seeds=ns.seeds if ns.seeds > 1 else None,
                             rows=[r.strip() for r in (ns.rows or "").split(",") if r.strip()]
                             or None, overrides=overrides, out=ns.out)
    from ..training.stopping import Interrupted, signals
    from .report import write_report

    rows = [r.strip() for r in ns.rows.split(",") if r.strip()] if ns.rows else None
    try:  # SIGTERM/SIGINT: Interrupted here; the runs in worker processes get SIGTERM and
        # save, a run in this process saves at the end of its batch
        with signals():
            res = run_table(tab, ns.data, ns.budget, ns.out, seeds=ns.seeds,
                            split_seeds=ns.split_seeds, jobs=ns.jobs, rows=rows,
                            overrides=overrides, force=ns.force, quiet=not ns.verbose,
                            dry_run=ns.dry_run, allow_changed=ns.allow_changed,
                            with_published=ns.with_published)
            if not ns.dry_run:
                write_report(tab, res, breakdown=ns.breakdown, force=ns.force)
                if ns.publish:
                    from .readme import publish

                    print(f"published {publish(tab, res['dir'], ns.publish)}")
    except (Interrupted, KeyboardInterrupt) as exc:
        why = f" ({exc})" if isinstance(exc, Interrupted) else ""
        print(f"bsp-reproduce: interrupted{why}; finished rows are kept and reused, an "
              "interrupted row continues where it stopped when the same command is run again",
              file=sys.stderr)
        return getattr(exc, "code", 130)
    return 0


if __name__ == "__main__":
    sys.exit(main())
