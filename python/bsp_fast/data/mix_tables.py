"""Mixing tables: which clip files a mixed training run reads and in what shares, checked
without PyTorch (bsp-train's ``mix``, ``mix_data`` and ``test_on`` options are checked
here before anything is trained). :class:`~bsp_fast.data.mixed.MixedDataModule` trains on
them; docs/interop.md, "Mixed training".

A mixing table is a mapping: a YAML file (``experiments/mix/NAME.yaml``, found by name in
:func:`mix_dirs`), or the ``mix`` option of a bsp-train ``--config`` file::

    task: autoencoder        # optional: the task it is for
    clip_length: 30          # optional: every source's clip length
    epoch_size: 20000        # optional: train clips per epoch (default: all sources')
    sources:
      - {name: jaad, share: 0.1}                  # bsp-train --mix-data jaad=FILE
      - {name: carla_bsp, share: 0.4, data: true}  # reads bsp-train's --data
      - {name: amass, share: 0.5}

The table names sources, not files: a run gives each source's clip file as
``--mix-data NAME=FILE``, except the one source marked ``data: true``, which reads
``--data`` (a CARLA-BSP dataset directory, converted with the run's options, or a clip
file).
"""
from __future__ import annotations

import functools
import math
import re
from pathlib import Path

import numpy as np

__all__ = ["MIX_TASKS", "quotas", "mix_dirs", "mix_table", "check_mix", "read_mix", "as_mix",
           "parse_files", "plan_mix", "check_run"]

MIX_TASKS = ("classification", "autoencoder")
MIX_KEYS = ("task", "clip_length", "epoch_size", "sources", "table")
SOURCE_KEYS = ("name", "share", "data")
_NAME = re.compile(r"[A-Za-z0-9_.-]+")
_MAKE = ("make it with bsp-interop import jaad|pie|coco|openpose ... --obs-length L, or "
         "bsp-convert DATASET OUT.h5 --clip-length L (docs/interop.md)")


def _raising(fn):
    """``fn(..., error=ValueError)``: its ValueError raised as ``error`` with the same
    message (bsp-train's option checks pass their ConfigError)."""
    @functools.wraps(fn)
    def wrapped(*args, error=ValueError, **kwargs):
        try:
            return fn(*args, **kwargs)
        except ValueError as exc:
            if error is ValueError:
                raise
            raise error(str(exc)) from None
    return wrapped


def quotas(shares, total: int) -> np.ndarray:
    """Integer counts proportional to ``shares`` adding up to ``total`` (largest
    remainders, ties to the earlier source)."""
    s = np.asarray(shares, np.float64)
    raw = s / s.sum() * total
    counts = np.floor(raw).astype(np.int64)
    order = np.argsort(-(raw - counts), kind="stable")
    counts[order[:total - counts.sum()]] += 1
    return counts


def mix_dirs() -> list:
    """Where mixing tables are looked up by name, in order: ``$BSP_EXPERIMENTS/mix``,
    ``./experiments/mix``, the tables installed with the package
    (``bsp_fast/experiments/mix``), the source tree's ``experiments/mix``
    (:func:`bsp_fast.defaults.experiments_dirs`, as bsp-reproduce's tables)."""
    from ..defaults import experiments_dirs

    return experiments_dirs("mix")


def mix_table(name_or_path) -> Path:
    """A mixing table's file: a path to a YAML file as is, or a table name
    (``"autoencoder"``) looked up as ``NAME.yaml`` in :func:`mix_dirs`."""
    p = Path(name_or_path)
    if p.suffix in (".yaml", ".yml") or p.is_file():
        if not p.is_file():
            raise FileNotFoundError(f"mixing table {p} does not exist")
        return p
    found = [d / f"{p.name}.yaml" for d in mix_dirs() if (d / f"{p.name}.yaml").is_file()]
    if not found:
        names = sorted({f.stem for d in mix_dirs() if d.is_dir() for f in d.glob("*.yaml")})
        raise FileNotFoundError(f"no mixing table {p.name!r} in {[str(d) for d in mix_dirs()]}"
                                f"; tables found: {names or 'none'}")
    return found[0]


def _positive_int(doc: dict, key: str, where: str) -> None:
    v = doc.get(key)
    if v is not None and (isinstance(v, bool) or not isinstance(v, int) or v <= 0):
        raise ValueError(f"{where}: {key} must be a positive integer, got {v!r}")


def check_mix(doc, where: str = "mix") -> dict:
    """A mixing table (a mapping as YAML reads it) checked and copied: known keys only;
    ``sources`` with unique names, shares that are numbers > 0 adding up to 1, at most one
    marked ``data: true``; ``clip_length`` and ``epoch_size`` positive integers; ``task``
    one of :data:`MIX_TASKS`. ValueError naming ``where`` and what is allowed."""
    if not isinstance(doc, dict) or not isinstance(doc.get("sources"), list) \
            or not doc["sources"]:
        raise ValueError(f"{where}: a mixing table needs a 'sources' list of "
                         "{name, share} entries")
    unknown = sorted(set(doc) - set(MIX_KEYS))
    if unknown:
        raise ValueError(f"{where}: unknown key(s) {unknown}; allowed: {', '.join(MIX_KEYS)}")
    if doc.get("task") is not None and doc["task"] not in MIX_TASKS:
        raise ValueError(f"{where}: task {doc['task']!r}; a mix trains one of {list(MIX_TASKS)} "
                         "(2D clip tasks)")
    for key in ("clip_length", "epoch_size"):
        _positive_int(doc, key, where)
    sources = []
    for i, s in enumerate(doc["sources"]):
        if not isinstance(s, dict) or set(s) - set(SOURCE_KEYS):
            raise ValueError(f"{where}: source {i + 1} must be a mapping with keys from "
                             f"{list(SOURCE_KEYS)}, got {s!r}")
        name, share = s.get("name"), s.get("share")
        if not isinstance(name, str) or not _NAME.fullmatch(name):
            raise ValueError(f"{where}: source {i + 1} needs a name of letters, digits, "
                             f"'_', '-' or '.', got {name!r}")
        if isinstance(share, bool) or not isinstance(share, (int, float)) \
                or not math.isfinite(share) or share <= 0:
            raise ValueError(f"{where}: source {name!r}: share must be a number > 0, "
                             f"got {share!r}")
        if not isinstance(s.get("data", False), bool):
            raise ValueError(f"{where}: source {name!r}: data must be true or false")
        sources.append(dict(name=name, share=float(share), data=bool(s.get("data", False))))
    names = [s["name"] for s in sources]
    if len(set(names)) != len(names):
        raise ValueError(f"{where}: source names must be unique, got {names}")
    total = sum(s["share"] for s in sources)
    if abs(total - 1) > 1e-6:  # a typo in a share changes every other source's share
        raise ValueError(f"{where}: shares must add up to 1, got {total:g} ({names})")
    if sum(s["data"] for s in sources) > 1:
        raise ValueError(f"{where}: at most one source reads --data (data: true), got "
                         f"{[s['name'] for s in sources if s['data']]}")
    return dict({k: doc[k] for k in MIX_KEYS if doc.get(k) is not None}, sources=sources)


def read_mix(path) -> dict:
    """A mixing table's YAML file, checked (:func:`check_mix`)."""
    import yaml

    try:
        with Path(path).open("r", encoding="utf-8") as fh:
            doc = yaml.safe_load(fh)
    except yaml.YAMLError as exc:
        raise ValueError(f"{path}: not valid YAML ({exc})") from None
    return check_mix(doc, str(path))


@_raising
def as_mix(value) -> dict:
    """bsp-train's ``mix`` option as the checked table it names: a table name or YAML path
    (the table's own contents, with ``table``: the file it was read from, so config.yaml
    records the mix itself), or a mapping as is."""
    if isinstance(value, dict):
        return check_mix(value)
    if not isinstance(value, (str, Path)):
        raise ValueError(f"mix must be a mixing table's name, a YAML file or a mapping, "
                         f"got {value!r}")
    try:
        path = mix_table(value)
    except FileNotFoundError as exc:
        raise ValueError(str(exc)) from None
    return dict(read_mix(path), table=str(path.absolute()))


@_raising
def parse_files(value) -> dict:
    """``mix_data``: ``NAME=FILE`` items (a list, one string with commas, or a mapping) ->
    ``{name: absolute path}`` (absolute: a resumed run or bsp-eval may start elsewhere)."""
    if value is None:
        return {}
    if isinstance(value, dict):
        pairs = list(value.items())
    else:
        items = [value] if isinstance(value, str) else list(value)
        pairs = []
        for item in (p for v in items for p in str(v).split(",") if p.strip()):
            name, sep, path = item.partition("=")
            if not sep:
                raise ValueError(f"mix_data expects NAME=FILE, got {item!r}")
            pairs.append((name, path))
    out = {}
    for name, path in pairs:
        name, path = str(name).strip(), str(path or "").strip()
        if not _NAME.fullmatch(name) or not path:
            raise ValueError(f"mix_data expects NAME=FILE with a source name of letters, "
                             f"digits, '_', '-' or '.', got {name}={path}")
        out[name] = str(Path(path).expanduser().absolute())
    return out


def plan_mix(mix: dict, files: dict, data=None, test_on: str | None = None) -> dict:
    """Where each source of ``mix`` (a checked table) reads: ``{"sources": [{name, share,
    data, h5_path}], "test": {name, data, h5_path} or None}``; a ``data: true`` source's
    ``h5_path`` is None (the run's ``--data``, converted first). ``files``: the
    ``mix_data`` mapping; ``test_on``: a source of the mix or another name in ``files``
    (e.g. a test-only dataset). ValueError naming every source without a file, a missing
    file, or an unknown test source."""
    sources = [dict(s, h5_path=None if s["data"] else files.get(s["name"]))
               for s in mix["sources"]]
    missing = [s["name"] for s in sources if not s["data"] and s["h5_path"] is None]
    if missing:
        raise ValueError(f"mix source(s) {missing} have no clip file: give "
                         + " ".join(f"--mix-data {n}=FILE" for n in missing) + f" ({_MAKE})")
    if any(s["data"] for s in sources) and data is None:
        raise ValueError(f"mix source {[s['name'] for s in sources if s['data']][0]!r} "
                         "reads --data (data: true): give --data DATASET_OR_H5")
    test = None
    if test_on is not None:
        known = {s["name"]: s for s in sources}
        if test_on not in known and test_on not in files:
            raise ValueError(f"test_on {test_on!r} has no clip file: give --mix-data "
                             f"{test_on}=FILE (a test-only dataset), or test on a source of "
                             f"the mix: {', '.join(known)}")
        own = known.get(test_on)
        test = dict(name=test_on, data=bool(own and own["data"]),
                    h5_path=own["h5_path"] if own else files[test_on])
    for s in sources + ([test] if test else []):
        if s["h5_path"] is not None and not Path(s["h5_path"]).is_file():
            # a missing input, not a bad option: exit 1 on the command line, as --data's
            raise FileNotFoundError(f"mix source {s['name']!r}: {s['h5_path']}: no such clip "
                                    f"file ({_MAKE})")
    return {"sources": sources, "test": test}


@_raising
def check_run(cfg: dict) -> dict:
    """bsp-train's cross-option checks of a mixed run (``mix``, ``mix_data``, ``test_on``):
    a mix of this task, one process, every source's file; ``data`` defaults to the first
    source's file when no source reads it. Returns the config; ValueError otherwise."""
    mix = cfg.get("mix")
    if mix is None:
        given = " and ".join(k for k in ("mix_data", "test_on") if cfg.get(k))
        raise ValueError(f"{given} without a mix: give --mix TABLE (mix_data names the "
                         "files of its sources, test_on its test source)")
    if cfg["task"] not in MIX_TASKS:
        raise ValueError(f"a mix trains one of {list(MIX_TASKS)} (2D clip tasks), not "
                         f"{cfg['task']!r}")
    if mix.get("task") not in (None, cfg["task"]):
        where = f"mix {mix['table']}" if mix.get("table") else "the mix"
        raise ValueError(f"{where} is a table for task {mix['task']!r}, this run trains "
                         f"{cfg['task']!r}")
    devices = cfg.get("devices", "auto")
    one_device = devices in ("auto", 1) or (isinstance(devices, list) and len(devices) == 1)
    if cfg.get("strategy", "auto") != "auto" or (cfg.get("num_nodes") or 1) > 1 \
            or not one_device:
        raise ValueError("a mix trains in one process (its batch sampler is not "
                         "distributed): --devices 1, --strategy auto, --num-nodes 1")
    if cfg.get("balance"):
        raise ValueError("--balance balances one file's train split; a mix sets each "
                         "source's share instead")
    plan = plan_mix(mix, cfg.get("mix_data") or {}, cfg.get("data"), cfg.get("test_on"))
    if cfg.get("data") is None:  # no source reads --data: the run's data is its first file
        cfg = dict(cfg, data=plan["sources"][0]["h5_path"])
    return cfg
