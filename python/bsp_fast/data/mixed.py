"""``MixedDataModule``: train on several clip files at once, each source in a stated share
of every epoch (the report's autoencoder mix: JAAD 10 %, CARLA-BSP 40 %, AMASS 50 %,
``experiments/mix/autoencoder.yaml``; the tables themselves are :mod:`.mix_tables`).

Every epoch of ``epoch_size`` clips takes ``round(share * epoch_size)`` clips from each
source (largest remainders, so the counts add up), drawn without replacement inside a
source while it has clips left (then from a fresh permutation), and shuffles them
together into batches. The draw is a function of ``(seed, epoch)``: the same seed gives
the same batches. Validation reads every source's split in order, one after the other;
test does too, or reads one named source alone (``test_source``: bsp-train's
``--test-on``). Each batch of several sources holds ``meta["source"]`` (the source's
index) and recordings named ``SOURCE:VIDEO`` (two sources may share a video name).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .._extras import require
from ..defaults import SEED
from .mix_tables import MIX_TASKS, check_mix, mix_dirs, mix_table, quotas, read_mix
from .sampling import IndexBatch, collate_batch, derived_seed

torch = require("torch")
import torch.utils.data  # noqa: E402

from .datasets import ClipDataset  # noqa: E402

try:
    from lightning.pytorch import LightningDataModule as _Base
except ImportError:  # pragma: no cover - depends on the environment
    try:
        from pytorch_lightning import LightningDataModule as _Base
    except ImportError:
        _Base = object

__all__ = ["MixedDataModule", "MixedDataset", "MixedBatchSampler", "quotas", "read_mix",
           "mix_table", "mix_dirs", "MIX_TASKS", "check_mix", "check_clip_lengths"]


class MixedDataset(torch.utils.data.Dataset):
    """Several :class:`ClipDataset` side by side; global index ``offset[k] + i`` is clip
    ``i`` of source ``k``. ``ds[IndexBatch]`` or ``ds[list]`` returns one collated batch
    in the order asked, with ``meta["source"]``; with ``names`` (one per dataset) and more
    than one dataset, ``meta["video_id"]`` is ``NAME:VIDEO``, so recordings of two sources
    stay apart in per-recording sums."""

    def __init__(self, datasets, names=None):
        self.datasets = list(datasets)
        self.names = None if names is None else [str(n) for n in names]
        if not self.datasets:
            raise ValueError("MixedDataset needs at least one dataset")
        lengths = {d.clip_length for d in self.datasets}
        if len(lengths) != 1:
            raise ValueError(f"sources have different clip lengths {sorted(lengths)}: "
                             "convert or import them with the same clip length")
        self.sizes = np.array([len(d) for d in self.datasets], np.int64)
        self.offsets = np.concatenate([[0], np.cumsum(self.sizes)])

    def __len__(self) -> int:
        return int(self.offsets[-1])

    def __getitem__(self, indices):
        if isinstance(indices, (int, np.integer)):
            raise TypeError("MixedDataset returns batches: index it with a list of indices")
        epoch = getattr(indices, "epoch", None)
        idx = np.asarray(list(indices), np.int64)
        if idx.ndim != 1 or len(idx) == 0 or idx.min() < 0 or idx.max() >= len(self):
            raise IndexError(f"indices must be a non-empty list in [0, {len(self)})")
        source = np.searchsorted(self.offsets, idx, side="right") - 1
        parts, where = [], []
        for k in np.unique(source):
            sel = np.flatnonzero(source == k)
            ds = self.datasets[int(k)]
            if epoch is not None:
                ds.set_epoch(epoch)
            parts.append(ds[(idx[sel] - self.offsets[k]).tolist()])
            where.append(sel)
        back = np.argsort(np.concatenate(where), kind="stable")
        batch = _concat(parts, torch.from_numpy(back))
        batch["meta"]["source"] = torch.from_numpy(source)
        if self.names is not None and len(self.datasets) > 1:
            batch["meta"]["video_id"] = [f"{self.names[k]}:{v}" for k, v in
                                         zip(source.tolist(), batch["meta"]["video_id"])]
        return batch


def _concat(parts: list, back) -> dict:
    out = {}
    for key, value in parts[0].items():
        if isinstance(value, dict):
            out[key] = _concat([p[key] for p in parts], back)
        elif isinstance(value, torch.Tensor):
            out[key] = torch.cat([p[key] for p in parts])[back]
        else:  # lists of strings
            joined = [x for p in parts for x in p[key]]
            out[key] = [joined[i] for i in back.tolist()]
    return out


class MixedBatchSampler:
    """Batches of global indices of a :class:`MixedDataset`, ``quotas(shares, epoch_size)``
    clips of each source per epoch, as :class:`IndexBatch` (carrying the epoch)."""

    def __init__(self, sizes, shares, epoch_size: int, batch_size: int, seed: int,
                 drop_last: bool = False):
        self.sizes = np.asarray(sizes, np.int64)
        self.shares = np.asarray(shares, np.float64)
        self.epoch_size, self.batch_size = int(epoch_size), int(batch_size)
        self.seed, self.drop_last = int(seed), bool(drop_last)
        self.offsets = np.concatenate([[0], np.cumsum(self.sizes)])
        self.counts = quotas(self.shares, self.epoch_size)
        empty = [k for k in range(len(self.sizes)) if self.counts[k] and not self.sizes[k]]
        if empty:
            raise ValueError(f"sources {empty} have a share but no clips")
        self.epoch, self._next, self._skip = 0, 0, None

    def set_epoch(self, epoch: int) -> None:
        self.epoch = self._next = int(epoch)

    def skip_batches(self, epoch: int, count: int) -> None:
        """The next iteration over epoch ``epoch`` leaves out its first ``count`` batches
        (bsp-train resumed mid-epoch: those were trained on before the interruption)."""
        self._skip = (int(epoch), int(count))

    def epoch_indices(self, epoch: int) -> np.ndarray:
        """The shuffled global indices of one epoch (before cutting into batches)."""
        rng = np.random.default_rng([self.seed, int(epoch)])
        chosen = []
        for k, (n, size) in enumerate(zip(self.counts, self.sizes)):
            picks = [rng.permutation(size) for _ in range(-(-int(n) // max(int(size), 1)))]
            local = np.concatenate(picks)[:n] if picks else np.zeros(0, np.int64)
            chosen.append(local + self.offsets[k])
        return rng.permutation(np.concatenate(chosen))

    def batches(self, epoch: int) -> list:
        idx = self.epoch_indices(epoch)
        cut = range(0, len(idx), self.batch_size)
        out = [IndexBatch(idx[i:i + self.batch_size].tolist(), epoch) for i in cut]
        if self.drop_last and out and len(out[-1]) < self.batch_size:
            out.pop()
        return out

    def __iter__(self):
        epoch = self._next
        self._next = epoch + 1
        skip = self._skip[1] if self._skip is not None and self._skip[0] == epoch else 0
        self._skip = None
        return iter(self.batches(epoch)[skip:])

    def __len__(self) -> int:
        full, rest = divmod(self.epoch_size, self.batch_size)
        return full + (0 if self.drop_last or not rest else 1)


class _Sequential:
    def __init__(self, n: int, batch_size: int):
        self.n, self.batch_size = n, batch_size

    def __iter__(self):
        return (IndexBatch(range(i, min(i + self.batch_size, self.n)), 0)
                for i in range(0, self.n, self.batch_size))

    def __len__(self) -> int:
        return -(-self.n // self.batch_size)


def _clip_length(h5_path) -> int:
    from ..conversion.vds import open_clip_file

    try:
        with open_clip_file(h5_path) as f:
            return int(f.attrs["clip_length"])
    except (OSError, KeyError) as exc:
        raise ValueError(f"{h5_path}: not a clip file with a clip_length ({exc})") from None


def check_clip_lengths(files: dict, want=None, where: str = "mix") -> int:
    """The clip length all of ``files`` (``{source: clip file}``) hold; ValueError naming
    each source whose file holds another than ``want`` (the table's, where it gives one)
    or than the others (a model is trained and scored on one clip length)."""
    lengths = {n: _clip_length(f) for n, f in files.items()}
    bad = {n: L for n, L in lengths.items() if want is not None and L != int(want)}
    if bad:
        raise ValueError(f"{where}: clip_length {want}, but " + ", ".join(
            f"source {n!r} ({files[n]}) has {L}" for n, L in bad.items())
            + f": convert or import {'it' if len(bad) == 1 else 'them'} with --clip-length "
            f"{want} (bsp-interop import jaad|pie: --obs-length {want})")
    if len(set(lengths.values())) > 1:
        raise ValueError(f"{where}: sources have different clip lengths {lengths}")
    return next(iter(lengths.values()))


class MixedDataModule(_Base):
    """Train/val/test loaders over several clip files (``sources``: a list of
    ``{"name", "h5_path", "share"}``; shares are positive and add up to 1). ``epoch_size``
    (default: the sources' train clips together) clips per train epoch, drawn by
    :class:`MixedBatchSampler` from ``seed`` (default: derived from torch's initial
    seed, so ``seed_everything`` fixes it). ``noise``, ``mjp``, ``augment`` and
    ``dataset_options`` as in :class:`BSPDataModule`; ``task``: classification or
    autoencoder.

    ``test_source`` (``{"name", "h5_path"}``): the test split is that file's alone (a
    source of the mix or another dataset: bsp-train's ``--test-on``); default: every
    source's. ``base``: a :class:`BSPDataModule` (bsp-train's ``--data``) whose converted
    file is read by the source (or test source) marked ``"data": True`` with no
    ``h5_path``; :meth:`prepare_data` converts it. ``clip_length``: what every file must
    hold, checked with the files against each other when the splits are opened."""

    def __init__(self, sources, task: str = "autoencoder", batch_size: int = 256,
                 num_workers: int = 0, *, epoch_size: int | None = None,
                 seed: int | None = None, eval_seed: int = SEED, noise: float = 0.0,
                 mjp=0.0, augment: bool = True, dataset_options: dict | None = None,
                 test_source: dict | None = None, base=None, clip_length: int | None = None):
        super().__init__()
        if task not in MIX_TASKS:
            raise ValueError(f"task must be one of {list(MIX_TASKS)} (2D clip tasks), got {task!r}")
        self.sources = [dict(s) for s in sources]
        names = [s.get("name") for s in self.sources]
        if not self.sources or len(set(names)) != len(names) or None in names:
            raise ValueError(f"sources need unique names, got {names}")
        self.test_source = None if test_source is None else dict(test_source)
        for s in self.sources + ([self.test_source] if self.test_source else []):
            if s.get("h5_path") is None and not (s.get("data") and base is not None):
                raise ValueError(f"source {s.get('name')!r} has no h5_path")
        for s in self.sources:
            if not isinstance(s.get("share"), (int, float)) or not s["share"] > 0:
                raise ValueError(f"source {s['name']!r}: share must be a number > 0, "
                                 f"got {s.get('share')!r}")
        total = sum(s["share"] for s in self.sources)
        if abs(total - 1) > 1e-6:
            raise ValueError(f"shares must add up to 1, got {total} ({names})")
        for name, v in (("batch_size", batch_size), ("epoch_size", epoch_size)):
            if v is not None and (not isinstance(v, int) or isinstance(v, bool) or v <= 0):
                raise ValueError(f"{name} must be a positive integer, got {v!r}")
        self.task, self.batch_size, self.num_workers = task, batch_size, int(num_workers)
        self.epoch_size, self.eval_seed = epoch_size, eval_seed
        self.seed = seed if seed is not None else derived_seed()
        self.noise, self.mjp, self.augment = noise, mjp, bool(augment)
        self.dataset_options = dict(dataset_options or {})
        self.base, self.clip_length = base, clip_length
        self.datasets: dict = {}

    @classmethod
    def from_config(cls, path, paths: dict, **overrides) -> "MixedDataModule":
        """From a mixing table: a YAML path, or a table name (``"autoencoder"``: the
        ``experiments/mix/autoencoder.yaml`` found by :func:`mix_table`); ``paths`` maps
        each source's name to its clip file (the table names sources, not files). Every
        file's clip length must be the table's ``clip_length`` (where it gives one) and
        the same for all sources."""
        path = mix_table(path)
        doc = read_mix(path)
        missing = [s["name"] for s in doc["sources"] if s.get("name") not in paths]
        if missing:
            raise ValueError(f"{path}: no clip file given for sources {missing} (paths=...)")
        sources = [dict(name=s["name"], share=s["share"], h5_path=str(paths[s["name"]]))
                   for s in doc["sources"]]
        check_clip_lengths({s["name"]: s["h5_path"] for s in sources}, doc.get("clip_length"),
                           str(path))
        options = {k: doc[k] for k in ("task", "epoch_size", "clip_length") if k in doc}
        options.update(overrides)
        return cls(sources, **options)

    @property
    def h5_path(self):
        """The file a run names as its data: the converted ``base`` when a source reads it,
        else the test source's file, else the first source's."""
        if self.base is not None:
            return self.base.h5_path
        return Path((self.test_source or self.sources[0])["h5_path"])

    def _fill(self) -> None:
        for s in self.sources + ([self.test_source] if self.test_source else []):
            if s.get("data") and self.base is not None:
                s["h5_path"] = str(self.base.h5_path)

    def prepare_data(self) -> None:
        """Converts ``base`` (when given; reused when up to date) for its source."""
        if self.base is not None:
            self.base.prepare_data()
        self._fill()

    def setup(self, stage: str | None = None) -> None:
        self._fill()
        if not self.datasets:
            files = {s["name"]: s["h5_path"] for s in self.sources}
            if self.test_source:
                files[self.test_source["name"]] = self.test_source["h5_path"]
            check_clip_lengths(files, self.clip_length)
        for split in ("train", "val", "test"):
            if split in self.datasets:
                continue
            train = split == "train"
            opts = dict(noise=self.noise, mjp=self.mjp,
                        seed=self.seed if train else self.eval_seed,
                        augment=self.augment and train)
            opts.update(self.dataset_options)
            chosen = [self.test_source] if split == "test" and self.test_source else self.sources
            sets = [ClipDataset(s["h5_path"], split, self.task, **opts) for s in chosen]
            # one file to score: its own dataset (its rows, file and recordings, as a run
            # on that file alone has them); train always mixed (the sampler's indices)
            self.datasets[split] = sets[0] if len(sets) == 1 and not train else \
                MixedDataset(sets, [s["name"] for s in chosen])

    def _loader(self, split: str, sampler):
        return torch.utils.data.DataLoader(self.datasets[split], sampler=sampler,
                                           batch_size=None, collate_fn=collate_batch,
                                           num_workers=self.num_workers,
                                           persistent_workers=self.num_workers > 0)

    def train_sampler(self) -> MixedBatchSampler:
        self.setup("fit")
        ds = self.datasets["train"]
        size = self.epoch_size or len(ds)
        return MixedBatchSampler(ds.sizes, [s["share"] for s in self.sources], size,
                                 self.batch_size, self.seed)

    def train_dataloader(self):
        return self._loader("train", self.train_sampler())

    def val_dataloader(self):
        self.setup("validate")
        return self._loader("val", _Sequential(len(self.datasets["val"]), self.batch_size))

    def test_dataloader(self):
        self.setup("test")
        return self._loader("test", _Sequential(len(self.datasets["test"]), self.batch_size))

    def predict_dataloader(self):
        return self.test_dataloader()
