"""``ClipDataset``: one split of a ``bsp-convert`` HDF5 file as batches of torch tensors.

The four tasks of the report (see docs/data.md for every key and shape):

* ``classification``: normalised 2D clip -> crossing label;
* ``autoencoder``: deformed normalised 2D -> clean normalised 2D;
* ``lifting``: normalised 2D -> hips-centred, hips-neck-scaled 3D (plus raw metres);
* ``pose_estimation``: crops ``frames/rgb`` -> 2D joints in crop pixels with visibility.

Reading: the file is opened lazily in the process that reads (each DataLoader worker) and
closed before any ``fork`` of this process. A batch is read with one call per HDF5 dataset
and contiguous run of clips and transformed vectorised (see :mod:`.base` for what
``ds[i]``, ``ds[list]`` and a plain ``DataLoader`` get).
"""
from __future__ import annotations

import warnings

import numpy as np

from . import images as I
from . import transforms as T
from .base import DEFAULT_EVAL_SEED, SPLITS, Rows, SplitDataset, choice, plain

__all__ = ["ClipDataset", "TASKS", "SPLITS", "LIFTING_TARGETS", "DEFAULT_EVAL_SEED",
           "NO_EVENT"]

TASKS = ("classification", "autoencoder", "lifting", "pose_estimation")
LIFTING_TARGETS = ("absolute", "world", "camera")
AUGMENTED_TASKS = ("classification", "autoencoder")  # 2D flips/rotations; images: pose
_META_STR = ("video_id", "pedestrian_id", "age", "gender")
_META_INT = ("clip_id", "start_frame", "end_frame")
#: ``meta/tte`` of a clip without an event (not a benchmark window), as the C++ kNoEvent
NO_EVENT = -1
MEDIA_DATASETS = ("frames/rgb", "frames/crop_box", "frames/joint_visible", "clip_frames")
CONTEXT_DATASETS = ("frames/context_rgb", "frames/context_box")


def _rotation_matrices(pyr: np.ndarray) -> np.ndarray:
    """CARLA rotation matrices (docs/dataset-format.md) of ``(N, 3)`` degrees, in NumPy so
    no worker process ever needs the C++ core's thread pool."""
    p, y, r = np.deg2rad(pyr.astype(np.float64)).T
    cp, sp, cy, sy, cr, sr = np.cos(p), np.sin(p), np.cos(y), np.sin(y), np.cos(r), np.sin(r)
    return np.stack([
        np.stack([cp * cy, cy * sp * sr - sy * cr, -cy * sp * cr - sy * sr], -1),
        np.stack([cp * sy, sy * sp * sr + cy * cr, -sy * sp * cr + cy * sr], -1),
        np.stack([sp, -cp * sr, cp * cr], -1)], -2)


class ClipDataset(SplitDataset):
    """One split of a converted HDF5 file for one task.

    Options: ``noise`` (Gaussian sigma in pixels) and ``mjp`` (missing-joint probability,
    one number or 26) deform the 2D inputs only. ``augment`` (default: True for the train
    split of the 2D tasks) flips with probability ``flip_p`` and rotates by up to
    ``rotation`` degrees; for ``pose_estimation`` (off by default) it flips, zooms
    (``image_scale``), shifts (``image_shift``), rotates (``image_rotation`` degrees,
    default 0) and colour-jitters the crops with the joints
    (:class:`~bsp_fast.data.images.ImageAugment`). ``image_dtype="float32"`` gives
    crops on [0, 1], ``mean``/``std`` normalise them per channel. Randomness depends on
    ``(seed, epoch, batch indices)``; the train split's ``seed`` defaults to one derived
    from torch's initial seed (``seed_everything`` fixes it), val and test use ``seed``
    (default ``bsp_fast.defaults.SEED``) with epoch 0, so a given batch of indices always gets the same inputs.
    ``balance`` keeps the first min-class-count clips of each class (stored order).
    ``lifting_target`` picks the 3D frame: ``absolute`` (walker actor / component space),
    ``world`` or ``camera`` (CARLA camera axes, x forward). ``with_pixels`` adds the clean
    (augmented) 2D joints in image pixels as ``pixels``; ``with_mask`` the segmentation
    crops (``pose_estimation``). ``indices`` restricts the split to those stored rows.
    ``transform``/``target_transform`` are called on each sample's ``inputs``/``targets``
    tensor (torchvision style; crops channels first) after everything else.
    ``box_noise=(scale, shift)`` (``pose_estimation``) perturbs each frame's crop box like
    a detector would (:class:`~bsp_fast.data.images.BoxNoise`) and cuts the crop out of
    the stored context crop (a file converted with ``crop_context``; docs/data.md, "Box
    noise"): train boxes change every epoch, val/test boxes are fixed per clip by
    ``seed``, whatever the batch size.
    """

    def __init__(self, h5_path, split: str = "train", task: str = "classification", *,
                 noise: float = 0.0, mjp=0.0, augment: bool | None = None, flip_p: float = 0.5,
                 rotation: float = 10.0, seed: int | None = None, balance: bool = False,
                 lifting_target: str = "absolute", with_mask: bool = False,
                 with_pixels: bool = False, indices=None, image_dtype: str = "uint8",
                 mean=None, std=None, image_scale: float = 0.1, image_shift: float = 0.05,
                 color_jitter: float = 0.2, transform=None, target_transform=None,
                 box_noise=None, image_rotation: float = 0.0):
        choice("task", task, TASKS)
        choice("lifting_target", lifting_target, LIFTING_TARGETS)
        self._init_common(h5_path, split, seed, transform, target_transform)
        self.task = task
        self.lifting_target, self.with_mask = lifting_target, bool(with_mask)
        self.with_pixels = bool(with_pixels)
        self._deform = T.Deform(noise, mjp)
        self.noise, self.mjp = float(noise), self._deform.transforms[1].p
        self._deforming = self.noise > 0 or bool(np.any(self.mjp > 0))
        if augment is None:
            augment = split == "train" and task in AUGMENTED_TASKS
        if augment and task not in AUGMENTED_TASKS + ("pose_estimation",):
            raise ValueError(f"augment: flips and rotations apply to the 2D tasks "
                             f"{list(AUGMENTED_TASKS)} (and image augmentation to "
                             f"pose_estimation), not {task!r}")
        if task == "pose_estimation" and self._deforming:
            raise ValueError("noise/mjp deform 2D joint inputs; pose_estimation inputs are images")
        self.image_dtype, self.mean, self.std = I.check_image_options(image_dtype, mean, std)
        if task != "pose_estimation" and (self.image_dtype != "uint8" or self.mean is not None):
            raise ValueError("image_dtype/mean/std apply to pose_estimation crops only")
        self.augment = bool(augment)
        self.box_noise = I.BoxNoise(*(box_noise or (0.0, 0.0)))
        if self.box_noise and task != "pose_estimation":
            raise ValueError("box_noise perturbs the crop boxes of pose_estimation only")
        if task == "pose_estimation":
            self._augment = I.ImageAugment(flip_p, image_scale, image_shift, color_jitter,
                                           image_rotation)
        else:
            self._augment = T.RandomFlipRotate(flip_p, rotation)  # = Compose([flip, rotation])
        self._read_header(indices, balance)

    # ----------------------------------------------------------------- header and meta
    def _read_header(self, indices, balance: bool) -> None:
        from ..conversion.vds import open_clip_file

        with open_clip_file(self.h5_path) as f:
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
                        if any(n in MEDIA_DATASETS for n in missing) else "")
                raise ValueError(f"{self.h5_path}: /{self.split} lacks {missing} needed by task "
                                 f"{self.task!r}{hint}")
            self.attrs = {k: plain(v) for k, v in f.attrs.items()}
            self.clip_length = int(f.attrs["clip_length"])
            self._labels = g["labels"][()].astype(np.int64)
            self._meta = {k: g[f"meta/{k}"].asstr()[()].astype(object) for k in _META_STR}
            self._meta.update({k: g[f"meta/{k}"][()].astype(np.int64) for k in _META_INT})
            # time to event (benchmark windows); a file written before meta/tte existed
            # reads as clips without an event, and says so (has_tte, tte_problem)
            self.has_tte = "meta/tte" in g
            self._tte = (g["meta/tte"][()].astype(np.int64) if self.has_tte
                         else np.full(len(self._labels), NO_EVENT, np.int64))
            self._width = g["meta/clip_width"][()].astype(np.float32)
            if self.lifting_target == "camera" and self.task == "lifting":
                cam = g["meta/camera_transform"][()].astype(np.float64)
                self._cam_t, self._cam_r = cam[:, :3], _rotation_matrices(cam[:, 3:])
        n = len(self._labels)
        rows = np.arange(n) if indices is None else np.asarray(indices, np.int64)
        if rows.ndim != 1 or (len(rows) and (rows.min() < 0 or rows.max() >= n)):
            raise ValueError(f"indices must be a 1-D list of rows in [0, {n}) of /{self.split}")
        self._rows = self._balanced(rows) if balance else rows
        self._check_context()

    def _check_context(self) -> None:
        if not self.box_noise:
            return
        ctx = float(self.attrs.get("crop_context", 1.0))
        need = 1 + self.box_noise.scale + 2 * self.box_noise.shift
        if ctx < need:
            raise ValueError(
                f"{self.h5_path}: box noise {self.box_noise} reaches {need:g} times the crop "
                f"box, past the stored context (crop_context {ctx:g}); convert with "
                f"--crop-context {need:g} or more (BSPDataModule uses 1.25 for pose_estimation)")

    def _required(self) -> list:
        names = ["projection_2d", "labels", "targets/frame_idx", "meta/clip_width"]
        names += [f"meta/{k}" for k in _META_STR + _META_INT]
        if self.task == "lifting":
            names.append("targets/" + ("absolute" if self.lifting_target == "absolute"
                                       else "world") + "_pose_loc")
            if self.lifting_target == "camera":
                names.append("meta/camera_transform")
        if self.task == "pose_estimation":
            names += list(MEDIA_DATASETS) + (["frames/mask"] if self.with_mask else [])
            names += list(CONTEXT_DATASETS) if self.box_noise else []
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

    @property
    def time_to_event(self) -> np.ndarray:
        """Frames from each clip's last frame to its event (``meta/tte``), in index order;
        :data:`NO_EVENT` for a clip without one (see :meth:`tte_problem`)."""
        return self._tte[self._rows]

    def tte_problem(self) -> str | None:
        """Why this dataset's clips have no time to event (None: every clip has one)."""
        return tte_problem(self.h5_path, self.has_tte, self.time_to_event, self.attrs)

    def __repr__(self) -> str:
        return (f"ClipDataset({self.h5_path!r}, split={self.split!r}, task={self.task!r}, "
                f"clips={len(self)}, L={self.clip_length}, noise={self.noise}, "
                f"augment={self.augment})")

    # ----------------------------------------------------------------- reading
    def _arrays(self, pos, rows, rng) -> tuple:
        reader = Rows(rows)
        if self.task == "pose_estimation":
            out, channels_last = self._pose_estimation(reader, rows, rng)
        else:
            out, channels_last = self._from_2d(reader, rows, rng), False
        out["label"] = self._labels[rows]
        if self.task == "classification":
            out["targets"] = out["label"]
        meta = {k: self._meta[k][rows] for k in _META_INT}
        meta["tte"] = self._tte[rows]
        meta["frames"] = reader.read(self._dataset("targets/frame_idx"))
        strings = {k: self._meta[k][rows].tolist() for k in _META_STR}
        return out, meta, strings, channels_last

    def _from_2d(self, reader: Rows, rows: np.ndarray, rng) -> dict:
        pixels = reader.read(self._dataset("projection_2d"))
        if self.augment:
            pixels = self._augment(pixels, rng=rng, width=self._width[rows])
        vis = T.visible_joints(pixels)
        if self._deforming:
            inputs, vis = self._deform.apply(pixels, rng, vis)
        else:
            inputs = pixels
        n = T.normalize_hips_neck(inputs, vis)
        out = dict(inputs=n.points, visible=n.visible, shift=n.shift, scale=n.scale,
                   normaliser_fallback=n.fallback)
        if self.with_pixels:
            out["pixels"] = pixels
        if self.task == "autoencoder":
            t = n if not self._deforming else T.normalize_hips_neck(pixels)
            out.update(targets=t.points, target_shift=t.shift, target_scale=t.scale)
        elif self.task == "lifting":
            out.update(self._lifting_targets(reader, rows))
        return out

    def _lifting_targets(self, reader: Rows, rows: np.ndarray) -> dict:
        frame = "absolute" if self.lifting_target == "absolute" else "world"
        metres = reader.read(self._dataset(f"targets/{frame}_pose_loc"))
        if self.lifting_target == "camera":  # x_cam = R_c^T (p - t_c)
            d = metres.astype(np.float64) - self._cam_t[rows][:, None, None, :]
            metres = np.einsum("bij,blki->blkj", self._cam_r[rows], d).astype(np.float32)
        t, shift, scale = T.normalize_hips_neck_3d(metres)
        return dict(targets=t, targets_m=metres, target_shift=shift, target_scale=scale)

    def _pose_estimation(self, reader: Rows, rows, rng) -> tuple:
        frames = reader.read(self._dataset("clip_frames"))
        freader = Rows(frames.reshape(-1))
        rgb = freader.read(self._dataset("frames/rgb"))
        B, L = frames.shape
        S = rgb.shape[1]
        rgb = rgb.reshape((B, L) + rgb.shape[1:])
        box = freader.read(self._dataset("frames/crop_box")).reshape(B, L, 4)
        pixels = reader.read(self._dataset("projection_2d"))
        vis = freader.read(self._dataset("frames/joint_visible")).reshape(B, L, -1) != 0
        mask = (freader.read(self._dataset("frames/mask")).reshape((B, L, S, S))
                if self.with_mask else None)
        if self.box_noise:
            rgb, box = self._noisy_crops(freader, rgb, box, rows, rng)
        out, channels_last = pose_crops(rgb, box, pixels, vis, mask, self, rng)
        if self.with_pixels:
            out["pixels"] = pixels
        return out, channels_last

    def _noisy_crops(self, freader: Rows, rgb, box, rows, rng) -> tuple:
        """``box_noise``: noisy boxes (per clip, from the clip's own stream like every draw)
        and their crops cut from the context crops."""
        B, L = box.shape[:2]
        new = self.box_noise(box, rng)
        moved = np.isfinite(box).all(-1) & (new != box).any(-1)
        if not moved.any():
            return rgb, box
        S = rgb.shape[2]
        ctx = freader.read(self._dataset("frames/context_rgb"))
        cbox = freader.read(self._dataset("frames/context_box")).reshape(B, L, 4)
        rgb = np.array(rgb, copy=True)
        rgb[moved] = I.recrop(ctx.reshape((B, L) + ctx.shape[1:])[moved], cbox[moved],
                              new[moved], S)
        return rgb, np.where(moved[..., None], new, box).astype(np.float32)


def tte_problem(path, has_tte: bool, tte: np.ndarray, attrs: dict) -> str | None:
    """Why the clips of ``path`` (``tte``: their ``meta/tte``) have no time to event, in
    words that say what to do; None when every clip has one."""
    if not has_tte:
        return (f"{path} has no meta/tte: it was written before the time to event was "
                "stored; convert it again (bsp-convert --benchmark, or bsp-interop "
                "import jaad|pie)")
    missing = int((tte < 0).sum())
    if missing == len(tte) and not int(attrs.get("benchmark", 0)):
        return (f"{path} holds no benchmark windows (converted without --benchmark), so "
                "its clips have no event")
    if missing:
        return f"{path}: {missing} of {len(tte)} clips have no time to event (meta/tte < 0)"
    return None


def pose_crops(rgb, box, pixels, vis, mask, ds, rng) -> tuple:
    """Pose-estimation arrays of ``(B, K)`` crops: joints in crop pixels, then ``ds``'s
    augmentation and image dtype. Returns ``(arrays, inputs still channels-last)``."""
    S = rgb.shape[-2]
    size = np.stack([box[..., 2] - box[..., 0], box[..., 3] - box[..., 1]], -1)
    crop = ((pixels - box[..., None, :2]) * (S / size)[..., None, :]).astype(np.float32)
    channels_last = True
    if ds.augment:
        rgb, crop, vis, mask = ds._augment(rgb, crop, vis, mask, rng=rng)
        channels_last = False  # float 0-255, channels first
        if ds.image_dtype == "uint8":
            rgb = np.clip(np.rint(rgb), 0, 255).astype(np.uint8)
        else:
            rgb = I.to_float_images(rgb, False, ds.mean, ds.std)
    elif ds.image_dtype == "float32":
        rgb, channels_last = I.to_float_images(rgb, True, ds.mean, ds.std), False
    # stored channels-last; handed out as a channels-first VIEW (B, L, 3, S, S): a
    # transposing copy of the images would cost more than reading them
    out = dict(inputs=rgb, targets=crop, visible=vis, crop_box=box)
    if mask is not None:
        out["mask"] = mask
    return out, channels_last
