"""Sending batches out of DataLoader workers cheaply.

torch sends every tensor of a worker's batch as its own shared-memory segment: a new file
(``shm_open``, ``ftruncate``, ``mmap``) that the worker fills page by page and the main
process maps and later frees. On the machines measured that is ~0.25 ms per tensor plus
~1 ms per MB, as much as reading and transforming the batch. Here a batch travels as ONE
buffer taken from a small ring of shared buffers that each worker allocates once:

* the worker packs every array of the batch into a free ring buffer (byte 0 of its header
  set to 1: in flight) and sends the buffer itself (a file descriptor) only the first
  time; afterwards just its key, because the main process keeps every ring buffer mapped.
  No page is allocated, faulted in or freed per batch and no descriptor is passed;
* unpickling in the main process copies the arrays out into ordinary tensors and sets the
  header byte back to 0, which returns the buffer to its worker's ring.

If every ring buffer is still in flight (the main process is slow to unpickle), the worker
falls back to a one-off buffer.

With the ``fork`` start method the buffers are better made BEFORE the workers exist: an
:class:`Arena` is one anonymous shared mapping created in the main process (by
``ClipDataset.loader()``'s DataLoader, just before it forks its workers), which every
worker inherits. A batch then travels as (arena, slot, layout) only: no shared-memory file
is created and no file descriptor is passed (passing one needs a round trip with a thread
of the busy worker, several milliseconds each, for each ring buffer of each worker), so
the first batches of an epoch cost what the later ones do. The per-worker ring remains the
fallback (spawn, a batch larger than a slot, all slots in flight).
"""
from __future__ import annotations

import itertools
import mmap
import os
import weakref

import numpy as np
import torch

__all__ = ["pack_batch", "Arena"]

RING_SLOTS = 6  # per worker: more than DataLoader's default 2 batches in flight per worker
_HEADER = 64  # byte 0: 1 while in flight; data start 64-byte aligned
_MIN_BYTES = 1 << 20

# this worker's buffers: [buffer tensor, its uint8 NumPy view, key, sent to main yet]
_ring: list = []
_generation = itertools.count()
_mapped: dict = {}  # main process: (worker pid, slot, generation) -> buffer


def _shared_bytes(n: int):
    try:  # created in shared memory at once: sending it copies nothing
        return torch.empty(0, dtype=torch.uint8).set_(torch.UntypedStorage._new_shared(n))
    except (AttributeError, RuntimeError):  # pragma: no cover - other torch versions
        return torch.empty(n, dtype=torch.uint8)


def _acquire(nbytes: int) -> tuple:
    """(buffer, raw uint8 view, key) with at least ``nbytes`` after the header, marked in
    flight; ``key`` is None for a one-off buffer."""
    need = _HEADER + nbytes
    free = [slot for slot in _ring if slot[1][0] == 0]
    for slot in free:
        if slot[1].size >= need:
            slot[1][0] = 1
            return slot
    if free or len(_ring) < RING_SLOTS:  # a new or grown ring buffer (25% headroom)
        index = _ring.index(free[0]) if free else len(_ring)
        buf = _shared_bytes(max(_MIN_BYTES, need + need // 4))
        slot = [buf, buf.numpy(), (os.getpid(), index, next(_generation)), False]
        if free:
            _ring[index] = slot
        else:
            _ring.append(slot)
        slot[1][0] = 1
        return slot
    buf = _shared_bytes(need)
    return [buf, buf.numpy(), None, False]


def _remember(key, buffer) -> None:
    """Main process: keeps a ring buffer mapped; forgets the slot's older generations and
    the buffers of workers that have exited."""
    pid, index, _ = key
    for old in [k for k in _mapped if k[:2] == (pid, index)]:
        del _mapped[old]
    for dead in {k[0] for k in _mapped} - {pid}:
        try:
            os.kill(dead, 0)
        except ProcessLookupError:
            for k in [k for k in _mapped if k[0] == dead]:
                del _mapped[k]
        except PermissionError:  # pragma: no cover - a reused pid of another user
            pass
    _mapped[key] = buffer


def _unpack_batch(buffer, key, layout: dict, strings: dict) -> dict:
    """Runs in the receiving process: copies the arrays out, then frees the ring slot."""
    if buffer is None:
        buffer = _mapped.get(key)
        if buffer is None:
            raise RuntimeError(f"bsp_fast.data: batch buffer {key} of a DataLoader worker "
                               "was never received by this process")
    elif key is not None:
        _remember(key, buffer)
    return _copy_out(buffer.numpy(), layout, strings)


def _place(batch: dict, name: str, t, order) -> None:
    """Puts tensor ``t`` of packed entry ``name`` (permuted by ``order``) into ``batch``."""
    if order is not None:
        t = t.permute(*order)
    if name.startswith("meta/"):
        batch["meta"][name[5:]] = t
    else:
        batch[name] = t


def _copy_out(raw: np.ndarray, layout: dict, strings: dict, release: bool = True) -> dict:
    """Copies a packed batch out of ``raw`` into fresh tensors, then frees the slot."""
    batch: dict = {"meta": dict(strings)}
    for name, (offset, nbytes, dtype, shape, order) in layout.items():
        t = torch.empty(shape, dtype=getattr(torch, dtype))
        view = raw[offset:offset + nbytes].view(t.numpy().dtype).reshape(shape)
        np.copyto(t.numpy(), view)
        _place(batch, name, t, order)
    if release:
        raw[0] = 0  # after the copies: the worker may refill the buffer
    return batch


class _PackedBatch:
    """A batch on its way out of a worker; unpickles to a plain dict of tensors."""

    def __init__(self, slot, layout: dict, strings: dict):
        self.slot, self.layout, self.strings = slot, layout, strings

    def __reduce__(self):
        buffer, _, key, sent = self.slot
        if key is not None:
            self.slot[3] = True  # later batches in this slot send only the key
        return (_unpack_batch, (None if sent else buffer, key, self.layout, self.strings))


_tuned_pid = None


def tune_worker_malloc() -> None:
    """Once per worker process: keep freed memory instead of returning it to the system.

    A batch allocates a few large arrays (crops: MBs) and frees them; glibc hands such
    blocks back (munmap / heap trim) and the next batch faults the pages in again, zeroed,
    page by page. Measured on pose-estimation batches (16 clips x 30 frames of 64x64
    crops) in a worker: ~850-1,200 page faults per batch before, ~75 after, and ~20 % less
    CPU per batch. Only DataLoader worker processes are tuned, never the caller's process.
    """
    global _tuned_pid
    if _tuned_pid == os.getpid():
        return
    _tuned_pid = os.getpid()
    try:
        import ctypes

        libc = ctypes.CDLL("libc.so.6")
        libc.mallopt(-3, 32 << 20)  # M_MMAP_THRESHOLD: blocks below 32 MB from the heap
        libc.mallopt(-1, 256 << 20)  # M_TRIM_THRESHOLD: keep up to 256 MB of free heap
    except (OSError, AttributeError):  # pragma: no cover - not glibc
        pass


def packed_nbytes(arrays) -> int:
    """Bytes a batch of these arrays takes in a buffer (after the header)."""
    return sum(-(-a.nbytes // 64) * 64 for a in arrays)


def pack_batch(arrays: dict, meta: dict, strings: dict, permute: dict | None = None,
               arena: Arena | None = None, worker: int = 0):
    """Packs NumPy ``arrays`` and ``meta`` arrays (and ``meta`` string lists) in a worker;
    the main process receives ``{**arrays, "meta": {**meta, **strings}}`` as tensors, the
    arrays named in ``permute`` as ``tensor.permute(*order)`` views. With ``arena`` (the
    pre-fork buffers) the batch goes into one of ``worker``'s slots when one is free."""
    items = list(arrays.items()) + [(f"meta/{k}", v) for k, v in meta.items()]
    layout, total = {}, _HEADER
    for name, a in items:
        dtype = "bool" if a.dtype == np.bool_ else str(a.dtype)
        layout[name] = (total, a.nbytes, dtype, tuple(a.shape), (permute or {}).get(name))
        total += -(-a.nbytes // 64) * 64  # 64-byte aligned arrays
    k = arena.acquire(worker, total - _HEADER) if arena is not None else None
    if k is not None:
        raw, out = arena.slot(k), None
    else:
        slot = _acquire(total - _HEADER)
        raw, out = slot[1], slot
    for name, a in items:
        offset, nbytes, _, shape, _ = layout[name]
        np.copyto(raw[offset:offset + nbytes].view(a.dtype).reshape(shape), a)
    if out is None:
        return _ArenaBatch(arena, k, layout, strings)
    return _PackedBatch(out, layout, strings)


# ----------------------------------------------------------------- pre-fork arena
_arenas: dict = {}  # main process: arena id -> Arena (alive while its DataLoader iterator is)
_arena_ids = itertools.count(1)


class Arena:
    """``workers * slots`` equal buffers in one anonymous shared mapping, made in the main
    process before the workers fork (they inherit it). Worker ``w`` fills only its own
    slots ``[w * slots, (w + 1) * slots)``; byte 0 of a slot is 1 while it is in flight."""

    def __init__(self, workers: int, slots: int, slot_bytes: int):
        self.slot_bytes = -(-(_HEADER + int(slot_bytes)) // 4096) * 4096
        self.workers, self.slots = int(workers), int(slots)
        self._map = mmap.mmap(-1, self.slot_bytes * self.workers * self.slots)
        self.raw = np.frombuffer(self._map, np.uint8)
        self.id = (os.getpid(), next(_arena_ids))
        _arenas[self.id] = self

    def attach(self, owner) -> None:
        """Forgets the arena once ``owner`` (the DataLoader iterator) is gone."""
        weakref.finalize(owner, _arenas.pop, self.id, None)

    def __getstate__(self):  # never pickled: only inherited through fork
        raise TypeError("an Arena lives in one process tree (fork); it cannot be pickled")

    def slot(self, k: int) -> np.ndarray:
        return self.raw[k * self.slot_bytes:(k + 1) * self.slot_bytes]

    def acquire(self, worker: int, nbytes: int):
        """A free slot of ``worker`` marked in flight, or None (too large, all busy)."""
        if _HEADER + nbytes > self.slot_bytes or not 0 <= worker < self.workers:
            return None
        for k in range(worker * self.slots, (worker + 1) * self.slots):
            raw = self.slot(k)
            if raw[0] == 0:
                raw[0] = 1
                return k
        return None


ZERO_COPY_BYTES = 1 << 18  # arena arrays this large are handed out as views, not copied


class _Holds:
    """Frees an arena slot once the last zero-copy array of its batch is gone."""

    def __init__(self, raw: np.ndarray, count: int):
        self.raw, self.count = raw, count

    def drop(self) -> None:
        self.count -= 1
        if self.count == 0:
            self.raw[0] = 0


def _unpack_arena(arena_id, k: int, layout: dict, strings: dict) -> dict:
    """Runs in the main process. Small arrays are copied out; large ones (images) become
    tensors over the slot itself, which goes back to its worker when the last of them is
    garbage (so keeping batches alive only costs slots; the worker then uses its ring)."""
    arena = _arenas.get(tuple(arena_id))
    if arena is None:
        raise RuntimeError(f"bsp_fast.data: batch arena {arena_id} is gone (its DataLoader "
                           "iterator was deleted while a worker batch was in flight)")
    raw = arena.slot(k)
    big = {n for n, (_, nbytes, *_) in layout.items() if nbytes >= ZERO_COPY_BYTES}
    if not big:
        return _copy_out(raw, layout, strings)
    holds = _Holds(raw, len(big))
    batch = _copy_out(raw, {n: v for n, v in layout.items() if n not in big}, strings,
                      release=False)
    for name in big:
        offset, nbytes, dtype, shape, order = layout[name]
        view = raw[offset:offset + nbytes].view(np.dtype(dtype)).reshape(shape)
        weakref.finalize(view, holds.drop)
        _place(batch, name, torch.from_numpy(view), order)
    return batch



class _ArenaBatch:
    def __init__(self, arena: Arena, k: int, layout: dict, strings: dict):
        self.arena_id, self.k, self.layout, self.strings = arena.id, k, layout, strings

    def __reduce__(self):
        return (_unpack_arena, (self.arena_id, self.k, self.layout, self.strings))
