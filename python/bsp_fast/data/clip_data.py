"""``ClipData``: converts a CARLA-BSP dataset on first use and builds the loaders, in plain
Python (``dm.prepare_data(); dm.setup(); dm.train_dataloader()``); ``BSPDataModule``
(:mod:`.datamodule`) is the same as a Lightning ``LightningDataModule``.
"""
from __future__ import annotations

import os
import sys
from pathlib import Path

from .. import conversion
from ..defaults import CONVERT as DEFAULTS, POSE_CROP_CONTEXT
from . import cache as _cache
from .cache import file_crop_box
from ..conversion.inputs import poses_only
from .datasets import DEFAULT_EVAL_SEED, SPLITS, TASKS, ClipDataset

__all__ = ["ClipData", "BENCHMARK"]

BENCHMARK = dict(clip_length=DEFAULTS["benchmark_clip_length"],
                 clip_offset=DEFAULTS["benchmark_clip_offset"], benchmark=True, balance=True)
_NOT_OUTPUT = ("threads", "verify", "force", "progress", "strict")  # convert options only


def _plain_value(v) -> bool:
    """Whether ``v`` can go into a checkpoint's hyper-parameters (YAML/JSON-like)."""
    if v is None or isinstance(v, (bool, int, float, str)):
        return True
    if isinstance(v, (list, tuple)):
        return all(_plain_value(x) for x in v)
    if isinstance(v, dict):
        return all(isinstance(k, str) and _plain_value(x) for k, x in v.items())
    return False


def _check_arguments(a: dict) -> None:
    """ValueError for a constructor argument ClipData cannot use."""
    if a["task"] not in TASKS:
        raise ValueError(f"task must be one of {list(TASKS)}, got {a['task']!r}")
    if a["dataset_dir"] is None and a["h5_path"] is None:
        raise ValueError("BSPDataModule needs dataset_dir (converted on first use), h5_path, "
                         "or both")
    n = a["batch_size"]
    if not isinstance(n, int) or isinstance(n, bool) or n <= 0:
        raise ValueError(f"batch_size must be a positive integer, got {n!r}")
    if not isinstance(a["num_workers"], int) or a["num_workers"] < 0:
        raise ValueError(f"num_workers must be an integer >= 0, got {a['num_workers']!r}")
    bad = sorted(set(a["convert_options"] or {}) & set(_NOT_OUTPUT + ("dataset", "out_path")))
    if bad:
        raise ValueError(f"convert_options: {bad} are not conversion settings")


def _plain_options(a: dict) -> dict:
    """The constructor's arguments as a checkpoint's hyper-parameters (plain values:
    paths as text, only the dataset options that are plain)."""
    out = dict(a)
    for key in ("dataset_dir", "h5_path", "cache_dir", "test_dir"):
        out[key] = None if a[key] is None else str(a[key])
    for key in ("benchmark", "balance", "augment", "pin_memory", "verbose"):
        out[key] = bool(a[key])
    out["convert_options"] = dict(a["convert_options"] or {})
    out["dataset_options"] = {k: v for k, v in (a["dataset_options"] or {}).items()
                              if _plain_value(v)}
    return out


class ClipData:
    """Train/val/test loaders of one task over a converted HDF5 file (plain Python: the
    scoring commands use it without Lightning; :class:`BSPDataModule` is the same as a
    ``LightningDataModule``).

    Give ``dataset_dir`` (a CARLA-BSP dataset, converted on first use into ``cache_dir``),
    ``h5_path`` (an existing file, or where to write one) or both. The cached file is
    keyed by every conversion option that changes the output and checked against data.csv
    (size, and CRC-32 when it was modified), so changed options or a changed data.csv
    convert again; the module says on stderr when it converts and when it reuses
    (``verbose``). ``cache_dir`` defaults to ``<dataset_dir>/bsp_fast-cache`` (or
    ``~/.cache/bsp_fast/...`` when the dataset is read-only). An explicit ``h5_path`` that
    disagrees with the options or data.csv raises ``ValueError`` instead of being replaced.

    ``clip_length``/``clip_offset`` default as in :func:`bsp_fast.convert` (30/L, 16/6 with
    ``benchmark``). ``balance`` balances the train split (in the converter, and in the
    dataset for files converted without it). ``noise``/``mjp`` deform the 2D inputs, train
    ``augment`` adds flips and rotations for the 2D tasks. ``convert_options`` go to
    :func:`bsp_fast.convert` (e.g. ``fov``, ``label``, ``seed``, ``crop_size``; ``media``
    defaults to True for ``pose_estimation`` only); other keywords of
    :class:`ClipDataset` go in ``dataset_options``. Every option is saved as a
    hyper-parameter, so ``load_from_checkpoint`` rebuilds the same data (callables in
    ``dataset_options``, e.g. transforms, cannot be saved: pass them again).
    """

    def __init__(self, dataset_dir=None, h5_path=None, task: str = "classification",
                 clip_length: int | None = None, clip_offset: int | None = None,
                 benchmark: bool = False, balance: bool = False, noise: float = 0.0, mjp=0.0,
                 batch_size: int = 256, num_workers: int = 0, *, augment: bool = True,
                 seed: int | None = None, eval_seed: int = DEFAULT_EVAL_SEED,
                 sampler_seed: int | None = None, block_size: int = 32, pin_memory: bool = False,
                 persistent_workers: bool | None = None, convert_options: dict | None = None,
                 dataset_options: dict | None = None, cache_dir=None, verbose: bool = True,
                 test_dir=None):
        given = {k: v for k, v in locals().items() if k not in ("self", "__class__")}
        super().__init__()
        _check_arguments(given)
        self.dataset_dir = None if dataset_dir is None else Path(dataset_dir)
        self.task, self.benchmark_windows, self.balance = task, bool(benchmark), bool(balance)
        self._explicit = dict(clip_length=clip_length, clip_offset=clip_offset)
        L = clip_length or (BENCHMARK["clip_length"] if benchmark else DEFAULTS["clip_length"])
        self.clip_length = L
        self.clip_offset = clip_offset or (BENCHMARK["clip_offset"] if benchmark else L)
        self.convert_options = dict(convert_options or {})
        # media crops cost decoding time and space; only pose estimation reads them
        self.convert_options.setdefault("media", task == "pose_estimation")
        if task == "pose_estimation":  # box noise is cut out of the wider context crops
            self.convert_options.setdefault("crop_context", POSE_CROP_CONTEXT)
        self._given_h5 = h5_path is not None
        self._h5 = Path(h5_path) if h5_path is not None else None
        self.cache_dir = Path(cache_dir) if cache_dir is not None else None
        self.noise, self.mjp, self.augment = noise, mjp, bool(augment)
        self.batch_size, self.num_workers = batch_size, num_workers
        self.seed, self.eval_seed, self.sampler_seed = seed, eval_seed, sampler_seed
        self.block_size, self.pin_memory = block_size, bool(pin_memory)
        self.persistent_workers = (num_workers > 0 if persistent_workers is None
                                   else bool(persistent_workers))
        self.dataset_options = dict(dataset_options or {})
        self.verbose = bool(verbose)
        self.datasets: dict = {}
        self.conversion_report = None
        self.reused = None
        #: the constructor's arguments as plain values (a checkpoint's hyper-parameters)
        self.options = _plain_options(given)
        #: ``test_dir``: another dataset directory whose test split, converted with these
        #: same options, replaces this one's (a registered independent test set)
        self.test_data = None if test_dir is None else ClipData(**{
            **{k: v for k, v in given.items() if k not in ("h5_path", "cache_dir")},
            "dataset_dir": test_dir, "test_dir": None})

    @classmethod
    def benchmark(cls, dataset_dir=None, h5_path=None, task: str = "classification", **kwargs):
        """The report's crossing-classification setup: 16-frame clips every 6 frames from
        the time-to-event windows (video-level labels), balanced train split. Any keyword
        of the constructor overrides. (``bsp-convert --benchmark`` alone does not balance.)"""
        options = dict(BENCHMARK)
        options.update(kwargs)
        return cls(dataset_dir, h5_path, task, **options)

    def _rank_zero(self) -> bool:
        """Whether this process prints (one process here; DDP: see BSPDataModule)."""
        return True

    # ----------------------------------------------------------------- the converted file
    def _say(self, message: str) -> None:
        if self.verbose and self._rank_zero():
            print(f"bsp_fast.data: {message}", file=sys.stderr, flush=True)

    def _convert_kwargs(self) -> dict:
        options = dict(clip_length=self.clip_length, clip_offset=self.clip_offset,
                       benchmark=self.benchmark_windows, balance=self.balance)
        options.update(self.convert_options)
        return options

    def settings(self) -> dict:
        """The resolved conversion settings this module asks for (needs ``dataset_dir``)."""
        self._check_media()  # the task's own words, before the converter's
        return conversion.conversion_settings(self.dataset_dir, **self._convert_kwargs())

    @property
    def h5_path(self) -> Path:
        """The converted file: ``h5_path`` if given, else its place in ``cache_dir``."""
        if self._h5 is None:
            folder = self.cache_dir or _cache.default_cache_dir(self.dataset_dir)
            self._h5 = Path(folder) / _cache.cache_name(self.settings())
        return self._h5

    def _stale(self) -> str | None:
        """Why the existing file cannot be used (None: it can, or there is no dataset to
        compare it with)."""
        if self.dataset_dir is None:
            return None
        _, csv = conversion.dataset_csv(self.dataset_dir)
        return _cache.stale_reason(self.h5_path, self.settings(), csv)

    def _poses_only(self) -> bool:
        """Whether the dataset's config.yaml says it was generated with --poses-only."""
        root, _ = conversion.dataset_csv(self.dataset_dir)
        return poses_only(root)

    def _cache_note(self) -> str:
        folder = self.h5_path.parent
        n, size = _cache.cache_usage(folder)
        return (f"cache {folder}: {n} file(s), {_cache.format_bytes(size)} "
                f"(bsp-cache ls / bsp-cache prune {self.dataset_dir})")

    def prepare_data(self) -> None:
        """Converts ``dataset_dir`` into :attr:`h5_path` through the C++ core unless an
        up-to-date conversion exists (then it says so and reuses it), and the test dataset
        (``test_dir``) likewise. Once done, later calls (Lightning's fit, validate and test
        each call it) do nothing."""
        self._prepare_own()
        if self.test_data is not None:
            self.test_data.prepare_data()

    def _prepare_own(self) -> None:
        path = self.h5_path
        if self.reused is not None and path.exists():
            return
        if path.exists():
            why = self._stale()
            if why is None:
                self.reused = True
                if self.dataset_dir is None:
                    self._say(f"using {path} (no dataset directory given: not compared with "
                              "a data.csv)")
                    return
                if not self._given_h5:
                    _, csv = conversion.dataset_csv(self.dataset_dir)
                    if csv.stat().st_mtime_ns > path.stat().st_mtime_ns:
                        os.utime(path)  # data.csv was CRC-checked: not again next time
                    _cache.mark_used(path)
                self._say(f"reusing {path} (same conversion options and data.csv)")
                return
            if self._given_h5:
                raise ValueError(f"{path} is not the conversion this data module asks for: "
                                 f"{why}; delete it, pass another h5_path, or leave h5_path "
                                 "out to use the cache")
            self._check_media()
            self._say(f"converting again: {path.name} is out of date ({why})")
        elif self.dataset_dir is None:
            raise FileNotFoundError(f"{path}: no such HDF5 file and no dataset_dir to "
                                    "convert it from")
        else:
            self._check_media()
            note = "" if self._given_h5 else f"; {self._cache_note()}"
            self._say(f"converting {self.dataset_dir} -> {path} (first use of these "
                      f"options{note})")
        self.conversion_report = conversion.convert(
            self.dataset_dir, path, force=True,
            progress=None if self.verbose and self._rank_zero() else False,
            **self._convert_kwargs())
        self.reused = False
        lines = conversion.format_report(self.conversion_report).splitlines()
        for line in lines[:4] + [x for x in lines[4:] if x.startswith("WARNING")]:
            self._say(line)
        if not self._given_h5:
            self._say(f"added {_cache.format_bytes(path.stat().st_size)} to the {self._cache_note()}")

    def _check_media(self) -> None:
        """A poses-only dataset has no MP4/APNG to crop: say so before the converter fails
        on the first missing video."""
        if self.convert_options.get("media") and self._poses_only():
            need = ("pose estimation needs the media (its inputs are the video crops)"
                    if self.task == "pose_estimation" else "media=True needs them")
            raise ValueError(
                f"{self.dataset_dir} was generated with --poses-only (its config.yaml says "
                f"poses_only: true): it has data.csv but no MP4/APNG files, and {need}. "
                "Generate the dataset without --poses-only (bsp-synth OUT_DIR), or use a "
                "recorded one")

    def _check_file(self, ds: ClipDataset) -> None:
        a = ds.attrs
        checks = [("clip_length", self._explicit["clip_length"], a.get("clip_length")),
                  ("clip_offset", self._explicit["clip_offset"], a.get("clip_stride")),
                  ("benchmark", self.benchmark_windows or None, bool(a.get("benchmark", 0))),
                  ("crop_box", self.convert_options.get("crop_box"), file_crop_box(a))]
        wanted, stored = {}, {}
        for name, want, have in checks:
            if want is not None and have is not None and want != type(want)(have):
                wanted[name], stored[name] = want, type(want)(have)
        if wanted:
            raise ValueError(
                f"{self.h5_path} was converted with other options: "
                f"{_cache.describe_difference(stored, wanted)}. Use the file's values "
                "(leave these options out), or convert again with yours: give the dataset "
                "directory instead of the file (converted on first use, and cached), or "
                "bsp-convert DATASET OUT.h5 with these options")

    def setup(self, stage: str | None = None) -> None:
        """Opens the splits (converting first if :meth:`prepare_data` has not run)."""
        if self.reused is None:
            self.prepare_data()
        want = {"fit": ("train", "val"), "validate": ("val",), "test": ("test",),
                "predict": ("test",)}.get(stage, SPLITS)
        for split in want:
            if split not in self.datasets:
                self.datasets[split] = self._dataset(split)
        self._check_file(self.datasets[want[0]])
        self.clip_length = int(self.datasets[want[0]].clip_length)

    def _dataset(self, split: str) -> ClipDataset:
        if split == "test" and self.test_data is not None:
            if self.test_data.reused is None:
                self.test_data.prepare_data()
            return self.test_data._dataset("test")
        train = split == "train"
        options = dict(noise=self.noise, mjp=self.mjp,
                       seed=self.seed if train else self.eval_seed,
                       balance=self.balance and train)
        if self.task in ("classification", "autoencoder"):
            options["augment"] = self.augment and train
        if self.task == "pose_estimation":
            options.pop("noise"), options.pop("mjp")
        extra = dict(self.dataset_options)
        # box_jitter: the train split's box noise; box_noise: val and test (evaluation)
        jitter, noise = extra.pop("box_jitter", None), extra.pop("box_noise", None)
        if (jitter if train else noise):
            options["box_noise"] = tuple(jitter if train else noise)
        if not train:  # augmentation asked for here (pose_estimation's) is train-time only
            extra.pop("augment", None)
        options.update(extra)
        return ClipDataset(self.h5_path, split, self.task, **options)

    def _loader(self, split: str):
        if split not in self.datasets:
            self.setup({"train": "fit", "val": "validate"}.get(split, "test"))
        return self.datasets[split].loader(
            self.batch_size, shuffle=split == "train", num_workers=self.num_workers,
            block_size=self.block_size, sampler_seed=self.sampler_seed,
            pin_memory=self.pin_memory, persistent_workers=self.persistent_workers)

    def train_dataloader(self):
        return self._loader("train")

    def val_dataloader(self):
        return self._loader("val")

    def test_dataloader(self):
        return self._loader("test")

    def predict_dataloader(self):
        return self._loader("test")
