"""Random draws of a batch that are a pure function of each clip, not of the batch.

Every random number a dataset applies to a clip (noise, missing joints, flips, rotations,
image augmentation, box noise) comes from :class:`ClipRandom`: one counter-based stream
per clip, keyed by ``(seed, split, epoch, the clip's row in the file)`` (the epoch is 0 for
``val`` and ``test``). The n-th number of clip c's stream is ``mix(key_c + n * G)`` with
SplitMix64's output function ``mix`` and its increment ``G`` (Steele et al., 2014): the
SplitMix64 sequence started at ``key_c``. So batch size, batch composition, shuffle
order, worker count and DDP rank change nothing: a clip scored alone, in a batch of 7 or in
one of 64 gets the same corruption.

The generator quacks like the part of :class:`numpy.random.Generator` that the transforms
use (``random``, ``uniform``, ``standard_normal``) with one rule: the first axis of every
``size`` is the batch axis, one clip per entry. Each call takes the next
``prod(size[1:])`` numbers of every clip's stream (two float32 per 64-bit word), so a
clip's draws depend only on its key and the sequence of calls, which is fixed by the
dataset's settings. It is vectorised over the batch in NumPy (no per-clip Python loop):
``docs/performance.md`` has the loader's rate with it.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["ClipRandom", "clip_keys"]

_MASK = (1 << 64) - 1
_G = 0x9E3779B97F4A7C15  # SplitMix64's increment (golden ratio)
_M1, _M2 = 0xBF58476D1CE4E5B9, 0x94D049BB133111EB
_U64 = {name: np.uint64(v) for name, v in (("G", _G), ("M1", _M1), ("M2", _M2))}
_S30, _S27, _S31 = np.uint64(30), np.uint64(27), np.uint64(31)
_S32, _S40, _S11 = np.uint64(32), np.uint64(40), np.uint64(11)
_LOW24 = np.uint64(0xFFFFFF)


def _mix_int(z: int) -> int:
    """SplitMix64's output function on a Python int (64-bit wrap-around)."""
    z &= _MASK
    z = ((z ^ (z >> 30)) * _M1) & _MASK
    z = ((z ^ (z >> 27)) * _M2) & _MASK
    return z ^ (z >> 31)


def _mix(z: np.ndarray) -> np.ndarray:
    """SplitMix64's output function, in place on a uint64 array (wraps, no warnings)."""
    z ^= z >> _S30
    z *= _U64["M1"]
    z ^= z >> _S27
    z *= _U64["M2"]
    z ^= z >> _S31
    return z


def clip_keys(seed: int, split: int, epoch: int, rows) -> np.ndarray:
    """The uint64 stream keys of clips ``rows`` (their rows in the split's arrays) for
    ``seed``, split code ``split`` and ``epoch``: each argument goes through the mixer in
    turn, so neighbouring seeds, epochs or rows give unrelated streams."""
    base = _mix_int(_mix_int(_mix_int(int(seed) + _G) + int(split) + 1) + int(epoch) + 1)
    r = np.asarray(rows, np.int64).astype(np.uint64)
    return _mix(r * _U64["G"] + np.uint64(base))


def _per_clip(size, batch: int) -> tuple:
    shape = (size,) if isinstance(size, (int, np.integer)) else tuple(int(s) for s in size)
    if not shape or shape[0] != batch:
        raise ValueError(f"ClipRandom: the first axis of size {shape} must be the batch's "
                         f"{batch} clips")
    return shape, math.prod(shape[1:])


class ClipRandom:
    """Per-clip streams for a batch of clips with stream keys ``keys`` (see
    :func:`clip_keys`); ``ClipRandom.for_rows(seed, split, epoch, rows)`` builds one."""

    def __init__(self, keys):
        self.keys = np.ascontiguousarray(keys, np.uint64).reshape(-1)
        self.used = 0  # numbers (64-bit words) taken from every clip's stream so far

    @classmethod
    def for_rows(cls, seed: int, split: int, epoch: int, rows) -> "ClipRandom":
        return cls(clip_keys(seed, split, epoch, rows))

    def __len__(self) -> int:
        return len(self.keys)

    def __repr__(self) -> str:
        return f"ClipRandom(clips={len(self)}, used={self.used})"

    def words(self, n: int) -> np.ndarray:
        """The next ``n`` 64-bit numbers of every clip's stream, ``(clips, n)`` uint64."""
        counters = np.arange(self.used, self.used + n, dtype=np.uint64)
        counters *= _U64["G"]
        self.used += n
        return _mix(self.keys[:, None] + counters[None, :])

    def _float32(self, n: int) -> np.ndarray:
        """``(clips, n)`` float32 uniform in [0, 1) on a 2^-24 grid, two per word."""
        w = self.words((n + 1) // 2)
        out = np.empty((len(self), 2 * w.shape[1]), np.float32)
        out[:, 0::2] = (w >> _S40).astype(np.float32)
        out[:, 1::2] = (w & _LOW24).astype(np.float32)
        out *= np.float32(2.0 ** -24)
        return out[:, :n]

    def random(self, size, dtype=np.float64) -> np.ndarray:
        """Uniform in [0, 1): float64 on a 2^-53 grid, float32 on a 2^-24 grid."""
        shape, n = _per_clip(size, len(self))
        if np.dtype(dtype) == np.float32:
            return self._float32(n).reshape(shape)
        if np.dtype(dtype) != np.float64:
            raise ValueError(f"ClipRandom.random: dtype must be float32 or float64, got {dtype}")
        u = (self.words(n) >> _S11).astype(np.float64)
        u *= 2.0 ** -53
        return u.reshape(shape)

    def uniform(self, low=0.0, high=1.0, size=None) -> np.ndarray:
        """float64 uniform in [low, high), ``size`` led by the batch axis."""
        return low + (high - low) * self.random(size)

    def standard_normal(self, size, dtype=np.float32) -> np.ndarray:
        """N(0, 1) by Box-Muller, one word (two 24-bit uniforms) per pair of numbers; the
        largest magnitude is sqrt(2 ln 2^25) = 5.9 (a 4e-9 tail is cut off)."""
        if np.dtype(dtype) not in (np.dtype(np.float32), np.dtype(np.float64)):
            raise ValueError(f"ClipRandom.standard_normal: dtype must be float32 or float64, "
                             f"got {dtype}")
        shape, n = _per_clip(size, len(self))
        half = (n + 1) // 2
        w = self.words(half)
        u1 = (w >> _S40).astype(np.float32)  # (0, 1] after the half step: log is finite
        u1 += np.float32(0.5)
        u1 *= np.float32(2.0 ** -24)
        angle = (w & _LOW24).astype(np.float32)
        angle *= np.float32(2 * np.pi * 2.0 ** -24)
        r = np.log(u1, out=u1)
        r *= np.float32(-2.0)
        np.sqrt(r, out=r)
        out = np.empty((len(self), 2 * half), np.float32)
        np.cos(angle, out=out[:, :half])
        np.sin(angle, out=out[:, half:])
        out[:, :half] *= r
        out[:, half:] *= r
        out = out[:, :n].reshape(shape)
        return out if np.dtype(dtype) == np.float32 else out.astype(np.float64)
