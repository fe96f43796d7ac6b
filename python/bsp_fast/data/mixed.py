"""``MixedDataModule``: train on several clip files at once, each source in a stated share
of every epoch (the report's autoencoder mix: JAAD 10 %, CARLA-BSP 40 %, AMASS 50 %,
``experiments/mix/autoencoder.yaml``).

Every epoch of ``epoch_size`` clips takes ``round(share * epoch_size)`` clips from each
source (largest remainders, so the counts add up), drawn without replacement inside a
source while it has clips left (then from a fresh permutation), and shuffles them
together into batches. The draw is a function of ``(seed, epoch)``: the same seed gives
the same batches. Validation and test read every source's split in order, one after the
other. Each batch holds ``meta["source"]`` (the source's index).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .._extras import require
from ..defaults import SEED
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
           "mix_table", "mix_dirs"]

MIX_TASKS = ("classification", "autoencoder")


def quotas(shares, total: int) -> np.ndarray:
    """Integer counts proportional to ``shares`` adding up to ``total`` (largest
    remainders, ties to the earlier source)."""
    s = np.asarray(shares, np.float64)
    raw = s / s.sum() * total
    counts = np.floor(raw).astype(np.int64)
    order = np.argsort(-(raw - counts), kind="stable")
    counts[order[:total - counts.sum()]] += 1
    return counts


class MixedDataset(torch.utils.data.Dataset):
    """Several :class:`ClipDataset` side by side; global index ``offset[k] + i`` is clip
    ``i`` of source ``k``. ``ds[IndexBatch]`` or ``ds[list]`` returns one collated batch
    in the order asked, with ``meta["source"]``."""

    def __init__(self, datasets):
        self.datasets = list(datasets)
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
        self.epoch, self._next = 0, 0

    def set_epoch(self, epoch: int) -> None:
        self.epoch = self._next = int(epoch)

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
        return iter(self.batches(epoch))

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


def _clip_length(h5_path) -> int:
    from ..conversion.vds import open_clip_file

    try:
        with open_clip_file(h5_path) as f:
            return int(f.attrs["clip_length"])
    except (OSError, KeyError) as exc:
        raise ValueError(f"{h5_path}: not a clip file with a clip_length ({exc})") from None


def read_mix(path) -> dict:
    """A mixing table (YAML): ``task``, ``sources`` (``name``, ``share``, optional
    ``h5_path``), optional ``epoch_size``, ``clip_length``; checked."""
    import yaml

    with Path(path).open("r", encoding="utf-8") as fh:
        doc = yaml.safe_load(fh)
    if not isinstance(doc, dict) or not isinstance(doc.get("sources"), list):
        raise ValueError(f"{path}: a mixing table needs a 'sources' list")
    return doc


class MixedDataModule(_Base):
    """Train/val/test loaders over several clip files (``sources``: a list of
    ``{"name", "h5_path", "share"}``; shares are positive and add up to 1). ``epoch_size``
    (default: the sources' train clips together) clips per train epoch, drawn by
    :class:`MixedBatchSampler` from ``seed`` (default: derived from torch's initial
    seed, so ``seed_everything`` fixes it). ``noise``, ``mjp``, ``augment`` and
    ``dataset_options`` as in :class:`BSPDataModule`; ``task``: classification or
    autoencoder."""

    def __init__(self, sources, task: str = "autoencoder", batch_size: int = 256,
                 num_workers: int = 0, *, epoch_size: int | None = None,
                 seed: int | None = None, eval_seed: int = SEED, noise: float = 0.0,
                 mjp=0.0, augment: bool = True, dataset_options: dict | None = None):
        super().__init__()
        if task not in MIX_TASKS:
            raise ValueError(f"task must be one of {list(MIX_TASKS)} (2D clip tasks), got {task!r}")
        self.sources = [dict(s) for s in sources]
        names = [s.get("name") for s in self.sources]
        if not self.sources or len(set(names)) != len(names) or None in names:
            raise ValueError(f"sources need unique names, got {names}")
        for s in self.sources:
            if "h5_path" not in s:
                raise ValueError(f"source {s['name']!r} has no h5_path")
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
        lengths = {s["name"]: _clip_length(s["h5_path"]) for s in sources}
        want = doc.get("clip_length")
        bad = {n: L for n, L in lengths.items() if want is not None and L != int(want)}
        if bad:
            raise ValueError(f"{path}: clip_length {want}, but " + ", ".join(
                f"source {n!r} ({paths[n]}) has {L}" for n, L in bad.items())
                + ": convert or import it with --clip-length " + str(want))
        if len(set(lengths.values())) > 1:
            raise ValueError(f"{path}: sources have different clip lengths {lengths}")
        options = {k: doc[k] for k in ("task", "epoch_size", "batch_size") if k in doc}
        options.update(overrides)
        return cls(sources, **options)

    def setup(self, stage: str | None = None) -> None:
        for split in ("train", "val", "test"):
            if split not in self.datasets:
                train = split == "train"
                opts = dict(noise=self.noise, mjp=self.mjp,
                            seed=self.seed if train else self.eval_seed,
                            augment=self.augment and train)
                opts.update(self.dataset_options)
                self.datasets[split] = MixedDataset(
                    [ClipDataset(s["h5_path"], split, self.task, **opts) for s in self.sources])

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

