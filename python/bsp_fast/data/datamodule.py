"""``BSPDataModule``: converts a CARLA-BSP dataset on first use and builds the loaders.

It subclasses ``lightning.pytorch.LightningDataModule`` when Lightning is importable (else
``pytorch_lightning``'s, else nothing) and works as a plain class either way:
``dm.prepare_data(); dm.setup(); dm.train_dataloader()``.
"""
from __future__ import annotations

from pathlib import Path

from .datasets import DEFAULT_EVAL_SEED, SPLITS, TASKS, ClipDataset

try:
    from lightning.pytorch import LightningDataModule as _Base
    LIGHTNING = True
except ImportError:  # pragma: no cover - depends on the environment
    try:
        from pytorch_lightning import LightningDataModule as _Base
        LIGHTNING = True
    except ImportError:
        _Base, LIGHTNING = object, False

__all__ = ["BSPDataModule", "LIGHTNING"]

BENCHMARK = dict(clip_length=16, clip_offset=6, benchmark=True, balance=True)


def _converter():
    """``bsp_fast``'s convert function (module ``conversion``, formerly ``convert``)."""
    import importlib

    try:
        return importlib.import_module("bsp_fast.conversion").convert
    except ModuleNotFoundError as exc:
        if exc.name != "bsp_fast.conversion":
            raise
        return importlib.import_module("bsp_fast.convert").convert


def _default_h5(dataset_dir: Path, L: int, offset: int, benchmark: bool, balance: bool,
                media: bool) -> Path:
    tags = f"L{L}-o{offset}" + ("-benchmark" if benchmark else "")
    tags += ("-balanced" if balance else "") + ("-media" if media else "")
    return Path(dataset_dir) / f"bsp_fast-clips-{tags}.h5"


class BSPDataModule(_Base):
    """Train/val/test loaders of one task over a converted HDF5 file.

    Give ``h5_path`` (an existing file, or where to write one), ``dataset_dir`` (a CARLA-BSP
    dataset converted on first use, to ``h5_path`` or by default to
    ``<dataset_dir>/bsp_fast-clips-L<L>-o<offset>[-benchmark][-balanced][-media].h5``) or
    both.
    ``clip_length``/``clip_offset`` default as in :func:`bsp_fast.convert.convert` (30/L,
    16/6 with ``benchmark``); for an existing file they are checked against its attributes.
    ``balance`` balances the train split (in the converter, and in the dataset for files
    converted without it). ``noise``/``mjp`` deform the 2D inputs (SPEC section 5), train
    ``augment`` adds flips and rotations for the 2D tasks. ``convert_options`` go to
    :func:`bsp_fast.convert` (e.g. ``fov``, ``label``, ``seed``, ``crop_size``; ``media``
    defaults to True for ``pose_estimation`` only); other keywords of
    :class:`ClipDataset` go in ``dataset_options``.
    """

    def __init__(self, dataset_dir=None, h5_path=None, task: str = "classification",
                 clip_length: int | None = None, clip_offset: int | None = None,
                 benchmark: bool = False, balance: bool = False, noise: float = 0.0, mjp=0.0,
                 batch_size: int = 256, num_workers: int = 0, *, augment: bool = True,
                 seed: int | None = None, eval_seed: int = DEFAULT_EVAL_SEED,
                 sampler_seed: int | None = None, block_size: int = 32, pin_memory: bool = False,
                 persistent_workers: bool | None = None, convert_options: dict | None = None,
                 dataset_options: dict | None = None):
        super().__init__()
        if task not in TASKS:
            raise ValueError(f"task must be one of {list(TASKS)}, got {task!r}")
        if dataset_dir is None and h5_path is None:
            raise ValueError("BSPDataModule needs dataset_dir (converted on first use), h5_path, "
                             "or both")
        if not isinstance(batch_size, int) or isinstance(batch_size, bool) or batch_size <= 0:
            raise ValueError(f"batch_size must be a positive integer, got {batch_size!r}")
        if not isinstance(num_workers, int) or num_workers < 0:
            raise ValueError(f"num_workers must be an integer >= 0, got {num_workers!r}")
        self.dataset_dir = None if dataset_dir is None else Path(dataset_dir)
        self.task, self.benchmark_windows, self.balance = task, bool(benchmark), bool(balance)
        self._explicit = dict(clip_length=clip_length, clip_offset=clip_offset)
        L = clip_length or (BENCHMARK["clip_length"] if benchmark else 30)
        self.clip_length = L
        self.clip_offset = clip_offset or (BENCHMARK["clip_offset"] if benchmark else L)
        self.convert_options = dict(convert_options or {})
        # media crops cost decoding time and space; only pose estimation reads them
        self.convert_options.setdefault("media", task == "pose_estimation")
        self.h5_path = Path(h5_path) if h5_path is not None else _default_h5(
            self.dataset_dir, L, self.clip_offset, self.benchmark_windows, self.balance,
            bool(self.convert_options["media"]))
        self.noise, self.mjp, self.augment = noise, mjp, bool(augment)
        self.batch_size, self.num_workers = batch_size, num_workers
        self.seed, self.eval_seed, self.sampler_seed = seed, eval_seed, sampler_seed
        self.block_size, self.pin_memory = block_size, bool(pin_memory)
        self.persistent_workers = (num_workers > 0 if persistent_workers is None
                                   else bool(persistent_workers))
        self.dataset_options = dict(dataset_options or {})
        self.datasets: dict = {}
        self.conversion_report = None
        if LIGHTNING:
            self.save_hyperparameters(ignore=["convert_options", "dataset_options"])

    @classmethod
    def benchmark(cls, dataset_dir=None, h5_path=None, task: str = "classification", **kwargs):
        """The report's crossing-classification setup: 16-frame clips every 6 frames from
        the time-to-event windows (video-level labels), balanced train split. Any keyword
        of the constructor overrides."""
        options = dict(BENCHMARK)
        options.update(kwargs)
        return cls(dataset_dir, h5_path, task, **options)

    def prepare_data(self) -> None:
        """Converts ``dataset_dir`` into ``h5_path`` through the C++ core when it is missing."""
        if self.h5_path.exists():
            return
        if self.dataset_dir is None:
            raise FileNotFoundError(f"{self.h5_path}: no such HDF5 file and no dataset_dir "
                                    "to convert it from")
        convert = _converter()
        options = dict(clip_length=self.clip_length, clip_offset=self.clip_offset,
                       benchmark=self.benchmark_windows, balance=self.balance)
        options.update(self.convert_options)
        self.conversion_report = convert(self.dataset_dir, self.h5_path, **options)

    def _check_file(self, ds: ClipDataset) -> None:
        a = ds.attrs
        checks = [("clip_length", self._explicit["clip_length"], a.get("clip_length")),
                  ("clip_offset", self._explicit["clip_offset"], a.get("clip_stride")),
                  ("benchmark", self.benchmark_windows or None, bool(a.get("benchmark", 0)))]
        for name, want, have in checks:
            if want is not None and have is not None and want != type(want)(have):
                raise ValueError(f"{self.h5_path}: file has {name}={have!r} but the data module "
                                 f"asks for {want!r}; pass another h5_path or delete the file "
                                 "to reconvert")

    def setup(self, stage: str | None = None) -> None:
        """Opens the splits (converting first if :meth:`prepare_data` has not run)."""
        if not self.h5_path.exists():
            self.prepare_data()
        want = {"fit": ("train", "val"), "validate": ("val",), "test": ("test",),
                "predict": ("test",)}.get(stage, SPLITS)
        for split in want:
            if split not in self.datasets:
                self.datasets[split] = self._dataset(split)
        self._check_file(self.datasets[want[0]])
        self.clip_length = int(self.datasets[want[0]].clip_length)

    def _dataset(self, split: str) -> ClipDataset:
        train = split == "train"
        options = dict(noise=self.noise, mjp=self.mjp,
                       seed=self.seed if train else self.eval_seed,
                       balance=self.balance and train)
        if self.task in ("classification", "autoencoder"):
            options["augment"] = self.augment and train
        if self.task == "pose_estimation":
            options.pop("noise"), options.pop("mjp")
        options.update(self.dataset_options)
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
