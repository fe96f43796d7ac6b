"""Batch sampling that keeps HDF5 reads contiguous, on one process or many (DDP).

``bsp-convert`` stores each split's clips already shuffled (seeded), so consecutive clips
are unrelated; reading a batch of neighbouring clips is one ``read`` per dataset instead of
one per clip. For training, :class:`ContiguousBatchSampler` still reshuffles every epoch at
block granularity: the clip axis is cut into blocks of ``block_size`` clips (at a random
offset each epoch), the blocks are permuted and concatenated, and batches are consecutive
slices of that order, i.e. about ``batch_size / block_size`` contiguous runs per batch.

With several processes (``torch.distributed``), every rank computes the same epoch order
and takes every ``world_size``-th batch-sized slice of it, so the ranks see disjoint shares
of each epoch and every batch stays made of contiguous runs.
"""
from __future__ import annotations

import math

import numpy as np

from .._extras import require

torch = require("torch")
import torch.utils.data  # noqa: E402

__all__ = ["IndexBatch", "ContiguousBatchSampler", "collate_batch", "derived_seed"]


def derived_seed() -> int:
    """A seed derived from torch's initial seed: fixed by ``torch.manual_seed`` /
    ``lightning.seed_everything``, different in every unseeded process."""
    return int(torch.initial_seed()) % (1 << 63)


class IndexBatch(list):
    """A list of dataset indices that carries the sampler's epoch to the worker processes,
    so train-time noise differs per epoch even with persistent workers. A dataset given an
    ``IndexBatch`` returns one collated batch (a dict), not a list of samples."""

    def __init__(self, indices=(), epoch: int = 0):
        super().__init__(indices)
        self.epoch = int(epoch)

    def __reduce__(self):
        return (IndexBatch, (list(self), self.epoch))


def collate_batch(batch):
    """The DataLoader ``collate_fn`` for :class:`ContiguousBatchSampler` batches: the dataset
    already returns a collated dict of tensors for an :class:`IndexBatch`, so this returns
    it unchanged."""
    return batch


def _positive(name: str, v) -> None:
    if not isinstance(v, int) or isinstance(v, bool) or v <= 0:
        raise ValueError(f"{name} must be a positive integer, got {v!r}")


class ContiguousBatchSampler(torch.utils.data.DistributedSampler):
    """Yields :class:`IndexBatch` lists of mostly contiguous indices, one rank's share.

    ``shuffle=False``: ``[0..B)``, ``[B..2B)``, ... every epoch (evaluation). ``shuffle=True``:
    blocks of ``block_size`` clips at a random offset, permuted per epoch. The epoch counts
    up on every iteration unless :meth:`set_epoch` (called by Lightning) sets it; the order
    of epoch ``e`` is a function of ``(seed, e)``. Without ``seed`` it is derived from
    torch's initial seed (so ``torch.manual_seed``/``seed_everything`` fix it) and, with
    several ranks, taken from rank 0 so that all ranks agree.

    Several ranks: ``num_replicas``/``rank`` (default: ``torch.distributed``'s world size and
    rank once a process group is initialised, else 1 and 0). The epoch order is cut into
    super-batches of ``num_replicas * batch_size`` clips and rank ``r`` takes the ``r``-th
    slice of each; the last super-batch is shared equally. Without ``drop_last`` the order
    is first padded by wrapping around (as ``DistributedSampler`` does, at most
    ``num_replicas - 1`` repeated clips), so every rank gets the same number of batches;
    with ``drop_last`` only whole super-batches are used (no repeats).

    It is used as a DataLoader's ``sampler`` with ``batch_size=None`` (see
    ``ClipDataset.loader``); it subclasses ``DistributedSampler`` so that Lightning keeps it
    instead of injecting its own, which would break the contiguous blocks. As a
    ``batch_sampler=`` it works too, without Lightning's sampler injection.
    """

    def __init__(self, num_items: int, batch_size: int, shuffle: bool = False,
                 block_size: int = 32, drop_last: bool = False, seed: int | None = None, *,
                 num_replicas: int | None = None, rank: int | None = None):
        # DistributedSampler.__init__ is not called: it needs a dataset and a process group
        if isinstance(num_items, torch.utils.data.Sampler):
            raise TypeError(
                "ContiguousBatchSampler takes the number of items, not a sampler: it shares "
                "epochs between ranks itself. Use it as DataLoader(ds, sampler=..., "
                "batch_size=None) as ClipDataset.loader() does, so Lightning keeps it.")
        _positive("batch_size", batch_size)
        _positive("block_size", block_size)
        if not isinstance(num_items, int) or isinstance(num_items, bool) or num_items < 0:
            raise ValueError(f"num_items must be an integer >= 0, got {num_items!r}")
        if seed is not None and (not isinstance(seed, int) or isinstance(seed, bool)):
            raise ValueError(f"seed must be an integer or None, got {seed!r}")
        if num_replicas is not None:
            _positive("num_replicas", num_replicas)
            if rank is None or not 0 <= rank < num_replicas:
                raise ValueError(f"rank must lie in [0, {num_replicas}), got {rank!r}")
        elif rank is not None:
            raise ValueError("rank needs num_replicas")
        self.num_items, self.batch_size = num_items, batch_size
        self.shuffle, self.block_size = bool(shuffle), block_size
        self.drop_last, self.seed = bool(drop_last), seed
        self._replicas, self._rank = num_replicas, rank
        self._seed = seed if seed is not None else derived_seed()
        self._seed_shared = seed is not None or not self.shuffle
        self.epoch = 0
        self._skip = None

    # ----------------------------------------------------------------- ranks
    @property
    def num_replicas(self) -> int:
        if self._replicas is not None:
            return self._replicas
        return _dist()[0]

    @property
    def rank(self) -> int:
        if self._replicas is not None:
            return self._rank
        return _dist()[1]

    def set_epoch(self, epoch: int) -> None:
        self.epoch = int(epoch)

    def __len__(self) -> int:
        W, B = self.num_replicas, self.batch_size
        if self.drop_last:
            return self.num_items // (W * B)
        return math.ceil(math.ceil(self.num_items / W) / B)

    # ----------------------------------------------------------------- orders
    def _base_seed(self) -> int:
        """The seed of the epoch orders; with several ranks and no explicit seed, rank 0's
        (one broadcast, at the first shuffled epoch)."""
        if not self._seed_shared and self.num_replicas > 1:
            d = torch.distributed
            if not (d.is_available() and d.is_initialized()):
                raise ValueError(
                    f"ContiguousBatchSampler: {self.num_replicas} ranks without a process group "
                    "cannot agree on a shuffled order; pass seed= (the same on every rank)")
            box = [self._seed]
            d.broadcast_object_list(box, src=0)
            self._seed = int(box[0])
            self._seed_shared = True
        return self._seed

    def order(self, epoch: int) -> np.ndarray:
        """The permutation of epoch ``epoch`` over all ranks (identity without shuffling)."""
        n = self.num_items
        if not self.shuffle or n == 0:
            return np.arange(n)
        rng = np.random.default_rng([self._base_seed(), epoch])
        k = self.block_size
        first = int(rng.integers(0, min(k, n)))
        edges = np.unique(np.r_[0, np.arange(first, n, k), n])
        blocks = rng.permutation(len(edges) - 1)
        return np.concatenate([np.arange(edges[b], edges[b + 1]) for b in blocks])

    def batches(self, epoch: int, rank: int | None = None) -> list:
        """The index arrays rank ``rank`` (default: this process's) gets in epoch ``epoch``."""
        W = self.num_replicas
        r = self.rank if rank is None else rank
        order, B = self.order(epoch), self.batch_size
        n = len(order)
        if self.drop_last:
            total = (n // (W * B)) * W * B
        else:
            total = W * math.ceil(n / W)
            if total > n:  # pad by wrapping around: every rank the same number of clips
                order = np.resize(order, total)
        out = []
        for start in range(0, total, W * B):
            b = min(W * B, total - start) // W
            out.append(order[start + r * b:start + (r + 1) * b])
        return out

    def skip_batches(self, epoch: int, count: int) -> None:
        """The next iteration over epoch ``epoch`` leaves out its first ``count`` batches
        (a run resumed mid-epoch: those were trained on before the interruption)."""
        self._skip = (int(epoch), int(count))

    def __iter__(self):
        epoch = self.epoch
        self.epoch += 1
        skip = self._skip[1] if self._skip is not None and self._skip[0] == epoch else 0
        self._skip = None
        for b in self.batches(epoch)[skip:]:
            yield IndexBatch(b.tolist(), epoch)


def _dist() -> tuple:
    d = torch.distributed
    if d.is_available() and d.is_initialized():
        return d.get_world_size(), d.get_rank()
    return 1, 0
