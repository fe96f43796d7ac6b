"""A procedural walking gait on the CARLA skeleton (relative pose per frame).

Bones keep their T-pose translations (fixed lengths) and are rotated about BODY axes of
the mesh space (x = body left, y = forward, z = up; docs/synth.md, "Poses"). Each bone j
gets a global delta D_j, so its posed component rotation is G_j = D_j G0_j and its
relative rotation rel_j = G_parent^T G_j (a bone whose delta equals its parent's keeps its
T-pose relative rotation). The hips joint is then shifted vertically each frame so the
lowest contact point (heels, toes) stays on the ground.

Cadence and stride follow the speed through the Froude number: step length
l = 1.25 L (v / sqrt(g L))^0.6 with L the hip height, cadence = v / l steps per second.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import skeleton as sk
from ..geometry import forward_kinematics, rotation_matrix, rotation_to_euler

J = sk.JOINT_INDEX
# Standing height (m) of each reference model (docs/dataset-format.md,
# "4. The 26-joint skeleton") and the walker capsule half-height h derived from it (0.92 m
# for the adults).
BODY_HEIGHT = {"sk_female": 1.69, "sk_male": 1.69, "sk_girl": 1.02, "sk_kid": 1.13}
ADULT_H = 0.92


def capsule_half_height(stem: str) -> float:
    return ADULT_H * BODY_HEIGHT[stem] / BODY_HEIGHT["sk_female"]


def mesh_offset_transform(stem: str) -> np.ndarray:
    """M = (0, 0, -h, 0, -90, 0): the mesh in the walker actor's frame."""
    return np.array([0.0, 0.0, -capsule_half_height(stem), 0.0, -90.0, 0.0])


def rx(a):
    a = np.radians(a)
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([o, z, z], -1), np.stack([z, c, -s], -1),
                     np.stack([z, s, c], -1)], -2)


def ry(a):
    a = np.radians(a)
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([c, z, s], -1), np.stack([z, o, z], -1),
                     np.stack([-s, z, c], -1)], -2)


def rz(a):
    a = np.radians(a)
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1),
                     np.stack([z, z, o], -1)], -2)


def _bump(phi, centre, kappa):
    """Periodic bump (von Mises shape) peaking at 1 at phase `centre` (fraction of cycle)."""
    return np.exp(kappa * (np.cos(phi - 2 * np.pi * centre) - 1.0))


@dataclass
class GaitStyle:
    """Per-clip variation of the gait (amplitudes as multipliers or degrees)."""

    hip_scale: float = 1.0
    knee_scale: float = 1.0
    cadence_scale: float = 1.0
    lean: float = 4.0
    pelvis_yaw: float = 4.0
    arm_swing: float = 20.0
    arm_down: float = 80.0
    elbow: float = 15.0
    phase: float = 0.0

    @staticmethod
    def sample(rng: np.random.Generator) -> "GaitStyle":
        return GaitStyle(hip_scale=rng.normal(1.0, 0.08), knee_scale=rng.normal(1.0, 0.1),
                         cadence_scale=rng.normal(1.0, 0.05), lean=rng.uniform(1.5, 7.0),
                         pelvis_yaw=rng.uniform(2.0, 6.0), arm_swing=rng.uniform(12.0, 30.0),
                         arm_down=rng.uniform(76.0, 85.0), elbow=rng.uniform(8.0, 25.0),
                         phase=rng.uniform(0, 2 * np.pi))


def reference(stem: str, scale: float = 1.0):
    """T-pose relative (26, 6), component (26, 6) and component rotations (26, 3, 3).
    ``scale`` multiplies every bone offset (joints 1..25; the root stays at the actor's
    origin): a walker whose bones are that much longer than the reference skeleton's."""
    rel0 = np.array(sk.reference_pose(stem), float)
    if scale != 1.0:
        rel0[1:, :3] *= scale
    comp0 = forward_kinematics(rel0)
    return rel0, comp0, rotation_matrix(comp0[:, 3:])


def cadence(speed: float, hip_height: float) -> tuple:
    """(step length m, steps per second) for a walking speed (Froude scaling)."""
    v = max(float(speed), 0.2)
    step = 1.25 * hip_height * (v / np.sqrt(9.81 * hip_height)) ** 0.6
    return step, v / step


def gait_deltas(stem: str, speed: float, frames: int, fps: float,
                style: GaitStyle, scale: float = 1.0) -> np.ndarray:
    """Global body-axis deltas D (frames, 26, 3, 3) for a constant-speed walk."""
    _, comp0, _ = reference(stem, scale)
    hip_h = comp0[J["crl_thigh__R"], 2]
    step, steps_per_s = cadence(speed, hip_h)
    t = np.arange(frames) / fps
    phi = style.phase + np.pi * steps_per_s * style.cadence_scale * t  # cycle = 2 steps
    theta = np.degrees(np.arcsin(np.clip(step / (2 * hip_h), 0, 0.9)))
    slow = min(1.0, 0.55 + 0.45 * speed / 1.4)
    D = np.broadcast_to(np.eye(3), (frames, 26, 3, 3)).copy()
    pelvis = -style.pelvis_yaw * np.cos(phi)
    D[:, J["crl_hips__C"]] = rz(pelvis)
    D[:, J["crl_spine__C"]] = rz(-0.3 * pelvis) @ rx(-0.5 * style.lean)
    spine01 = rz(-0.8 * pelvis) @ rx(-style.lean)
    for name in ("crl_spine01__C", "crl_shoulder__L", "crl_shoulder__R"):
        D[:, J[name]] = spine01
    for name in ("crl_neck__C", "crl_Head__C", "crl_eye__L", "crl_eye__R"):
        D[:, J[name]] = rx(-0.2 * style.lean + 1.5 * np.cos(2 * phi))
    for side, ph in (("R", phi), ("L", phi + np.pi)):
        hip = 0.85 * theta * style.hip_scale * np.cos(ph) + 0.25 * theta
        knee = style.knee_scale * slow * (15 * _bump(ph, 0.12, 12) + 58 * _bump(ph, 0.70, 6)) + 3
        foot = 12 * _bump(ph, 0.0, 25) - 30 * slow * _bump(ph, 0.6, 14) + 8 * _bump(ph, 0.85, 8)
        toe = foot + 25 * slow * _bump(ph, 0.58, 14)
        D[:, J[f"crl_thigh__{side}"]] = rz(pelvis) @ rx(hip)
        D[:, J[f"crl_leg__{side}"]] = rz(pelvis) @ rx(hip - knee)
        D[:, J[f"crl_foot__{side}"]] = rz(0.5 * pelvis) @ rx(foot)
        D[:, J[f"crl_toe__{side}"]] = rz(0.5 * pelvis) @ rx(toe)
        D[:, J[f"crl_toeEnd__{side}"]] = D[:, J[f"crl_toe__{side}"]]
        swing = -style.arm_swing * np.sqrt(slow) * np.cos(ph)  # opposite to the same-side leg
        down = ry(style.arm_down if side == "L" else -style.arm_down)
        elbow = style.elbow + 12 * np.clip(swing / max(style.arm_swing, 1e-6), 0, 1)
        D[:, J[f"crl_arm__{side}"]] = rz(-0.8 * pelvis) @ rx(swing) @ down
        fore = rz(-0.8 * pelvis) @ rx(swing + elbow) @ down
        D[:, J[f"crl_foreArm__{side}"]] = fore
        D[:, J[f"crl_hand__{side}"]] = fore
    return D


def pose_from_deltas(stem: str, D: np.ndarray, scale: float = 1.0) -> np.ndarray:
    """Relative poses (frames, 26, 6) from global deltas, feet kept on the ground
    (``scale``: bone lengths relative to the reference skeleton's)."""
    rel0, comp0, G0 = reference(stem, scale)
    G = D @ G0
    parents = np.array(sk.PARENTS)
    rel_R = np.empty_like(G)
    rel_R[:, 0] = G[:, 0]
    rel_R[:, 1:] = np.swapaxes(G[:, parents[1:]], -1, -2) @ G[:, 1:]
    rel = np.broadcast_to(rel0, D.shape[:1] + rel0.shape).copy()
    rel[:, :, 3:] = rotation_to_euler(rel_R)
    return ground_feet(stem, rel, scale)


def _contact_z(stem: str, comp: np.ndarray, scale: float = 1.0) -> np.ndarray:
    """Lowest contact point per frame: toes, toe tips and a heel point under each ankle."""
    R = rotation_matrix(comp[..., 3:])
    _, comp0, G0 = reference(stem, scale)
    zs = [comp[:, J[n], 2] for n in ("crl_toe__R", "crl_toe__L", "crl_toeEnd__R",
                                      "crl_toeEnd__L")]
    for side in ("R", "L"):
        j = J[f"crl_foot__{side}"]
        heel0 = np.array([0.0, -0.6, -1.0]) * comp0[j, 2]  # behind and below the ankle
        local = G0[j].T @ heel0  # fixed in the foot bone's frame
        zs.append(comp[:, j, 2] + (R[:, j] @ local)[:, 2])
    return np.min(np.stack(zs, -1), axis=-1)


def ground_feet(stem: str, rel: np.ndarray, scale: float = 1.0) -> np.ndarray:
    """Shifts the hips (relative translation of joint 1) so the lowest contact point sits
    at its T-pose height in every frame."""
    rel0, comp0, _ = reference(stem, scale)
    target = _contact_z(stem, comp0[None], scale)[0]
    comp = forward_kinematics(rel)
    dz = target - _contact_z(stem, comp, scale)
    R_root = rotation_matrix(rel0[0, 3:])
    hips_mesh = R_root @ rel0[1, :3] + rel0[0, :3]
    shifted = hips_mesh[None, :] + dz[:, None] * np.array([0.0, 0.0, 1.0])
    out = rel.copy()
    out[:, 1, :3] = (shifted - rel0[0, :3]) @ R_root  # R_root^T (p - t_root), row form
    return out


def walk(stem: str, speed: float, frames: int, fps: float, style: GaitStyle,
         scale: float = 1.0) -> np.ndarray:
    """Relative poses (frames, 26, 6) of a walk at `speed` m/s (``scale``: bone lengths
    relative to the reference skeleton's)."""
    return pose_from_deltas(stem, gait_deltas(stem, speed, frames, fps, style, scale), scale)
