"""Batched, differentiable forward kinematics in torch (CARLA convention).

A bone j has a rotation ``R[j]`` and an offset ``t[j]`` relative to its parent; in
component space ``A[j] = A[parent[j]] ∘ (t[j], R[j])`` with ``(Ra, ta) ∘ (Rb, tb) =
(Ra Rb, Ra tb + ta)`` and ``A[0] = root ∘ (t[0], R[0])``: exactly
:func:`bsp_fast.forward_kinematics` of the C++ core, on rotation matrices.

Speed: joints are processed one tree *level* at a time (8 levels for the 26-joint CARLA
skeleton instead of 26 joints) on a "poses-last" layout ``(J, 3, 3, *batch)``: every 3x3
product is 27 multiply-adds over long contiguous vectors of poses rather than thousands of
tiny matrix products, and a level's joints are one contiguous slice. Models that produce
their rotations in that layout (``lstm_relative_rot`` computes its head as ``W @ h.T``)
skip the layout change entirely (``poses_last=True``).
"""
from __future__ import annotations

import functools

import numpy as np
import torch
from torch import nn

from .. import skeleton as _sk

__all__ = [
    "ForwardKinematics", "ReferenceSkeletons", "rotation_6d_to_matrix", "matrix_to_rotation_6d",
    "euler_to_matrix", "matmul3", "PROFILES", "profile_index", "MESH_YAW",
]

#: Reference skeleton profiles (age, gender) in the order of :class:`ReferenceSkeletons`.
PROFILES = (("adult", "female"), ("adult", "male"), ("child", "female"), ("child", "male"))
_PROFILE_INDEX = {p: i for i, p in enumerate(PROFILES)}
#: Yaw (degrees) of the mesh-in-actor transform of CARLA-BSP's component space.
MESH_YAW = -90.0


def euler_to_matrix(pyr: torch.Tensor) -> torch.Tensor:
    """``(..., 3)`` [pitch, yaw, roll] in DEGREES -> ``(..., 3, 3)``, CARLA's
    ``Rz(yaw) Ry(-pitch) Rx(-roll)`` (as :func:`bsp_fast.rotation_matrix`)."""
    p, y, r = torch.deg2rad(pyr).unbind(-1)
    cp, sp, cy, sy, cr, sr = p.cos(), p.sin(), y.cos(), y.sin(), r.cos(), r.sin()
    return torch.stack([
        torch.stack([cp * cy, cy * sp * sr - sy * cr, -cy * sp * cr - sy * sr], -1),
        torch.stack([cp * sy, sy * sp * sr + cy * cr, -sy * sp * cr + cy * sr], -1),
        torch.stack([sp, -cp * sr, cp * cr], -1)], -2)


def rotation_6d_to_matrix(d6: torch.Tensor, dim: int = -1) -> torch.Tensor:
    """6D rotations -> matrices by Gram-Schmidt (Zhou et al. 2019).

    The 6 values along ``dim`` are two 3-vectors ``a1, a2``; the matrix rows are
    ``b1 = a1/|a1|``, ``b2`` = the unit part of ``a2`` orthogonal to ``b1`` and
    ``b3 = b1 x b2``, so ``[1, 0, 0, 0, 1, 0]`` is the identity. The rows axis replaces
    ``dim`` and the columns axis follows it: ``(..., 6) -> (..., 3, 3)``, or in the
    poses-last layout ``(J, 6, N) -> (J, 3, 3, N)`` with ``dim=1``. Computed in float32 or
    wider (also under autocast).
    """
    dim = dim % d6.ndim
    if d6.shape[dim] != 6:
        raise ValueError(f"rotation_6d_to_matrix: expected 6 values along dim {dim}, "
                         f"got shape {tuple(d6.shape)}")
    if d6.dtype not in (torch.float32, torch.float64):
        d6 = d6.float()
    # component-wise on the unbound axis: long contiguous vectors in the poses-last layout
    # (torch's norm/cross over a short non-innermost axis are ~10x slower)
    x0, x1, x2, y0, y1, y2 = d6.unbind(dim)
    n1 = torch.rsqrt(x0 * x0 + x1 * x1 + x2 * x2 + 1e-12)
    b10, b11, b12 = x0 * n1, x1 * n1, x2 * n1
    dot = b10 * y0 + b11 * y1 + b12 * y2
    u0, u1, u2 = y0 - dot * b10, y1 - dot * b11, y2 - dot * b12
    n2 = torch.rsqrt(u0 * u0 + u1 * u1 + u2 * u2 + 1e-12)
    b20, b21, b22 = u0 * n2, u1 * n2, u2 * n2
    b30, b31, b32 = b11 * b22 - b12 * b21, b12 * b20 - b10 * b22, b10 * b21 - b11 * b20
    R = torch.stack([b10, b11, b12, b20, b21, b22, b30, b31, b32], dim)
    return R.unflatten(dim, (3, 3))


def matrix_to_rotation_6d(R: torch.Tensor) -> torch.Tensor:
    """Inverse of :func:`rotation_6d_to_matrix` on rotation matrices: the first two rows."""
    return R[..., :2, :].reshape(R.shape[:-2] + (6,))


def matmul3(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """``a @ b`` for 3x3 blocks in the poses-last layout ``(k, 3, 3, *N)`` (broadcast)."""
    return _mm(None, a, b)


def _mm(out, a, b, ta: bool = False, tb: bool = False):
    """``out = op(a) @ op(b)`` for 3x3 blocks in the poses-last layout ``(k, 3, 3, *N)``
    (broadcast), ``op`` = transpose where asked: one multiply and two fused
    multiply-adds over long vectors (a reduction over the short axis is several times
    slower, and tiny batched matrix products slower still)."""
    for m in range(3):
        am = (a[:, m] if ta else a[:, :, m]).unsqueeze(2)  # column m of op(a): (k, 3, 1, *N)
        bm = (b[:, :, m] if tb else b[:, m]).unsqueeze(1)  # row m of op(b): (k, 1, 3, *N)
        if m == 0 and out is None:
            out = am * bm
        elif m == 0 and torch.broadcast_shapes(am.shape, bm.shape) == out.shape:
            torch.mul(am, bm, out=out)
        else:
            if m == 0:  # a product smaller than `out` (broadcast batch): accumulate
                out.zero_()
            out.addcmul_(am, bm)
    return out


def _mv(out, a, v, ta: bool = False):
    """``out = op(a) @ v``: ``a (k, 3, 3, *N)``, ``v (k, 3, *N)`` -> ``out (k, 3, *N)``."""
    for m in range(3):
        am = a[:, m] if ta else a[:, :, m]  # column m of op(a): (k, 3, *N)
        vm = v[:, m].unsqueeze(1)  # (k, 1, *N)
        if m == 0 and out is None:
            out = am * vm
        elif m == 0 and torch.broadcast_shapes(am.shape, vm.shape) == out.shape:
            torch.mul(am, vm, out=out)
        else:
            if m == 0:  # a product smaller than `out` (broadcast batch): accumulate
                out.zero_()
            out.addcmul_(am, vm)
    return out


def _sum_to(grad: torch.Tensor, shape) -> torch.Tensor:
    """Sums a broadcast gradient back to ``shape``."""
    if tuple(grad.shape) == tuple(shape):
        return grad
    dims = [i for i, (g, s) in enumerate(zip(grad.shape, shape)) if s == 1 and g != 1]
    return grad.sum(dims, keepdim=True)


class _Level:
    """One tree level: its joints (joint order), where they sit in the level-ordered
    buffers, their parents (level-ordered indices; ``single`` when they share one)."""

    def __init__(self, joints, start, parents, single, needs_rot):
        self.joints = torch.tensor(joints, dtype=torch.long)
        lo, hi = joints[0], joints[-1] + 1
        self.slice = slice(lo, hi) if list(joints) == list(range(lo, hi)) else None
        self.start, self.stop = start, start + len(joints)
        self.parents = torch.tensor(parents, dtype=torch.long)
        self.single, self.needs_rot = single, needs_rot

    def take(self, x: torch.Tensor) -> torch.Tensor:
        """The rows of this level's joints (a view when they are contiguous)."""
        return x[self.slice] if self.slice is not None else x.index_select(0, self.joints)

    def to(self, device):
        self.joints, self.parents = self.joints.to(device), self.parents.to(device)
        return self


class _FKFunction(torch.autograd.Function):
    """Level-by-level FK with an analytic backward: one reverse sweep over the levels
    instead of an autograd graph of ~150 small ops and their zero-filled buffers.

    Poses-last layout, joint order: ``R (J, 3, 3, *NR)``, ``t (J, 3, *Nt)``, ``M (1, 3, 3,
    *NM)`` or None -> positions ``(J, 3, *N)`` (N = the broadcast batch).
    """

    @staticmethod
    def forward(ctx, R, t, M, levels, inverse):
        J = R.shape[0]
        batch = torch.broadcast_shapes(R.shape[3:], t.shape[2:],
                                       M.shape[3:] if M is not None else ())
        AR = R.new_empty((J, 3, 3) + batch)  # absolute rotations, level order
        At = R.new_empty((J, 3) + batch)  # absolute positions, level order
        root = levels[0]
        a, b = root.start, root.stop
        if M is None:
            AR[a:b].copy_(root.take(R).expand((b - a, 3, 3) + batch))
            At[a:b].copy_(root.take(t).expand((b - a, 3) + batch))
        else:
            _mm(AR[a:b], M, root.take(R))
            _mv(At[a:b], M, root.take(t))
        for lv in levels[1:]:
            a, b, s = lv.start, lv.stop, lv.single
            Rp = AR[s:s + 1] if s is not None else AR.index_select(0, lv.parents)
            tp = At[s:s + 1] if s is not None else At.index_select(0, lv.parents)
            _mv(At[a:b], Rp, lv.take(t))
            At[a:b] += tp
            if lv.needs_rot:
                _mm(AR[a:b], Rp, lv.take(R))
        ctx.save_for_backward(R, t, M, AR)
        ctx.levels, ctx.inverse = levels, inverse
        return At.index_select(0, inverse)

    @staticmethod
    def backward(ctx, grad):
        R, t, M, AR = ctx.saved_tensors
        levels, order = ctx.levels, torch.argsort(ctx.inverse)
        need_R, need_t, need_M = ctx.needs_input_grad[:3]
        # total gradients w.r.t. absolute positions / rotations, level order, children first
        gAt = grad.index_select(0, order)
        gAR = torch.zeros_like(AR[: levels[-1].start])  # the last level has no children
        dR = torch.zeros_like(AR) if need_R else None  # joint order
        dt = torch.empty_like(gAt) if need_t else None
        for lv in reversed(levels[1:]):
            a, b = lv.start, lv.stop
            Rp = AR.index_select(0, lv.parents)
            Gt = gAt[a:b]
            if need_t:
                dt[lv.joints] = _mv(None, Rp, Gt, ta=True)
            contrib = Gt.unsqueeze(2) * lv.take(t).unsqueeze(1)  # Gt t^T
            if lv.needs_rot:  # a level of leaves only has no rotation gradient
                GR = gAR[a:b]
                if need_R:
                    dR[lv.joints] = _mm(None, Rp, GR, ta=True)
                contrib.add_(_mm(None, GR, lv.take(R), tb=True))
            gAR.index_add_(0, lv.parents, contrib)
            gAt.index_add_(0, lv.parents, Gt.clone())
        root = levels[0]
        a, b = root.start, root.stop
        dM = None
        if M is None:
            if need_R:
                dR[root.joints] = gAR[a:b]
            if need_t:
                dt[root.joints] = gAt[a:b]
        else:
            if need_R:
                dR[root.joints] = _mm(None, M, gAR[a:b], ta=True)
            if need_t:
                dt[root.joints] = _mv(None, M, gAt[a:b], ta=True)
            if need_M:
                dM = _mm(None, gAR[a:b], root.take(R), tb=True)
                dM = _sum_to(dM + gAt[a:b].unsqueeze(2) * root.take(t).unsqueeze(1), M.shape)
        return (_sum_to(dR, R.shape) if need_R else None,
                _sum_to(dt, t.shape) if need_t else None, dM, None, None)


def _cat(parts: list) -> torch.Tensor:
    """Concatenates along dim 0 after broadcasting the other dims to a common shape."""
    tail = torch.broadcast_shapes(*(x.shape[1:] for x in parts))
    return torch.cat([x.expand((x.shape[0],) + tail) for x in parts], 0)


def _tree_levels(parents) -> list:
    """Joints by depth (root level first, joint order inside a level)."""
    depth = []
    for j, p in enumerate(parents):
        if p >= j:
            raise ValueError(f"parents: parent {p} of joint {j} must come before it")
        depth.append(0 if p < 0 else depth[p] + 1)
    levels = [[j for j, d in enumerate(depth) if d == k] for k in range(max(depth) + 1)]
    if len(levels[0]) != 1:
        raise ValueError("parents: expected exactly one root (parent -1)")
    return levels


class ForwardKinematics(nn.Module):
    """Joint positions (optionally rotations) in component space.

    ``forward(rotations, offsets, root_rotation=None, root_translation=None, *,
    return_rotations=False, poses_last=False)``:

    * default layout: ``rotations (..., J, 3, 3)``, ``offsets (..., J, 3)`` (broadcast
      against each other, e.g. one skeleton per clip as ``(B, 1, J, 3)``),
      ``root_rotation (..., 3, 3)``, ``root_translation (..., 3)`` -> positions
      ``(..., J, 3)`` (and rotations ``(..., J, 3, 3)``);
    * ``poses_last=True``: ``rotations (J, 3, 3, *N)``, ``offsets (J, 3, *N)``,
      ``root_rotation (3, 3, *N)``, ``root_translation (3, *N)`` -> ``(J, 3, *N)``, with no
      layout change (the fast path for models).

    ``parents`` (default: the 26-joint CARLA skeleton) must list parents before children.
    Differentiable (positions through an analytic backward, rotations through autograd),
    float32 or float64; autocast is turned off inside (chains of bf16 products would lose
    millimetres).
    """

    def __init__(self, parents=None):
        super().__init__()
        parents = tuple(int(p) for p in (_sk.PARENTS if parents is None else parents))
        self.parents, self.num_joints = parents, len(parents)
        has_children = {p for p in parents if p >= 0}
        where, start, self._levels = {}, 0, []
        for joints in _tree_levels(parents):
            ps = [where[parents[j]] for j in joints if parents[j] >= 0]
            single = ps[0] if ps and len(set(ps)) == 1 else None
            self._levels.append(_Level(joints, start, ps, single,
                                       any(j in has_children for j in joints)))
            for j in joints:
                where[j] = start
                start += 1
        order = [j for lv in self._levels for j in lv.joints.tolist()]
        self.register_buffer("_inverse", torch.tensor(np.argsort(order)), persistent=False)

    def _apply(self, fn, *args, **kwargs):  # keep the level index tensors on our device
        out = super()._apply(fn, *args, **kwargs)
        device = self._inverse.device
        self._levels = [lv.to(device) for lv in self._levels]
        return out

    def forward(self, rotations, offsets, root_rotation=None, root_translation=None, *,
                return_rotations: bool = False, poses_last: bool = False):
        J = self.num_joints
        if poses_last:
            ok = rotations.shape[:3] == (J, 3, 3) and offsets.shape[:2] == (J, 3)
            want = f"rotations (J={J}, 3, 3, *N) and offsets ({J}, 3, *N)"
        else:
            ok = rotations.shape[-3:] == (J, 3, 3) and offsets.shape[-2:] == (J, 3)
            want = f"rotations (..., J={J}, 3, 3) and offsets (..., {J}, 3)"
        if not ok:
            raise ValueError(f"ForwardKinematics: expected {want}, got "
                             f"{tuple(rotations.shape)} and {tuple(offsets.shape)}")
        with torch.autocast(rotations.device.type, enabled=False):
            if poses_last:
                return self._fk(rotations, offsets, root_rotation, root_translation,
                                return_rotations)
            return self._fk_poses_first(rotations, offsets, root_rotation, root_translation,
                                        return_rotations)

    def _fk_poses_first(self, rotations, offsets, root_rotation, root_translation, with_rot):
        batch = torch.broadcast_shapes(rotations.shape[:-3], offsets.shape[:-2])
        n = len(batch)

        def poses_last(x, k):  # (..., *tail) -> (*tail, ...) with n batch dims
            if x is None:
                return None
            x = torch.as_tensor(x)
            x = x.reshape((1,) * (n + k - x.ndim) + tuple(x.shape))
            return x.permute(*range(n, n + k), *range(n))

        R = poses_last(rotations.reshape(rotations.shape[:-2] + (9,)), 2)
        R = R.reshape((self.num_joints, 3, 3) + R.shape[2:])
        out = self._fk(R, poses_last(offsets, 2), poses_last(root_rotation, 2),
                       poses_last(root_translation, 1), with_rot)
        back = lambda x, k: x.permute(*range(k, k + n), *range(k))  # noqa: E731
        return (back(out[0], 2), back(out[1], 3)) if with_rot else back(out, 2)

    def _fk(self, R, t, root_rotation, root_translation, with_rot):
        dtype = torch.promote_types(R.dtype, torch.float32)
        R, t = R.to(dtype), t.to(dtype)
        M = None if root_rotation is None else root_rotation.to(dtype).unsqueeze(0)
        if with_rot:
            pos, rot = self._fk_autograd(R, t, M)
        else:
            pos = _FKFunction.apply(R, t, M, self._levels, self._inverse)
        if root_translation is not None:
            pos = pos + root_translation.to(dtype).unsqueeze(0)
        return (pos, rot) if with_rot else pos

    def _fk_autograd(self, R, t, M):
        """Positions and rotations with plain autograd ops (joint order in and out)."""
        root = self._levels[0]
        Ra, ta = root.take(R), root.take(t)
        if M is not None:
            Ra, ta = _mm(None, M, Ra), _mv(None, M, ta)
        rots, locs = [Ra], [ta]
        for lv in self._levels[1:]:
            Rp = _cat(rots).index_select(0, lv.parents)
            tp = _cat(locs).index_select(0, lv.parents)
            locs.append(tp + _mv(None, Rp, lv.take(t)))
            rots.append(_mm(None, Rp, lv.take(R)))
        return (_cat(locs).index_select(0, self._inverse),
                _cat(rots).index_select(0, self._inverse))


def profile_index(age, gender) -> torch.Tensor:
    """Ages and genders (lists, or one string each) -> ``(B,)`` indices into
    :data:`PROFILES`; unknown values raise ValueError listing the allowed ones."""
    age = [age] if isinstance(age, str) else list(age)
    gender = [gender] if isinstance(gender, str) else list(gender)
    if len(age) != len(gender):
        raise ValueError(f"age and gender: got {len(age)} and {len(gender)} values")
    out = []
    for a, g in zip(age, gender):
        i = _PROFILE_INDEX.get((a, g))
        if i is None:
            raise ValueError(f"unknown profile ({a!r}, {g!r}); allowed ages {list(_sk.AGES)}, "
                             f"genders {list(_sk.GENDERS)}")
        out.append(i)
    return torch.tensor(out, dtype=torch.long)


@functools.lru_cache(maxsize=None)
def _reference_arrays():
    from .. import geometry

    rel = np.stack([_sk.reference_pose(p) for p in PROFILES])  # (4, J, 6)
    absolute = geometry.forward_kinematics(rel)
    hn = np.linalg.norm(absolute[:, _sk.NECK, :3] - absolute[:, _sk.HIPS, :3], axis=-1)
    return rel[..., :3], geometry.rotation_matrix(rel[..., 3:]), absolute[..., :3], hn


class ReferenceSkeletons(nn.Module):
    """The four reference T-poses as (non-persistent) buffers, in :data:`PROFILES` order:
    ``offsets (4, J, 3)`` (m) and ``rotations (4, J, 3, 3)`` relative to the parent,
    ``positions (4, J, 3)`` after FK with an identity root, ``hips_neck (4,)`` (m)."""

    def __init__(self):
        super().__init__()
        off, rot, pos, hn = _reference_arrays()
        for name, a in (("offsets", off), ("rotations", rot), ("positions", pos),
                        ("hips_neck", hn)):
            self.register_buffer(name, torch.tensor(a, dtype=torch.float32), persistent=False)
