"""Rigid transforms, forward kinematics and camera projection (CARLA convention).

Transforms are ``(..., 6)`` arrays ``[x, y, z, pitch, yaw, roll]`` in metres and degrees;
a transform maps p to R p + t with R = Rz(yaw) Ry(-pitch) Rx(-roll) (docs/dataset-format.md,
"5. Geometry conventions").
Every function accepts any leading batch dimensions (NumPy broadcasting between operands),
computes in float64 in the C++ core with the GIL released, and returns float64 arrays.
"""
from __future__ import annotations

import math

import numpy as np

from ._native import core as _core

__all__ = [
    "rotation_matrix", "rotation_to_euler", "compose", "invert", "transform_points",
    "forward_kinematics", "mesh_offset", "to_world", "project", "in_frame",
]


def _real(x, name: str, tail: tuple, expected: str, min_ndim: int | None = None) -> np.ndarray:
    """float64 C-contiguous array whose last dims equal `tail` (-1 = any), else ValueError."""
    a = np.asarray(x)
    if a.dtype.kind not in "fiu":
        raise TypeError(f"{name}: expected a real-valued numeric array, got dtype {a.dtype}")
    need = len(tail) if min_ndim is None else min_ndim
    ok = a.ndim >= need and all(t < 0 or a.shape[a.ndim - len(tail) + i] == t
                                for i, t in enumerate(tail))
    if not ok:
        raise ValueError(f"{name}: expected shape {expected}, got {tuple(a.shape)}")
    return np.ascontiguousarray(a, dtype=np.float64)


def _repeat_view(x: np.ndarray, ntail: int, batch: tuple):
    """(flat, k): x read at i // k serves output i of the flattened `batch`.

    Works without a copy when x's batch dims are a prefix of `batch` followed by ones
    (the common case: one camera or walker transform per frame); otherwise copies.
    """
    xb = x.shape[: x.ndim - ntail]
    xb = (1,) * (len(batch) - len(xb)) + xb
    m = len(batch)
    while m > 0 and xb[m - 1] == 1:
        m -= 1
    tail = x.shape[x.ndim - ntail:]
    if xb[:m] == batch[:m]:
        return x.reshape((-1,) + tail), math.prod(batch[m:])
    full = np.ascontiguousarray(np.broadcast_to(x.reshape(xb + tail), batch + tail))
    return full.reshape((-1,) + tail), 1


def _batch(a: np.ndarray, ntail: int, b: np.ndarray, mtail: int, what: str) -> tuple:
    try:
        return tuple(np.broadcast_shapes(a.shape[: a.ndim - ntail], b.shape[: b.ndim - mtail]))
    except ValueError:
        raise ValueError(f"{what}: batch shapes {a.shape[: a.ndim - ntail]} and "
                         f"{b.shape[: b.ndim - mtail]} do not broadcast") from None


def rotation_matrix(pyr) -> np.ndarray:
    """``(..., 3)`` [pitch, yaw, roll] in degrees -> ``(..., 3, 3)`` rotation matrices."""
    return _core.rotation_matrix(_real(pyr, "pyr", (3,), "(..., 3)"))


def rotation_to_euler(R) -> np.ndarray:
    """``(..., 3, 3)`` rotation matrices -> ``(..., 3)`` [pitch, yaw, roll] in degrees.

    Round-trips rotation_matrix to ~1e-9 deg away from gimbal lock (|pitch| = 90), where
    roll is set to 0 and yaw carries the rest.
    """
    return _core.rotation_to_euler(_real(R, "R", (3, 3), "(..., 3, 3)"))


def compose(a, b) -> np.ndarray:
    """``a ∘ b`` (apply b, then a): R = Ra Rb, t = Ra tb + ta. ``(..., 6)`` each."""
    a = _real(a, "a", (6,), "(..., 6)")
    b = _real(b, "b", (6,), "(..., 6)")
    batch = _batch(a, 1, b, 1, "compose")
    af, ka = _repeat_view(a, 1, batch)
    bf, kb = _repeat_view(b, 1, batch)
    return _core.compose_flat(af, ka, bf, kb, math.prod(batch)).reshape(batch + (6,))


def invert(t) -> np.ndarray:
    """Inverse transforms, ``(..., 6)``."""
    return _core.invert(_real(t, "t", (6,), "(..., 6)"))


def transform_points(t, p) -> np.ndarray:
    """Applies ``(..., 6)`` transforms to ``(..., 3)`` points (batch dims broadcast)."""
    t = _real(t, "t", (6,), "(..., 6)")
    p = _real(p, "p", (3,), "(..., 3)")
    batch = _batch(t, 1, p, 1, "transform_points")
    tf, kt = _repeat_view(t, 1, batch)
    pf, kp = _repeat_view(p, 1, batch)
    return _core.transform_points_flat(tf, kt, pf, kp, math.prod(batch)).reshape(batch + (3,))


def forward_kinematics(relative, root=None, parents=None) -> np.ndarray:
    """Parent-relative bone transforms ``(..., J, 6)`` -> component-space ``(..., J, 6)``.

    ``A[0] = root ∘ relative[0]`` (identity root if None), ``A[j] = A[parents[j]] ∘
    relative[j]``. ``root`` is ``(..., 6)``, broadcast over the batch dims of
    ``relative``. ``parents`` defaults to the 26-joint CARLA skeleton; any tree whose
    parents come before their children works.
    """
    par = np.asarray(_core.PARENTS if parents is None else parents)
    if par.ndim != 1 or par.dtype.kind not in "iu":
        raise ValueError(f"parents: expected a 1-D integer sequence, got {par!r}")
    par = np.ascontiguousarray(par, dtype=np.int32)
    J = len(par)
    rel = _real(relative, "relative", (J, 6), f"(..., {J}, 6)")
    if root is None:
        return _core.forward_kinematics(rel, None, 1, par)
    root = _real(root, "root", (6,), "(..., 6)")
    batch = _batch(rel, 2, root, 1, "forward_kinematics")
    if batch != rel.shape[:-2]:
        rel = np.ascontiguousarray(np.broadcast_to(rel, batch + (J, 6)))
    rf, kr = _repeat_view(root, 1, batch)
    return _core.forward_kinematics(rel, rf, kr, par)


def mesh_offset(relative, component) -> np.ndarray:
    """The mesh-in-actor transform M per frame: ``component[0] ∘ relative[0]⁻¹``.

    ``relative`` and ``component`` are ``(..., J, 6)``; returns ``(..., 6)``. In CARLA-BSP
    ``component = M ∘ FK(relative)`` with M = (0, 0, -h, 0, -90, 0).
    """
    rel = _real(relative, "relative", (-1, 6), "(..., J, 6)", min_ndim=2)
    comp = _real(component, "component", (-1, 6), "(..., J, 6)", min_ndim=2)
    return compose(comp[..., 0, :], invert(rel[..., 0, :]))


def to_world(component, walker_transform) -> np.ndarray:
    """World bone transforms ``walker ∘ component``: ``(..., J, 6)`` and ``(..., 6)``."""
    comp = _real(component, "component", (-1, 6), "(..., J, 6)", min_ndim=2)
    walker = _real(walker_transform, "walker_transform", (6,), "(..., 6)")
    return compose(walker[..., None, :], comp)


def project(points, camera_transform, width, height, fov=90.0) -> np.ndarray:
    """World points ``(..., J, 3)`` -> pixels ``(..., J, 2)`` through a CARLA camera.

    ``camera_transform`` is ``(..., 6)`` (one per pose, broadcast over J). Horizontal field
    of view ``fov`` in degrees; f = W / (2 tan(fov/2)); u = W/2 + f y/x, v = H/2 - f z/x
    in camera coordinates (x forward). Points behind the camera give NaN.
    """
    pts = _real(points, "points", (-1, 3), "(..., J, 3)", min_ndim=2)
    cam = _real(camera_transform, "camera_transform", (6,), "(..., 6)")
    for name, v in (("width", width), ("height", height), ("fov", fov)):
        if not np.isscalar(v) or not np.isfinite(v) or v <= 0:
            raise ValueError(f"{name}: expected a positive number, got {v!r}")
    if fov >= 180:
        raise ValueError(f"fov: expected 0 < fov < 180 degrees, got {fov!r}")
    cam = cam[..., None, :]
    batch = _batch(pts, 1, cam, 1, "project")
    if batch != pts.shape[:-1]:
        pts = np.ascontiguousarray(np.broadcast_to(pts, batch + (3,)))
    cf, kc = _repeat_view(cam, 1, batch)
    return _core.project_flat(pts, cf, kc, float(width), float(height), float(fov))


def in_frame(uv, width, height) -> np.ndarray:
    """The recorder's loose ``in_frame`` flag of ``(..., J, 2)`` pixel poses -> ``(...)``.

    True when all joints are finite and any u >= 0, any v >= 0, any u <= W, any v <= H
    (four independent tests, docs/dataset-format.md, "5. Geometry conventions"). It is a
    weak "partly visible" flag.
    """
    return _core.in_frame(_real(uv, "uv", (-1, 2), "(..., J, 2)", min_ndim=2),
                          float(width), float(height))
