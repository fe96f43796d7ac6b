"""``ClipDataset``: one split of a ``bsp-convert`` HDF5 file as batches of torch tensors.

The four tasks of the report (see docs/data.md for every key and shape):

* ``classification``: normalised 2D clip -> crossing label;
* ``autoencoder``: deformed normalised 2D -> clean normalised 2D;
* ``lifting``: normalised 2D -> hips-centred, hips-neck-scaled 3D (plus raw metres);
* ``pose_estimation``: crops ``frames/rgb`` -> 2D joints in crop pixels with visibility.

Reading: the file is opened lazily in the process that reads (each DataLoader worker) and
closed before any ``fork`` of this process. ``__getitems__`` reads a batch with one call
per HDF5 dataset and contiguous run of clips and transforms it vectorised; it returns a
collated dict, so loaders use :func:`collate_batch` (``ClipDataset.loader`` sets it up).
"""
from __future__ import annotations

import os
import warnings
import weakref
import zlib
from pathlib import Path

import numpy as np
import torch
import torch.utils.data

from . import transforms as T
from .sampling import ContiguousBatchSampler, collate_batch
from .transport import pack_batch

__all__ = ["ClipDataset", "TASKS", "SPLITS", "LIFTING_TARGETS", "DEFAULT_EVAL_SEED"]

TASKS = ("classification", "autoencoder", "lifting", "pose_estimation")
SPLITS = ("train", "val", "test")
LIFTING_TARGETS = ("absolute", "world", "camera")
AUGMENTED_TASKS = ("classification", "autoencoder")  # SPEC 5: augmentation for 2D tasks
DEFAULT_EVAL_SEED = 22742
_SPLIT_CODE = {s: i for i, s in enumerate(SPLITS)}
_META_STR = ("video_id", "pedestrian_id", "age", "gender")
_META_INT = ("clip_id", "start_frame", "end_frame")
_MEDIA = ("frames/rgb", "frames/crop_box", "frames/joint_visible", "clip_frames")
_CHANNELS_FIRST = (0, 1, 4, 2, 3)  # (B, L, S, S, 3) -> (B, L, 3, S, S)

_open_datasets: "weakref.WeakSet[ClipDataset]" = weakref.WeakSet()


def _close_before_fork() -> None:
    # HDF5 handles must not cross a fork (SPEC/STYLE): children reopen lazily.
    for ds in list(_open_datasets):
        ds.close()


os.register_at_fork(before=_close_before_fork)


class _Rows:
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


def _rotation_matrices(pyr: np.ndarray) -> np.ndarray:
    """CARLA rotation matrices (SPEC section 3) of ``(N, 3)`` degrees, in NumPy so no
    worker process ever needs the C++ core's thread pool."""
    p, y, r = np.deg2rad(pyr.astype(np.float64)).T
    cp, sp, cy, sy, cr, sr = np.cos(p), np.sin(p), np.cos(y), np.sin(y), np.cos(r), np.sin(r)
    return np.stack([
        np.stack([cp * cy, cy * sp * sr - sy * cr, -cy * sp * cr - sy * sr], -1),
        np.stack([cp * sy, sy * sp * sr + cy * cr, -sy * sp * cr + cy * sr], -1),
        np.stack([sp, -cp * sr, cp * cr], -1)], -2)


def _choice(name: str, value, allowed) -> None:
    if value not in allowed:
        raise ValueError(f"{name} must be one of {list(allowed)}, got {value!r}")


class ClipDataset(torch.utils.data.Dataset):
    """One split of a converted HDF5 file for one task.

    Options: ``noise`` (Gaussian sigma in pixels) and ``mjp`` (missing-joint probability,
    one number or 26) deform the 2D inputs only. ``augment`` (default: True for the train
    split of the 2D tasks) flips with probability ``flip_p`` and rotates by up to
    ``rotation`` degrees. Randomness: the train split draws fresh values every batch unless
    ``seed`` is given (then they depend on seed, epoch and batch indices); val and test use
    ``seed`` (default 22742) with epoch 0, so a given batch of indices always gets the same
    inputs. ``balance`` keeps the first min-class-count clips of each class (stored order).
    ``lifting_target`` picks the 3D frame: ``absolute`` (walker actor / component space),
    ``world`` or ``camera`` (CARLA camera axes, x forward). ``with_pixels`` adds the clean
    (augmented) 2D joints in image pixels as ``pixels``; ``with_mask`` the segmentation
    crops (``pose_estimation``). ``indices`` restricts the split to those stored rows.
    """

    def __init__(self, h5_path, split: str = "train", task: str = "classification", *,
                 noise: float = 0.0, mjp=0.0, augment: bool | None = None, flip_p: float = 0.5,
                 rotation: float = 10.0, seed: int | None = None, balance: bool = False,
                 lifting_target: str = "absolute", with_mask: bool = False,
                 with_pixels: bool = False, indices=None):
        _choice("split", split, SPLITS)
        _choice("task", task, TASKS)
        _choice("lifting_target", lifting_target, LIFTING_TARGETS)
        self.h5_path, self.split, self.task = str(Path(h5_path)), split, task
        self.lifting_target, self.with_mask = lifting_target, bool(with_mask)
        self.with_pixels = bool(with_pixels)
        self._deform = T.Deform(noise, mjp)
        self.noise, self.mjp = float(noise), self._deform.transforms[1].p
        self._deforming = self.noise > 0 or bool(np.any(self.mjp > 0))
        if augment is None:
            augment = split == "train" and task in AUGMENTED_TASKS
        if augment and task not in AUGMENTED_TASKS:
            raise ValueError(f"augment: flips and rotations apply to the 2D tasks "
                             f"{list(AUGMENTED_TASKS)} only, not {task!r}")
        if task == "pose_estimation" and self._deforming:
            raise ValueError("noise/mjp deform 2D joint inputs; pose_estimation inputs are images")
        self.augment = bool(augment)
        self._augment = T.RandomFlipRotate(flip_p, rotation)  # = Compose([flip, rotation])
        self.seed = seed if seed is not None or split == "train" else DEFAULT_EVAL_SEED
        self.epoch = 0
        self._file, self._pid, self._ds = None, None, {}
        self._read_header(indices, balance)

    # ----------------------------------------------------------------- header and meta
    def _read_header(self, indices, balance: bool) -> None:
        import h5py

        with h5py.File(self.h5_path, "r") as f:
            version = int(f.attrs.get("schema_version", -1))
            if version != 1:
                raise ValueError(f"{self.h5_path}: schema_version {version}, expected 1 "
                                 "(a bsp-convert file, see docs/hdf5-schema.md)")
            if self.split not in f:
                raise ValueError(f"{self.h5_path}: no group /{self.split}")
            g = f[self.split]
            missing = [n for n in self._required() if n not in g]
            if missing:
                hint = (" (convert with media=True, i.e. without --no-media)"
                        if any(n in _MEDIA for n in missing) else "")
                raise ValueError(f"{self.h5_path}: /{self.split} lacks {missing} needed by task "
                                 f"{self.task!r}{hint}")
            self.attrs = {k: _plain(v) for k, v in f.attrs.items()}
            self.clip_length = int(f.attrs["clip_length"])
            self._labels = g["labels"][()].astype(np.int64)
            self._meta = {k: g[f"meta/{k}"].asstr()[()].astype(object) for k in _META_STR}
            self._meta.update({k: g[f"meta/{k}"][()].astype(np.int64) for k in _META_INT})
            self._width = g["meta/clip_width"][()].astype(np.float32)
            if self.lifting_target == "camera" and self.task == "lifting":
                cam = g["meta/camera_transform"][()].astype(np.float64)
                self._cam_t, self._cam_r = cam[:, :3], _rotation_matrices(cam[:, 3:])
        n = len(self._labels)
        rows = np.arange(n) if indices is None else np.asarray(indices, np.int64)
        if rows.ndim != 1 or (len(rows) and (rows.min() < 0 or rows.max() >= n)):
            raise ValueError(f"indices must be a 1-D list of rows in [0, {n}) of /{self.split}")
        self._rows = self._balanced(rows) if balance else rows

    def _required(self) -> list:
        names = ["projection_2d", "labels", "targets/frame_idx", "meta/clip_width"]
        names += [f"meta/{k}" for k in _META_STR + _META_INT]
        if self.task == "lifting":
            names.append("targets/" + ("absolute" if self.lifting_target == "absolute"
                                       else "world") + "_pose_loc")
            if self.lifting_target == "camera":
                names.append("meta/camera_transform")
        if self.task == "pose_estimation":
            names += list(_MEDIA) + (["frames/mask"] if self.with_mask else [])
        return names

    def _balanced(self, rows: np.ndarray) -> np.ndarray:
        labels = self._labels[rows]
        counts = np.bincount(labels, minlength=2)
        if counts.min() == 0:  # the converter's rule gives an empty split: say so
            warnings.warn(f"balance: /{self.split} of {self.h5_path} has class counts "
                          f"{counts.tolist()}; balancing leaves no clip", stacklevel=3)
        keep = np.concatenate([np.flatnonzero(labels == c)[:counts.min()] for c in range(2)])
        return rows[np.sort(keep)]

    @property
    def class_counts(self) -> list:
        """``[not-crossing, crossing]`` clips in this dataset (after balancing/indices)."""
        return np.bincount(self._labels[self._rows], minlength=2).tolist()

    @property
    def labels(self) -> np.ndarray:
        """Crossing labels of every clip of this dataset, in index order."""
        return self._labels[self._rows]

    def __len__(self) -> int:
        return len(self._rows)

    def __repr__(self) -> str:
        return (f"ClipDataset({self.h5_path!r}, split={self.split!r}, task={self.task!r}, "
                f"clips={len(self)}, L={self.clip_length}, noise={self.noise}, "
                f"augment={self.augment})")

    # ----------------------------------------------------------------- file handling
    def _h5(self):
        if self._file is None or self._pid != os.getpid():
            import h5py

            self._file, self._pid, self._ds = h5py.File(self.h5_path, "r"), os.getpid(), {}
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
        state.update(_file=None, _pid=None, _ds={})
        return state

    def set_epoch(self, epoch: int) -> None:
        """Epoch used for seeded train randomness when batches do not carry one."""
        self.epoch = int(epoch)

    # ----------------------------------------------------------------- reading
    def __getitem__(self, index):
        if isinstance(index, (int, np.integer)):
            i = int(index) + (len(self) if index < 0 else 0)
            batch = self.__getitems__([i])
            return _unbatch(batch)
        if isinstance(index, slice):
            return self.__getitems__(list(range(*index.indices(len(self)))))
        return self.__getitems__(index)

    def __getitems__(self, indices) -> dict:
        pos = np.asarray(list(indices), np.int64)
        if pos.ndim != 1 or len(pos) == 0:
            raise ValueError("ClipDataset: expected a non-empty list of indices")
        if pos.min() < 0 or pos.max() >= len(self):
            raise IndexError(f"index out of range [0, {len(self)}) in {self!r}")
        rows = self._rows[pos]
        reader = _Rows(rows)
        rng = self._rng(pos, getattr(indices, "epoch", self.epoch))
        if self.task == "pose_estimation":
            out = self._pose_estimation(reader)
        else:
            out = self._from_2d(reader, rows, rng)
        out["label"] = self._labels[rows]
        if self.task == "classification":
            out["targets"] = out["label"]
        meta = self._meta_batch(pos, rows, reader)
        strings = {k: self._meta[k][rows].tolist() for k in _META_STR}
        permute = {"inputs": _CHANNELS_FIRST} if self.task == "pose_estimation" else {}
        if torch.utils.data.get_worker_info() is not None:  # leaving a worker: one buffer
            return pack_batch(out, meta, strings, permute)
        batch = {k: torch.from_numpy(np.ascontiguousarray(v)) for k, v in out.items()}
        for k, order in permute.items():
            batch[k] = batch[k].permute(*order)
        batch["meta"] = {k: torch.from_numpy(v) for k, v in meta.items()}
        batch["meta"].update(strings)
        return batch

    def _rng(self, pos: np.ndarray, epoch: int) -> np.random.Generator:
        # SFC64: ~15% faster normals than the default PCG64, and noise is most of the work
        if self.seed is None:  # train without a seed: fresh entropy (per worker, per batch)
            return np.random.Generator(np.random.SFC64())
        epoch = epoch if self.split == "train" else 0
        key = zlib.crc32(pos.tobytes())
        entropy = [self.seed, _SPLIT_CODE[self.split], epoch, key, len(pos)]
        return np.random.Generator(np.random.SFC64(np.random.SeedSequence(entropy)))

    def _from_2d(self, reader: _Rows, rows: np.ndarray, rng) -> dict:
        pixels = reader.read(self._dataset("projection_2d"))
        if self.augment:
            pixels = self._augment(pixels, rng=rng, width=self._width[rows])
        vis = T.visible_joints(pixels)
        if self._deforming:
            inputs, vis = self._deform.apply(pixels, rng, vis)
        else:
            inputs = pixels
        n = T.normalize_hips_neck(inputs, vis)
        out = dict(inputs=n.points, visible=n.visible, shift=n.shift, scale=n.scale)
        if self.with_pixels:
            out["pixels"] = pixels
        if self.task == "autoencoder":
            t = n if not self._deforming else T.normalize_hips_neck(pixels)
            out.update(targets=t.points, target_shift=t.shift, target_scale=t.scale)
        elif self.task == "lifting":
            out.update(self._lifting_targets(reader, rows))
        return out

    def _lifting_targets(self, reader: _Rows, rows: np.ndarray) -> dict:
        frame = "absolute" if self.lifting_target == "absolute" else "world"
        metres = reader.read(self._dataset(f"targets/{frame}_pose_loc"))
        if self.lifting_target == "camera":  # x_cam = R_c^T (p - t_c)
            d = metres.astype(np.float64) - self._cam_t[rows][:, None, None, :]
            metres = np.einsum("bij,blki->blkj", self._cam_r[rows], d).astype(np.float32)
        t, shift, scale = T.normalize_hips_neck_3d(metres)
        return dict(targets=t, targets_m=metres, target_shift=shift, target_scale=scale)

    def _pose_estimation(self, reader: _Rows) -> dict:
        frames = reader.read(self._dataset("clip_frames"))
        freader = _Rows(frames.reshape(-1))
        rgb = freader.read(self._dataset("frames/rgb"))
        B, L = frames.shape
        S = rgb.shape[1]
        box = freader.read(self._dataset("frames/crop_box")).reshape(B, L, 4)
        pixels = reader.read(self._dataset("projection_2d"))
        size = np.stack([box[..., 2] - box[..., 0], box[..., 3] - box[..., 1]], -1)
        crop = (pixels - box[..., None, :2]) * (S / size)[..., None, :]
        vis = freader.read(self._dataset("frames/joint_visible")).reshape(B, L, -1) != 0
        # stored channels-last; handed out as a channels-first VIEW (B, L, 3, S, S): a
        # transposing copy of the images would cost more than reading them
        out = dict(inputs=rgb.reshape((B, L) + rgb.shape[1:]),
                   targets=crop.astype(np.float32), visible=vis, crop_box=box)
        if self.with_pixels:
            out["pixels"] = pixels
        if self.with_mask:
            out["mask"] = freader.read(self._dataset("frames/mask")).reshape((B, L, S, S))
        return out

    def _meta_batch(self, pos, rows, reader: _Rows) -> dict:
        meta = {k: self._meta[k][rows] for k in _META_INT}
        meta["frames"] = reader.read(self._dataset("targets/frame_idx"))
        meta["index"] = pos
        meta["row"] = rows
        return meta

    # ----------------------------------------------------------------- loaders
    def loader(self, batch_size: int = 256, shuffle: bool | None = None, num_workers: int = 0,
               block_size: int = 32, drop_last: bool = False, sampler_seed: int | None = None,
               **kwargs) -> torch.utils.data.DataLoader:
        """A DataLoader reading contiguous batches (shuffled by blocks for ``train``).

        Extra keyword arguments go to :class:`torch.utils.data.DataLoader`;
        ``persistent_workers`` defaults to True when ``num_workers > 0``.
        """
        shuffle = self.split == "train" if shuffle is None else shuffle
        sampler = ContiguousBatchSampler(len(self), batch_size, shuffle, block_size,
                                         drop_last, sampler_seed)
        kwargs.setdefault("persistent_workers", num_workers > 0)
        return torch.utils.data.DataLoader(self, batch_sampler=sampler, collate_fn=collate_batch,
                                           num_workers=num_workers, **kwargs)


def _plain(value):
    """An HDF5 attribute as plain Python (str, int, float, list)."""
    if isinstance(value, bytes):
        return value.decode()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return [v.decode() if isinstance(v, bytes) else v for v in value.tolist()]
    return value


def _unbatch(batch: dict) -> dict:
    out = {}
    for k, v in batch.items():
        out[k] = _unbatch(v) if isinstance(v, dict) else v[0]
    return out
