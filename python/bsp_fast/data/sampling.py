"""Batch sampling that keeps HDF5 reads contiguous.

``bsp-convert`` stores each split's clips already shuffled (seeded), so consecutive clips
are unrelated; reading a batch of neighbouring clips is one ``read`` per dataset instead of
one per clip. For training, :class:`ContiguousBatchSampler` still reshuffles every epoch at
block granularity: the clip axis is cut into blocks of ``block_size`` clips (at a random
offset each epoch), the blocks are permuted and concatenated, and batches are consecutive
slices of that order, i.e. about ``batch_size / block_size`` contiguous runs per batch.
"""
from __future__ import annotations

import math

import numpy as np
import torch.utils.data

__all__ = ["IndexBatch", "ContiguousBatchSampler", "collate_batch"]


class IndexBatch(list):
    """A list of dataset indices that carries the sampler's epoch to the worker processes,
    so train-time noise differs per epoch even with persistent workers."""

    def __init__(self, indices=(), epoch: int = 0):
        super().__init__(indices)
        self.epoch = int(epoch)

    def __reduce__(self):
        return (IndexBatch, (list(self), self.epoch))


def collate_batch(batch):
    """The DataLoader ``collate_fn`` for :class:`ClipDataset`: ``__getitems__`` already
    returns a collated dict of tensors, so this returns it unchanged."""
    return batch


class ContiguousBatchSampler(torch.utils.data.Sampler):
    """Yields :class:`IndexBatch` lists of mostly contiguous indices.

    ``shuffle=False``: ``[0..B)``, ``[B..2B)``, ... every epoch (evaluation). ``shuffle=True``:
    blocks of ``block_size`` clips at a random offset, permuted per epoch. The epoch counts
    up on every iteration unless :meth:`set_epoch` (called by Lightning) sets it; the order
    of epoch ``e`` is a function of ``(seed, e)`` when ``seed`` is given, else fresh.
    """

    def __init__(self, num_items: int, batch_size: int, shuffle: bool = False,
                 block_size: int = 32, drop_last: bool = False, seed: int | None = None):
        for name, v in (("batch_size", batch_size), ("block_size", block_size)):
            if not isinstance(v, int) or isinstance(v, bool) or v <= 0:
                raise ValueError(f"{name} must be a positive integer, got {v!r}")
        if not isinstance(num_items, int) or num_items < 0:
            raise ValueError(f"num_items must be an integer >= 0, got {num_items!r}")
        self.num_items, self.batch_size = num_items, batch_size
        self.shuffle, self.block_size = bool(shuffle), block_size
        self.drop_last, self.seed = bool(drop_last), seed
        self.epoch = 0

    def set_epoch(self, epoch: int) -> None:
        self.epoch = int(epoch)

    def __len__(self) -> int:
        if self.drop_last:
            return self.num_items // self.batch_size
        return math.ceil(self.num_items / self.batch_size)

    def order(self, epoch: int) -> np.ndarray:
        """The permutation of epoch ``epoch`` (identity without shuffling)."""
        n = self.num_items
        if not self.shuffle or n == 0:
            return np.arange(n)
        rng = np.random.default_rng(None if self.seed is None else [self.seed, epoch])
        k = self.block_size
        first = int(rng.integers(0, min(k, n)))
        edges = np.unique(np.r_[0, np.arange(first, n, k), n])
        blocks = rng.permutation(len(edges) - 1)
        return np.concatenate([np.arange(edges[b], edges[b + 1]) for b in blocks])

    def __iter__(self):
        epoch = self.epoch
        self.epoch += 1
        order = self.order(epoch)
        for i in range(len(self)):
            yield IndexBatch(order[i * self.batch_size:(i + 1) * self.batch_size].tolist(), epoch)
