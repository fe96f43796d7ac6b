"""Options of ``bsp-train``: one table (``OPTIONS``) drives the command line (a jsonargparse
parser, :func:`parser`), ``--config run.yaml`` (safe YAML, same names with ``_`` or ``-``),
the Python API (``bsp_fast.train(**options)``: :func:`normalise`), ``--print-config`` and
the resolved ``config.yaml`` every run writes back (:func:`dump`).

Precedence: built-in defaults < the saved config of a ``--resume``d run < ``--config``
YAML < options given on the command line (or as keywords), whatever their order on the
line (``training.train.resolve_config``; docs/design.md says why ``--config`` is not jsonargparse's
``ActionConfigFile``).

Adding an option is one entry in ``OPTIONS``: ``_o(name, kind, default, help, group,
...)``, where ``kind`` names a converter of ``KINDS`` (:mod:`bsp_fast.training.option_kinds`) or is a
function ``value -> value`` that raises :class:`ConfigError` (or ``ValueError``) for a bad
value. The same entry is an override of ``bsp-reproduce`` (every option but the run's
identity) and, with ``scoring=True``, of ``bsp-eval`` and ``bsp-predict``
(:mod:`.overrides`): one declaration, the same names, types and messages everywhere.
"""
from __future__ import annotations

import argparse
import re
from dataclasses import dataclass
from pathlib import Path

from ..data import mix_tables  # mixing tables (no torch)
from ..command_line import did_you_mean
from ..defaults import SEED
from ..models import catalogue  # the registered models, without torch
from .option_kinds import KINDS, ConfigError, parse_hp  # the value converters
from .tasks import TASKS, get_task  # the task registry (no torch)

__all__ = ["OPTIONS", "BY_NAME", "KINDS", "ConfigError", "defaults", "parser",
           "parse_command_line", "read_yaml", "normalise", "validate",
           "parse_hp", "dump", "write_yaml", "MergeItems"]

ACCELERATORS = ("auto", "cpu", "gpu")
STRATEGIES = ("auto", "ddp", "ddp_spawn", "ddp_find_unused_parameters_true")
PRECISIONS = ("auto", "32", "64", "bf16-mixed", "16-mixed", "bf16-true")
LOGGERS = ("csv", "tensorboard", "wandb")
LIFTING_TARGETS = ("absolute", "world", "camera")


@dataclass(frozen=True)
class Option:
    name: str
    #: a KINDS name (int, float, str, path, flag, bool, mjp, hp, devices, mix, files) or a
    #: function ``value -> value`` raising ConfigError or ValueError
    kind: object
    default: object
    help: str
    group: str
    choices: tuple = ()
    minimum: float | None = None
    metavar: str | None = None
    #: also an option of bsp-eval and bsp-predict: how a saved run is scored (its
    #: input corruption, batches, hardware), not what was trained
    scoring: bool = False

    def convert(self, value):
        """``value`` (a command-line string or a YAML/Python value) as this option's type;
        :class:`ConfigError` naming the option and the allowed values otherwise."""
        if value is None:
            if self.kind in ("flag", "bool"):
                raise ConfigError(f"{self.name} must be true or false, got null")
            return None
        try:
            value = (KINDS[self.kind] if isinstance(self.kind, str) else self.kind)(value)
        except ConfigError:
            raise
        except (TypeError, ValueError):
            what = {"int": "an integer", "float": "a finite number", "str": "a string",
                    "path": "a string"}.get(self.kind, "a valid value")
            raise ConfigError(f"{self.name} expects {what}, got {value!r}") from None
        if self.choices and value not in self.choices:
            raise ConfigError(f"{self.name} must be one of {list(self.choices)}, got {value!r}"
                              + did_you_mean(value, self.choices))
        if self.minimum is not None and value < self.minimum:
            raise ConfigError(f"{self.name} must be >= {self.minimum}, got {value!r}")
        return value


_o = Option  # _o(name, kind, default, help, group, choices=, minimum=, metavar=, scoring=)


OPTIONS: tuple = (
    # ------------------------------------------------------------------ what to train
    _o("task", "str", None, "task: " + ", ".join(TASKS), "run", choices=tuple(TASKS)),
    _o("model", "str", None, "registered model of the task (see the list below)", "run"),
    _o("data", "path", None, "CARLA-BSP dataset directory (converted on first use, cached "
       "in that directory) or a bsp-convert HDF5 file", "run", metavar="DATASET_OR_H5"),
    _o("out", "path", None, "run directory (default runs/TASK-MODEL-YYYYmmdd-HHMMSS); written "
       "under a temporary name and renamed when complete", "run", metavar="RUN_DIR"),
    _o("force", "flag", False, "replace an existing run directory", "run"),
    _o("resume", "path", None, "continue a run (its directory or a .ckpt) from its last "
       "checkpoint; its saved config is the base, options given here override (e.g. a "
       "larger --epochs). Without --out the run directory is updated in place", "run",
       metavar="RUN_OR_CKPT"),
    _o("seed", "int", SEED, "seed of weights, train-time noise/augmentation and batch order; "
       "the same seed on the same data gives the same metrics on CPU", "run", minimum=0),
    _o("quiet", "flag", False, "no progress output and no initial metrics; the results "
       "table and the path written are still printed", "run"),
    # ------------------------------------------------------------------ data
    _o("clip_length", "int", None, "frames per clip when converting (default 30; 16 with "
       "--benchmark); checked against an existing HDF5 file", "data", minimum=1, metavar="L"),
    _o("clip_offset", "int", None, "frames between consecutive train clips when converting "
       "(default L; 6 with --benchmark)", "data", minimum=1, metavar="N"),
    _o("eval_clip_offset", "int", None, "the same for val/test clips (default --clip-offset)",
       "data", minimum=1, metavar="N"),
    _o("benchmark", "flag", False, "the crossing benchmark's time-to-event windows (16 frames "
       "every 6, video-level labels)", "data"),
    _o("balance", "flag", False, "balance the train split's classes", "data"),
    _o("label", "str", "last", "clip label when converting: last or any:F", "data",
       metavar="last|any:F"),
    _o("fov", "float", None, "camera field of view in degrees when converting (default: the "
       "dataset's config.yaml, else 90)", "data", minimum=1e-6),
    _o("crop_size", "int", 128, "side of the pedestrian crops when converting media "
       "(pose_estimation)", "data", minimum=8, metavar="S"),
    _o("split_seed", "int", SEED, "seed of the converter's recording split", "data",
       minimum=0),
    _o("noise", "float", 0.0, "Gaussian noise sigma in pixels on the 2D inputs (train, val "
       "and test; val/test noise is fixed by the evaluation seed)", "data", minimum=0.0,
       metavar="SIGMA", scoring=True),
    _o("mjp", "mjp", 0.0, "missing-joint probability of the 2D inputs: one value, or 26 "
       "comma-separated values (one per joint)", "data", metavar="P[,P...]", scoring=True),
    _o("augment", "bool", True, "random flips and rotations of the train clips "
       "(classification and autoencoder only)", "data"),
    _o("box_jitter_scale", "float", 0.0, "pose_estimation: train-time box jitter, crop-box "
       "side x U[1-S, 1+S], re-cut from the stored context crops (0: off)", "data",
       minimum=0.0, metavar="S"),
    _o("box_jitter_shift", "float", 0.0, "pose_estimation: train-time box jitter, centre "
       "moved by U[-T, T] x side per axis (0: off)", "data", minimum=0.0, metavar="T"),
    _o("image_augment", "bool", False, "pose_estimation: augment the train crops (random "
       "flips with the left/right joints swapped, zoom x U[0.9, 1.1], shift, rotation by "
       "--image-rotation, colour jitter), the joints moved with the pixels", "data"),
    _o("image_rotation", "float", 15.0, "pose_estimation: with --image-augment, rotation "
       "uniform in [-DEG, DEG] degrees about the crop centre", "data", minimum=0.0,
       metavar="DEG"),
    _o("lifting_target", "str", "absolute", "3D frame of the lifting targets", "data",
       choices=LIFTING_TARGETS),
    _o("mix", "mix", None, "train on clip files in stated shares: a mixing table (name in "
       "experiments/mix/, YAML file, or in --config the table itself); config.yaml records "
       "it (docs/interop.md, Mixed training)", "data", metavar="TABLE"),
    _o("mix_data", "files", {}, "NAME=FILE: a --mix or --test-on source's clip file (repeatable;"
       " a source marked data: true reads --data)", "data", metavar="NAME=FILE", scoring=True),
    _o("test_on", "str", None, "with --mix: test on this source's test split alone (default: "
       "every source's)", "data", metavar="NAME", scoring=True),
    _o("test_data", "path", None, "score the test split of this dataset directory instead "
       "of --data's, converted with the run's own options (clip length, windows, split "
       "seed): a table's registered independent test set (docs/reproduce.md, 'Tables any "
       "machine can finish')", "data", metavar="DIR", scoring=True),
    # ------------------------------------------------------------------ model
    _o("hp", "hp", {}, "a model hyper-parameter, KEY=VALUE (repeatable; YAML value syntax); "
       "checked against the model's hyper-parameters", "model", metavar="KEY=VALUE"),
    _o("lr", "float", None, "learning rate (default: the model's, e.g. AdamW 1e-4)", "model",
       minimum=0.0),
    # ------------------------------------------------------------------ training
    _o("epochs", "int", 30, "maximum number of epochs", "training", minimum=1),
    _o("max_steps", "int", 0, "maximum number of optimiser updates (0: no cap; --epochs "
       "still applies)", "training", minimum=0, metavar="N"),
    _o("batch_size", "int", 256, "clips per batch (per process with DDP)", "training",
       minimum=1, scoring=True),
    _o("early_stop", "int", 0, "stop after this many epochs without a better val loss "
       "(0: never)", "training", minimum=0, metavar="EPOCHS"),
    _o("workers", "int", 0, "DataLoader worker processes per training process", "training",
       minimum=0, scoring=True),
    _o("threads", "int", 0, "torch CPU threads per training process (0: torch's default, "
       "the core count); 1 is often fastest for small models or on a busy machine",
       "training", minimum=0, metavar="N", scoring=True),
    _o("accelerator", "str", "auto", "where to run: cpu, gpu, or auto (a GPU when there is "
       "one)", "training", choices=ACCELERATORS,
       scoring=True),
    _o("devices", "devices", "auto", "number of devices (processes with DDP) or 'auto' or a "
       "comma-separated list of GPU indices", "training"),
    _o("strategy", "str", "auto", "Lightning strategy (ddp: one process per device; on CPU "
       "through gloo)", "training", choices=STRATEGIES),
    _o("num_nodes", "int", 1, "machines of a multi-machine DDP run: start bsp-train on each "
       "with MASTER_ADDR, MASTER_PORT and NODE_RANK set, or under torchrun "
       "(docs/distributed.md)", "training", minimum=1, metavar="N"),
    _o("precision", "str", "auto", "arithmetic precision; auto = bf16-mixed on GPUs that "
       "support it; on a CPU with AVX512-BF16/AMX decided by a short timed probe of this "
       "model on this machine (cached; config.yaml says what and why); 32 otherwise "
       "(docs/training.md, Precision)", "training", choices=PRECISIONS, scoring=True),
    _o("compile", "str", "off", "torch.compile the model (inductor) before training: on or "
       "off; off by default because on CPU it was slower end to end for every model at the "
       "quick budgets, compile time included (docs/performance.md, Training)", "training",
       choices=("off", "on")),
    _o("checkpoint_every", "str", "5m", "save checkpoints/last.ckpt at the first batch or "
       "epoch end once this long has passed since the last save, and after the last epoch "
       "(e.g. 5m, 90s, 1h; 0: at every epoch end and never within one), so a killed run "
       "resumes near where it stopped (--resume)", "training", metavar="DURATION"),
    _o("limit_batches", "int", 0, "use at most this many batches of each split per epoch "
       "(0: all; for smoke tests - metrics then cover part of a split)", "training",
       minimum=0, metavar="N", scoring=True),
    _o("logger", "str", "csv", "CSV logs are always written; tensorboard or wandb (offline) "
       "log as well when installed", "training", choices=LOGGERS),
)
BY_NAME = {o.name: o for o in OPTIONS}


def defaults() -> dict:
    """Every option at its built-in default."""
    return {o.name: (dict(o.default) if isinstance(o.default, dict) else o.default)
            for o in OPTIONS}


# ---------------------------------------------------------------------- whole configs
def normalise(values: dict, source: str = "options") -> dict:
    """Known option names (``-`` or ``_``) with converted values; unknown names are a
    :class:`ConfigError` listing the allowed ones."""
    out = {}
    for key, value in values.items():
        name = str(key).replace("-", "_")
        if name not in BY_NAME:
            raise ConfigError(f"{source}: unknown option {key!r}"
                              f"{did_you_mean(name, BY_NAME)}; allowed: "
                              + ", ".join(o.name for o in OPTIONS))
        out[name] = BY_NAME[name].convert(value)
    return out


def parse_duration(text) -> float:
    """``"10m"``, ``"90s"``, ``"1.5h"`` or a number of seconds -> seconds; ``0``/``off``:
    no checkpoints within epochs. ValueError for anything else."""
    s = str(text).strip().lower()
    if s in ("0", "off", "none", "no", "false"):
        return 0.0
    m = re.fullmatch(r"(\d+(?:\.\d*)?)\s*(s|m|h|min)?", s)
    if not m:
        raise ValueError(f"checkpoint_every expects a duration such as 10m, 90s, 1h or 0 "
                         f"(off), got {text!r}")
    unit = {"s": 1, None: 1, "m": 60, "min": 60, "h": 3600}[m.group(2)]
    return float(m.group(1)) * unit


def validate(cfg: dict) -> dict:
    """Cross-option checks on a complete config (task, model and hyper-parameters against
    the task and model registries)."""
    cfg = dict(cfg)
    if cfg.get("task") is None:
        raise ConfigError("no task given; allowed: " + ", ".join(TASKS))
    names = catalogue.names(cfg["task"])  # read from the model modules, without torch
    if cfg.get("model") is None:
        raise ConfigError(f"no model given for task {cfg['task']!r}; allowed: "
                          + ", ".join(names))
    if cfg["model"] not in names:
        raise ConfigError(f"unknown model {cfg['model']!r} for task {cfg['task']!r}"
                          f"{did_you_mean(cfg['model'], names)}; allowed: {', '.join(names)}")
    if cfg.get("mix") is not None or cfg.get("mix_data") or cfg.get("test_on"):
        cfg = mix_tables.check_run(cfg, error=ConfigError)  # may set data: the first file
    if cfg.get("data") is None:
        raise ConfigError("no data given (--data DATASET_DIR or clips.h5)")
    if cfg.get("test_data") is not None and (cfg.get("mix") is not None
                                             or cfg.get("test_on")):
        raise ConfigError("test_data replaces --data's test split; with --mix, test on "
                          "another dataset with --test-on NAME --mix-data NAME=FILE")
    if cfg["label"] != "last" and not cfg["label"].startswith("any:"):
        raise ConfigError(f"label must be 'last' or 'any:F', got {cfg['label']!r}")
    try:
        parse_duration(cfg.get("checkpoint_every", 0))
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    if get_task(cfg["task"]).image_inputs and (cfg["noise"] or cfg["mjp"]):
        raise ConfigError(f"noise/mjp deform 2D joint inputs; {cfg['task']} reads images")
    allowed = catalogue.hparams(cfg["task"], cfg["model"])
    bad = sorted(set(cfg["hp"]) - set(allowed))
    if bad:
        raise ConfigError(f"model {cfg['model']!r} has no hyper-parameter {bad[0]!r}"
                          f"{did_you_mean(bad[0], allowed)}; allowed: "
                          f"{', '.join(f'{k}={v!r}' for k, v in allowed.items())}")
    return cfg


# ---------------------------------------------------------------------- YAML
def read_yaml(path) -> dict:
    """A run config (``--config``): a mapping of option names, safe YAML only; a run's
    ``config.yaml`` is one (its ``resolved``, ``versions`` and ``machine`` records are
    ignored)."""
    import yaml

    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"--config {p}: no such file")
    try:
        doc = yaml.safe_load(p.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        raise ConfigError(f"--config {p}: not valid YAML ({exc})") from None
    if doc is None:
        return {}
    if not isinstance(doc, dict):
        raise ConfigError(f"--config {p}: expected a mapping of option: value")
    doc = {k: v for k, v in doc.items() if k not in ("resolved", "versions", "machine")}
    return normalise(doc, f"--config {p}")


def dump(cfg: dict, extra: dict | None = None) -> str:
    """The config as YAML usable as ``--config`` (``--print-config``, ``config.yaml``):
    every option in table order, then ``extra`` (what the run resolved: precision, data
    file, model hyper-parameters, versions, machine)."""
    import yaml

    doc = {o.name: cfg.get(o.name) for o in OPTIONS}
    doc.update(extra or {})
    return ("# bsp-train resolved config (usable as --config)\n"
            + yaml.safe_dump(doc, sort_keys=False, default_flow_style=None))


def write_yaml(cfg: dict, path, extra: dict | None = None) -> None:
    Path(path).write_text(dump(cfg, extra), encoding="utf-8")


# ---------------------------------------------------------------------- command line
class MergeItems(argparse.Action):
    """``--hp a=1 --hp b=2`` -> ``{"a": 1, "b": 2}`` (each item already a dict)."""

    def __call__(self, parser, namespace, values, option_string=None):
        setattr(namespace, self.dest, {**(getattr(namespace, self.dest, None) or {}), **values})


def parser(prog: str = "bsp-train", description: str | None = None, epilog: str | None = None):
    """The command line: jsonargparse's ``ArgumentParser`` with ``TASK MODEL``, ``--config``,
    ``--print-config`` and one option per table entry, typed by the entry's converter (its
    :class:`ConfigError` is the parser's message). Nothing has a parser default: read the
    options given with :func:`parse_command_line`."""
    from .._extras import require

    ArgumentParser = require("jsonargparse", prog).ArgumentParser
    S = argparse.SUPPRESS
    p = ArgumentParser(prog=prog, description=description, epilog=epilog,
                       formatter_class=argparse.RawDescriptionHelpFormatter,
                       exit_on_error=False, print_config=None, allow_abbrev=True)
    for o in OPTIONS[:2]:  # argparse passes an absent positional's default to its type
        p.add_argument(o.name, nargs="?", default=S, metavar=o.name.upper(), help=o.help,
                       type=lambda v, o=o: v if v is S else o.convert(v))
    p.add_argument("--config", default=S, metavar="RUN.yaml",
                   help="read options from a YAML file (any option below, by name); "
                        "options on the command line override it, wherever they stand")
    p.add_argument("--print-config", action="store_true", default=S,
                   help="print the resolved config as YAML (usable as --config) and exit")
    titles = {"run": "run", "data": "data (converter and loader options)",
              "model": "model", "training": "training"}
    groups = {g: p.add_argument_group(t) for g, t in titles.items()}
    for o in OPTIONS[2:]:
        default = o.default if not isinstance(o.default, dict) else "{}"
        text = o.help + (f" (default: {default})" if default not in (None, False, "{}") else "")
        kw = dict(default=S, help=text)
        if o.kind == "flag":
            kw.update(action="store_true")
        elif o.kind == "bool":
            kw.update(action=argparse.BooleanOptionalAction)
        else:
            kw.update(type=o.convert, metavar=o.metavar or
                      ("|".join(o.choices) if o.choices else o.name.upper()))
            if o.kind in ("hp", "files"):
                kw.update(action=MergeItems)
        groups[o.group].add_argument("--" + o.name.replace("_", "-"), **kw)
    return p


def parse_command_line(p, argv) -> tuple:
    """``(options given, --config path or None, --print-config)``; a bad or unknown
    option raises ``argparse.ArgumentError``."""
    given = p.parse_args(list(argv), defaults=False).as_dict()
    return given, given.pop("config", None), bool(given.pop("print_config", False))
