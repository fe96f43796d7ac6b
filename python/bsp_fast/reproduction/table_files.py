"""The table files of ``bsp-reproduce`` (``experiments/TABLE.yaml``): where they are found,
how they are read and checked (rows, findings, the one budget rule per table), and a row's
resolved ``bsp-train`` options. See docs/reproduce.md.

A table file holds ``common`` options, ``budgets`` (smoke / quick / full option sets),
``rows`` (a name, a label, the row's own options, optionally the report's values),
``findings`` and ``budget_rule`` (the training rule every row follows, in words); the
ablation tables also use ``own_updates`` (a row's own update cap, with its reason),
``data_suffix`` (a row reads a sibling dataset: ``--data`` plus the suffix; the table's
``data_variants`` says how to make each) and ``figures`` (:func:`check_figures`; drawn
by :mod:`bsp_fast.reporting.figures`). The registered protocol's fields, ``deviations``
and a finding's ``exploratory``, are :mod:`.protocol`'s.
"""
from __future__ import annotations

import re
from pathlib import Path

from .. import defaults
from ..command_line import unknown
from ..training import config as C
from .protocol import check_deviations, check_exploratory
from ..training.tasks import get_task

__all__ = ["wanted_rows", "TABLES", "BUDGETS", "KINDS",
           "RELATIONS", "RULE_KEYS", "experiments_dirs", "experiments_dir", "load_table",
           "row_options", "check_budget_rule", "rows_of", "ROW_CROP_BOXES", "row_crop_box",
           "prepare_row_data", "UPDATE_KEYS", "row_data", "table_names", "check_figures",
           "FIGURE_KEYS", "X_SETTINGS"]

TABLES = ("lifting", "classification", "autoencoder", "pose_estimation")
BUDGETS = ("smoke", "quick", "full")
KINDS = ("order", "compare", "drop", "fails", "robuster", "at_least", "beats_initial")
RELATIONS = (">", ">=", "<", "<=")
RULE_KEYS = ("epochs", "max_steps", "early_stop", "limit_batches", "batch_size")
#: the budget-rule options a row with an ``own_updates`` reason may set for a budget (its
#: cap of updates and patience, e.g. the original's batch-1 update count at batch 64)
UPDATE_KEYS = ("epochs", "max_steps", "early_stop")
#: Crop boxes a pose-estimation row may ask for (``crop_box:`` beside its options): mask
#: boxes (the default, every row's protocol) or the union with the ground-truth joint box,
#: only as an upper bound in a row of its own.
ROW_CROP_BOXES = ("mask", "mask+joints")


FIGURE_KEYS = ("file", "metric", "x", "title", "lines")
#: row settings a figure may put on its x axis (as the runs recorded them)
X_SETTINGS = ("mjp", "noise")


def check_figures(tab: dict) -> None:
    """ValueError naming the table file and the figure for a bad ``figures`` entry::

        figures:
          - file: f1_vs_mjp.png
            metric: f1
            x: mjp
            title: "F1 against MJP"
            lines:
              - {label: "LSTM, σ 0", rows: [lstm-s0-m0, lstm-s0-m0.3]}
    """
    where = tab.get("path", tab.get("table"))
    figs = tab.get("figures", [])
    if not isinstance(figs, list):
        raise ValueError(f"{where}: figures must be a list, got {type(figs).__name__}")
    names = {r["name"] for r in tab["rows"]}
    files = set()
    for i, fig in enumerate(figs):
        what = f"{where}: figure {i + 1}"
        if not isinstance(fig, dict) or set(fig) - set(FIGURE_KEYS):
            raise ValueError(f"{what}: a mapping with keys from {list(FIGURE_KEYS)}, got {fig!r}")
        file = fig.get("file")
        if not isinstance(file, str) or not re.fullmatch(r"[-_.A-Za-z0-9]+\.png", file):
            raise ValueError(f"{what}: file {file!r} must be a plain name ending in .png")
        if file in files or file == "curves.png":
            raise ValueError(f"{what}: file {file!r} is already written for this table")
        files.add(file)
        if fig.get("metric") not in tab["metrics"]:
            raise ValueError(f"{what}: metric {fig.get('metric')!r} is not one of "
                             f"{list(tab['metrics'])}")
        if fig.get("x") not in X_SETTINGS:
            raise ValueError(f"{what}: x {fig.get('x')!r}; allowed: {list(X_SETTINGS)}")
        lines = fig.get("lines")
        if not isinstance(lines, list) or not lines:
            raise ValueError(f"{what}: lines must be a non-empty list of {{label, rows}}")
        for line in lines:
            if not isinstance(line, dict) or not isinstance(line.get("label"), str) \
                    or not isinstance(line.get("rows"), list) or not line["rows"]:
                raise ValueError(f"{what}: a line is {{label: TEXT, rows: [ROW, ...]}}, "
                                 f"got {line!r}")
            bad = [r for r in line["rows"] if r not in names]
            if bad:
                raise ValueError(f"{what}: line {line['label']!r} names unknown row(s) {bad}")


def check_budget_rule(tab: dict) -> None:
    """One budget rule per table: the table states it (``budget_rule``), and no row changes
    the epochs, update cap, patience or batch limit of a budget; a row may use its own
    batch size only with an ``own_batch_size`` reason (the same update cap then applies),
    its own ``epochs``/``max_steps``/``early_stop`` only with an ``own_updates`` reason
    (which the table's ``budget_rule`` states)."""
    where = tab.get("path", tab.get("table"))
    if not isinstance(tab.get("budget_rule"), str) or not tab["budget_rule"].strip():
        raise ValueError(f"{where}: missing key 'budget_rule' (the table's training rule, "
                         "in words)")
    for row in tab["rows"]:
        for budget, opts in (row.get("budgets") or {}).items():
            for key in set(opts or {}) & set(RULE_KEYS):
                if key == "batch_size" and row.get("own_batch_size"):
                    continue
                if key in UPDATE_KEYS and row.get("own_updates"):
                    continue
                raise ValueError(
                    f"{where}: row {row['name']!r} sets {key!r} for budget {budget!r}: every "
                    f"row of a table follows its budget rule ({', '.join(RULE_KEYS)} are the "
                    "budget's; a row's own batch_size needs an own_batch_size reason, its "
                    f"own {'/'.join(UPDATE_KEYS)} an own_updates reason)")
        if set(RULE_KEYS) & set(row.get("options") or {}):
            raise ValueError(f"{where}: row {row['name']!r} sets budget options "
                             f"{sorted(set(RULE_KEYS) & set(row['options']))} in 'options'")


def experiments_dirs() -> list:
    """Where table files are looked up (:func:`bsp_fast.defaults.experiments_dirs`):
    ``$BSP_EXPERIMENTS``, ``./experiments``, the tables installed with the package
    (``bsp_fast/experiments``), the source tree's ``experiments/``."""
    return defaults.experiments_dirs()


def experiments_dir() -> Path:
    """The first of :func:`experiments_dirs` that exists (else the last)."""
    dirs = experiments_dirs()
    return next((d for d in dirs if d.is_dir()), dirs[-1])


def table_names() -> list:
    """The report's :data:`TABLES`, then the other table files of :func:`experiments_dirs`
    (the ablations), by name."""
    extra = sorted({p.stem for d in experiments_dirs() if d.is_dir()
                    for p in d.glob("*.yaml")} - set(TABLES))
    return list(TABLES) + extra


def load_table(table) -> dict:
    """A table by name (one of :func:`table_names`) or a path to its YAML file, checked."""
    import yaml

    path = _table_path(table)
    doc = yaml.safe_load(path.read_text(encoding="utf-8"))
    for key in ("table", "task", "metrics", "common", "budgets", "rows", "findings"):
        if not isinstance(doc, dict) or key not in doc:
            raise ValueError(f"{path}: missing key {key!r}")
    try:
        task = get_task(doc["task"])
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None
    doc["metrics"] = metric_specs(task, doc["metrics"], path)
    # what the renderers (bsp_fast.reporting) need of the task: its setting columns
    # (sigma and MJP, where inputs can be deformed) and its trivial baseline's name
    doc["deformed_inputs"], doc["trivial"] = task.deformed_inputs, task.baseline
    _check_rows(doc, path)
    _check_findings(doc, path, task)
    check_exploratory(doc, path)
    doc["deviations"] = check_deviations(doc, path)
    doc["path"] = str(path)
    check_budget_rule(doc)
    check_figures(doc)
    return doc


def _table_path(table) -> Path:
    """The YAML file of a table name (the first of :func:`experiments_dirs` that has it)
    or of a path."""
    path = Path(table)
    if path.suffix not in (".yaml", ".yml"):
        if str(table) not in table_names():
            raise ValueError(unknown("table", str(table), table_names())
                             + " (or a path to a table YAML)")
        dirs = experiments_dirs()
        path = next((d / f"{table}.yaml" for d in dirs if (d / f"{table}.yaml").is_file()),
                    None)
        if path is None:
            raise ValueError(f"no table file {table}.yaml in " + ", ".join(map(str, dirs))
                             + " (a broken install? a path to a table YAML reads your own)")
    if not path.is_file():
        raise ValueError(f"{path}: no such table file")
    return path


def _check_rows(doc: dict, path: Path) -> None:
    """Each row's budgets, name, data_suffix, crop_box and max_seeds."""
    names = [r["name"] for r in doc["rows"]]
    for r in doc["rows"]:
        extra = r.get("budgets") or {}
        if not isinstance(extra, dict) or set(extra) - set(doc["budgets"]):
            raise ValueError(f"{path}: row {r['name']!r}: budgets must be a mapping with keys "
                             f"from {list(doc['budgets'])}, got {extra!r}")
    if len(set(names)) != len(names):
        raise ValueError(f"{path}: duplicate row names in {names}")
    for r in doc["rows"]:
        suffix = r.get("data_suffix")
        if suffix is not None and (not isinstance(suffix, str)
                                   or not re.fullmatch(r"[-_.A-Za-z0-9]+", suffix)):
            raise ValueError(f"{path}: row {r['name']!r}: data_suffix {suffix!r}; a suffix of "
                             "letters, digits, '-', '_' or '.' appended to --data")
        if "crop_box" in r and (doc["task"] != "pose_estimation" or r["crop_box"] not in ROW_CROP_BOXES):
            raise ValueError(f"{path}: row {r['name']!r}: crop_box {r['crop_box']!r}; a "
                             f"pose_estimation row may ask for one of {list(ROW_CROP_BOXES)}")
    for r in doc["rows"]:  # a row too costly for the table's seed count (issue #37 rule)
        cap = r.get("max_seeds")
        if cap is None:
            continue
        if not isinstance(cap, dict) or set(cap) - set(doc["budgets"]) or not all(
                isinstance(v, int) and not isinstance(v, bool) and v >= 1 for v in cap.values()):
            raise ValueError(f"{path}: row {r['name']!r}: max_seeds must map budgets of "
                             f"{list(doc['budgets'])} to a number of seeds >= 1, got {cap!r}")
        if not str(r.get("max_seeds_why") or "").strip():
            raise ValueError(f"{path}: row {r['name']!r}: max_seeds needs a max_seeds_why "
                             "(its measured cost per seed); its findings are then "
                             "inconclusive by the 5-seed rule")


def _check_findings(doc: dict, path: Path, task) -> None:
    """Each finding's kind, relation, rows, baseline and metric."""
    names = [r["name"] for r in doc["rows"]]
    for f in doc["findings"]:
        if f.get("kind") not in KINDS:
            raise ValueError(f"{path}: finding kind {f.get('kind')!r}; allowed: {', '.join(KINDS)}")
        if f.get("relation", ">") not in RELATIONS:
            raise ValueError(f"{path}: relation {f['relation']!r}; allowed: {', '.join(RELATIONS)}")
        for name in rows_of(f):
            if name not in names:
                raise ValueError(f"{path}: finding {f.get('text')!r} names unknown row {name!r}")
        if f.get("baseline") is not None and f["baseline"] not in task.finding_baselines:
            raise ValueError(f"{path}: finding {f.get('text')!r}: baseline {f['baseline']!r}; "
                             f"allowed for {task.name}: {list(task.finding_baselines)}")
        if f.get("metric") not in doc["metrics"]:
            raise ValueError(f"{path}: finding {f.get('text')!r}: metric {f.get('metric')!r} "
                             f"is not one of {list(doc['metrics'])}")


def _registry(task) -> dict:
    """``{key: Metric}`` a table of ``task`` may name: the task's metrics, its extra ones,
    the normaliser fallback share and each metric scored on noisy boxes (``KEY_noisy``)."""
    from ..metrics.spec import NORMALISER_FALLBACK

    known = {m.key: m for m in (*task.metrics, *task.extra_metrics, NORMALISER_FALLBACK)}
    for m in list(known.values()):
        known[f"{m.key}_noisy"] = type(m)(f"{m.key}_noisy", f"{m.label} noisy boxes", m.unit,
                                          m.better, m.fmt)
    return known


def metric_specs(task, named, path) -> dict:
    """The table's metrics as ``{key: {"label", "better", "format"}}``, from the task
    registry: a table file names its metrics (a list, or a mapping whose entries may give
    only a ``label`` of the table's own); direction and format are the task's, and a file
    that states them otherwise is refused."""
    known = _registry(task)
    items = {k: None for k in named} if isinstance(named, list) else named
    if not isinstance(items, dict) or not items:
        raise ValueError(f"{path}: metrics must be a non-empty list of metric names (or a "
                         "mapping of names to {label: ...})")
    out = {}
    for key, own in items.items():
        m = known.get(key)
        if m is None:
            raise ValueError(f"{path}: metric {key!r} is not one that task {task.name!r} "
                             f"scores; allowed: {', '.join(known)}")
        own = own or {}
        if not isinstance(own, dict) or set(own) - {"label", "better", "format"}:
            raise ValueError(f"{path}: metric {key!r}: only a label may be given, got {own!r}")
        for field, value in (("better", m.better), ("format", m.fmt)):
            if field in own and own[field] != value:
                raise ValueError(f"{path}: metric {key!r}: {field} {own[field]!r} differs from "
                                 f"the task registry's {value!r} (training/tasks/); leave it "
                                 "out, the registry's is used")
        out[key] = {"label": own.get("label", m.header), "better": m.better, "format": m.fmt}
    return out


def row_data(data, row: dict) -> str:
    """Where a row reads: ``data``, or with the row's ``data_suffix`` the sibling dataset
    ``data + suffix`` (``d/medium-poses`` -> ``d/medium-poses-bones5``; a file
    ``d/clips.h5`` -> ``d/clips-bones5.h5``)."""
    suffix = row.get("data_suffix")
    if not suffix:
        return str(data)
    p = Path(data)
    if p.suffix in (".h5", ".hdf5"):
        return str(p.with_name(p.stem + suffix + p.suffix))
    return str(p.with_name(p.name + suffix))


def row_crop_box(table: dict, row: dict) -> str | None:
    """The crop-box policy a row's data must have: ``mask`` for every pose-estimation row
    unless it asks for ``mask+joints`` (an upper bound); None for the other tasks."""
    if table["task"] != "pose_estimation":
        return None
    return row.get("crop_box", "mask")


def prepare_row_data(table: dict, row: dict, opts: dict, convert: bool = True) -> dict:
    """Checks (and with ``convert`` makes) the data of one row for its crop-box policy;
    returns ``opts`` with ``data`` pointing where the row reads.

    A bsp-convert file made with another policy is refused (ValueError naming both and how
    to convert). A dataset directory is converted by bsp-train with the default (mask
    boxes); a row that asks for ``mask+joints`` gets its own cached conversion here, and
    its ``data`` becomes that file."""
    if convert and row.get("data_suffix") and not Path(opts["data"]).exists():
        make = (table.get("data_variants") or {}).get(row["data_suffix"])
        raise ValueError(f"table {table['table']!r} row {row['name']!r} reads {opts['data']} "
                         f"(--data + data_suffix {row['data_suffix']!r}), which does not "
                         "exist" + (f"; make it with: {make}" if make else ""))
    want = row_crop_box(table, row)
    if want is None:
        return opts
    data = Path(opts["data"])
    where = f"table {table['table']!r} row {row['name']!r}"
    if data.is_file() and data.suffix in (".h5", ".hdf5"):
        from ..conversion.vds import open_clip_file
        from ..data.cache import file_crop_box

        with open_clip_file(data) as f:
            have = file_crop_box(f.attrs)
        if have != want:
            raise ValueError(
                f"{data} was converted with --crop-box {have}, but {where} needs --crop-box "
                f"{want} (every pose-estimation row is scored on mask-box crops; mask+joints "
                "only in a row that asks for it as an upper bound): give the dataset "
                f"directory, or convert again with bsp-convert DATASET OUT.h5 --crop-box {want}")
        return opts
    if want == "mask" or (not convert and not data.is_dir()):
        return opts
    from ..training.setup import make_datamodule, prepare_data

    dm = make_datamodule(C.defaults() | opts)
    dm.convert_options["crop_box"] = want
    if convert:
        prepare_data(dm, stages=())
    return dict(opts, data=str(dm.h5_path))


def rows_of(f: dict) -> list:
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
    opts.update(data=row_data(data, row), out=str(run_dir))
    return C.normalise(opts, f"{table['table']} row {row['name']!r}")


def wanted_rows(tab: dict, rows=None) -> list:
    """The names of the rows to run: all, or ``rows`` (ValueError naming unknown ones),
    plus every row whose run another wanted row reads (``initial_of``)."""
    names = [r["name"] for r in tab["rows"]]
    wanted = list(names) if not rows else list(rows)
    bad = [r for r in wanted if r not in names]
    if bad:
        raise ValueError(f"unknown row(s) {bad} of table {tab['table']!r}; allowed: "
                         + ", ".join(names))
    by_name = {r["name"]: r for r in tab["rows"]}
    for name in list(wanted):
        src = by_name[name].get("initial_of")
        if src and src not in wanted:
            wanted.append(src)
    return wanted
