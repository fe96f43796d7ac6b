"""What the datasets of ``bsp_fast.data`` share: lazy HDF5 handles, batched reads, the
PyTorch item protocol, per-clip random draws, ``transform`` hooks and the contiguous loader.

A dataset subclass implements ``_arrays(pos, rows, rng)``, returning NumPy arrays of one
batch; this base turns them into what each caller expects:

* ``ds[i]``: one sample (a dict of tensors without the batch axis);
* ``ds[list]``, ``ds[slice]`` and ``ds.__getitems__(IndexBatch)``: one collated batch (the
  fast path of ``ds.loader()``; leaving a DataLoader worker it travels in one shared
  buffer, see :mod:`.transport`);
* ``ds.__getitems__(list)``, what a plain ``DataLoader(ds, batch_size=..., shuffle=...)``
  and ``Subset`` call: a list of samples for ``default_collate`` (read and transformed as
  one batch all the same).
"""
from __future__ import annotations

import os
import weakref

import numpy as np

from .._extras import require
from ..defaults import SEED

torch = require("torch")
import torch.utils.data  # noqa: E402

from .clip_random import ClipRandom
from .sampling import ContiguousBatchSampler, IndexBatch, collate_batch, derived_seed
from . import transport
from .transport import pack_batch

__all__ = ["SplitDataset", "SPLITS", "DEFAULT_EVAL_SEED"]

SPLITS = ("train", "val", "test")
DEFAULT_EVAL_SEED = SEED
_SPLIT_CODE = {s: i for i, s in enumerate(SPLITS)}

_open_datasets: "weakref.WeakSet[SplitDataset]" = weakref.WeakSet()


def _close_before_fork() -> None:
    # HDF5 handles must not cross a fork: children reopen lazily.
    for ds in list(_open_datasets):
        ds.close()


os.register_at_fork(before=_close_before_fork)


def choice(name: str, value, allowed) -> None:
    if value not in allowed:
        raise ValueError(f"{name} must be one of {list(allowed)}, got {value!r}")


class Rows:
    """Sorted unique rows of a batch as contiguous runs, and how to put them back in order."""

    def __init__(self, rows: np.ndarray):
        uniq, inv = np.unique(rows, return_inverse=True)
        self.count = len(uniq)
        self.inverse = None if len(uniq) == len(rows) and np.array_equal(uniq, rows) else inv
        cut = np.flatnonzero(np.diff(uniq) != 1) + 1
        starts, ends = np.r_[0, cut], np.r_[cut, len(uniq)]
        self.runs = [(int(uniq[a]), int(uniq[b - 1]) + 1, int(a)) for a, b in zip(starts, ends)]

    def read(self, ds) -> np.ndarray:
        """One low-level HDF5 read per run (~30 us; h5py's high-level ``read_direct`` costs
        ~4x that, and one read of the union of the runs' hyperslabs is slower still)."""
        import h5py

        tail = tuple(ds.shape[1:])
        out = np.empty((self.count,) + tail, ds.dtype)
        space, zeros = ds.id.get_space(), (0,) * len(tail)
        for a, b, o in self.runs:
            space.select_hyperslab((a,) + zeros, (b - a,) + tail)
            ds.id.read(h5py.h5s.create_simple((b - a,) + tail), space, out[o:o + b - a])
        return out if self.inverse is None else out[self.inverse]


def plain(value):
    """An HDF5 attribute as plain Python (str, int, float, list)."""
    if isinstance(value, bytes):
        return value.decode()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return [v.decode() if isinstance(v, bytes) else v for v in value.tolist()]
    return value


def _callable(name: str, fn) -> None:
    if fn is not None and not callable(fn):
        raise ValueError(f"{name} must be a callable or None, got {fn!r}")


def _per_sample(fn, batch: np.ndarray, view=None) -> np.ndarray:
    """``fn`` on each sample of a batch (as a tensor, ``view`` applied), stacked again."""
    out = []
    for a in batch:
        t = torch.from_numpy(a)
        y = fn(t if view is None else view(t))
        out.append(y if isinstance(y, torch.Tensor) else torch.as_tensor(np.asarray(y)))
    return torch.stack(out).numpy()


class SplitDataset(torch.utils.data.Dataset):
    """One split of a ``bsp-convert`` file; subclasses define the items (``_arrays``)."""

    _h5_path: str
    split: str

    def _init_common(self, h5_path, split: str, seed, transform, target_transform) -> None:
        choice("split", split, SPLITS)
        _callable("transform", transform)
        _callable("target_transform", target_transform)
        if seed is not None and (not isinstance(seed, int) or isinstance(seed, bool)):
            raise ValueError(f"seed must be an integer or None, got {seed!r}")
        self.h5_path, self.split = str(h5_path), split
        self.transform, self.target_transform = transform, target_transform
        self.seed = seed if seed is not None or split == "train" else DEFAULT_EVAL_SEED
        # no seed: derived from torch's initial seed, so seed_everything() fixes it
        self._seed = self.seed if self.seed is not None else derived_seed()
        self.epoch = 0
        self._file, self._pid, self._ds = None, None, {}

    # ----------------------------------------------------------------- file handling
    def _h5(self):
        if self._file is None or self._pid != os.getpid():
            from ..conversion.vds import open_clip_file

            self._file, self._pid, self._ds = open_clip_file(self.h5_path), os.getpid(), {}
            _open_datasets.add(self)
        return self._file

    def _dataset(self, name: str):
        ds = self._ds.get(name)
        if ds is None:
            ds = self._ds[name] = self._h5()[self.split][name]
        return ds

    def close(self) -> None:
        """Closes this process's handle (reopened on the next read)."""
        if self._file is not None and self._pid == os.getpid():
            self._file.close()
        self._file, self._pid, self._ds = None, None, {}

    def __getstate__(self):
        state = self.__dict__.copy()
        state.update(_file=None, _pid=None, _ds={}, _arena=None)
        return state

    def set_epoch(self, epoch: int) -> None:
        """Epoch of the train randomness for batches that do not carry one (a plain
        DataLoader's): call it every epoch, as with ``DistributedSampler``."""
        self.epoch = int(epoch)

    # ----------------------------------------------------------------- item protocol
    def __len__(self) -> int:
        return len(self._rows)

    def __getitem__(self, index):
        if isinstance(index, (int, np.integer)):
            i = int(index) + (len(self) if index < 0 else 0)
            return _sample(self._batch([i]), 0)
        if isinstance(index, slice):
            return self._batch(list(range(*index.indices(len(self)))))
        return self._batch(index)

    def __getitems__(self, indices):
        """A collated batch for an :class:`IndexBatch` (``ds.loader()``), else the list of
        samples that ``default_collate`` expects (a plain DataLoader, ``Subset``)."""
        if isinstance(indices, IndexBatch):
            return self._batch(indices)
        batch = self._batch(indices, pack=False)
        return [_sample(batch, i) for i in range(len(batch["meta"]["index"]))]

    def _batch(self, indices, pack: bool | None = None):
        if torch.utils.data.get_worker_info() is not None:  # a DataLoader worker process
            transport.tune_worker_malloc()
        pos = np.asarray(list(indices), np.int64)
        if pos.ndim != 1 or len(pos) == 0:
            raise ValueError(f"{type(self).__name__}: expected a non-empty list of indices")
        if pos.min() < 0 or pos.max() >= len(self):
            raise IndexError(f"index out of range [0, {len(self)}) in {self!r}")
        rows = self._rows[pos]
        rng = self._rng(rows, getattr(indices, "epoch", self.epoch))
        out, meta, strings, channels_last = self._arrays(pos, rows, rng)
        meta["index"], meta["row"] = pos, rows
        if channels_last and self.transform is not None:  # transforms see (.., 3, S, S)
            out["inputs"] = _per_sample(self.transform, out["inputs"], _channels_first)
            channels_last = False
        elif self.transform is not None:
            out["inputs"] = _per_sample(self.transform, out["inputs"])
        if self.target_transform is not None:
            out["targets"] = _per_sample(self.target_transform, out["targets"])
        permute = {"inputs": _CHANNELS_FIRST[out["inputs"].ndim]} if channels_last else {}
        if pack is None:
            pack = isinstance(indices, IndexBatch)
        info = torch.utils.data.get_worker_info() if pack else None
        if info is not None:  # leaving a worker: one shared buffer
            return pack_batch(out, meta, strings, permute, getattr(self, "_arena", None),
                              info.id)
        batch = {k: torch.from_numpy(np.ascontiguousarray(v)) for k, v in out.items()}
        for k, order in permute.items():
            batch[k] = batch[k].permute(*order)
        batch["meta"] = {k: torch.from_numpy(v) for k, v in meta.items()}
        batch["meta"].update(strings)
        return batch

    def _rng(self, rows: np.ndarray, epoch: int) -> ClipRandom:
        """The batch's random draws: one stream per clip keyed by (seed, split, epoch for
        train / 0 for val and test, the clip's row), so neither the batch nor the worker
        nor the rank that reads a clip changes what is drawn for it (see .clip_random)."""
        epoch = epoch if self.split == "train" else 0
        return ClipRandom.for_rows(self._seed, _SPLIT_CODE[self.split], epoch, rows)

    # ----------------------------------------------------------------- loaders
    def loader(self, batch_size: int = 256, shuffle: bool | None = None, num_workers: int = 0,
               block_size: int = 32, drop_last: bool = False, sampler_seed: int | None = None,
               *, num_replicas: int | None = None, rank: int | None = None,
               **kwargs) -> torch.utils.data.DataLoader:
        """A DataLoader reading contiguous batches (shuffled by blocks for ``train``).

        Under ``torch.distributed`` (or with ``num_replicas``/``rank``) each rank reads a
        disjoint share of every epoch (:class:`ContiguousBatchSampler`). Extra keyword
        arguments go to :class:`torch.utils.data.DataLoader`; ``persistent_workers``
        defaults to True when ``num_workers > 0``.
        """
        shuffle = self.split == "train" if shuffle is None else shuffle
        sampler = ContiguousBatchSampler(len(self), batch_size, shuffle, block_size,
                                         drop_last, sampler_seed, num_replicas=num_replicas,
                                         rank=rank)
        kwargs.setdefault("persistent_workers", num_workers > 0)
        # the sampler yields whole batches: batch_size=None hands each to __getitem__
        return ClipLoader(self, sampler=sampler, batch_size=None, collate_fn=collate_batch,
                          num_workers=num_workers, **kwargs)

    def _packed_bytes(self, batch_size: int) -> int:
        """Buffer bytes of a ``batch_size`` batch, from a one-clip batch read here."""
        b = self._batch(IndexBatch([0]), pack=False)
        tensors = [v for k, v in b.items() if k != "meta"]
        tensors += [v for v in b["meta"].values() if isinstance(v, torch.Tensor)]
        per_item = sum(t.numel() * t.element_size() for t in tensors)
        return batch_size * per_item + 64 * len(tensors)


class ClipLoader(torch.utils.data.DataLoader):
    """The DataLoader of ``ds.loader()``: with forked workers it creates the batch buffers
    (:class:`~bsp_fast.data.transport.Arena`) just before the workers start, so they
    inherit them and no batch ever passes a file descriptor."""

    def _get_iterator(self):
        ds = self.dataset
        batch = getattr(self.sampler, "batch_size", None)
        if (self.num_workers == 0 or not isinstance(ds, SplitDataset) or not batch
                or len(ds) == 0 or not _forks(self.multiprocessing_context)):
            return super()._get_iterator()
        slots = (self.prefetch_factor or 2) + 2  # queued + being filled + being copied out
        arena = transport.Arena(self.num_workers, slots, ds._packed_bytes(batch))
        ds._arena = arena  # inherited by the workers forked now
        try:
            it = super()._get_iterator()
        finally:
            ds._arena = None
        arena.attach(it)
        return it


def _forks(context) -> bool:
    import multiprocessing

    if context is None:
        return multiprocessing.get_start_method(allow_none=False) == "fork"
    if isinstance(context, str):
        return context == "fork"
    return context.get_start_method() == "fork"


_CHANNELS_FIRST = {5: (0, 1, 4, 2, 3), 4: (0, 3, 1, 2)}  # (B, [L,] S, S, 3) -> (B, [L,] 3, S, S)


def _channels_first(t: torch.Tensor) -> torch.Tensor:
    return t.movedim(-1, -3)


def _sample(batch: dict, i: int) -> dict:
    out = {}
    for k, v in batch.items():
        out[k] = _sample(v, i) if isinstance(v, dict) else v[i]
    return out
