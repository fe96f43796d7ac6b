"""LSTM models: the crossing classifier, absolute-location lifting and relative-rotation
lifting through forward kinematics."""
from __future__ import annotations

import functools

import torch
from torch import nn

from .. import skeleton as _sk
from .base import ClassificationModel, LiftingModel, check_int
from .kinematics import (MESH_YAW, ForwardKinematics, ReferenceSkeletons, euler_to_matrix,
                         matmul3, profile_index, rotation_6d_to_matrix)
from .registry import register

__all__ = ["LSTMClassifier", "LSTMLifting", "LSTMRelativeRot"]

J = _sk.NUM_JOINTS


class _LSTMBody(nn.Module):
    """``LSTM(J * channels -> hidden, layers, batch_first)`` over flattened frames."""

    def __init__(self, in_channels: int, hidden_size: int, num_layers: int):
        super().__init__()
        check_int("hidden_size", hidden_size)
        check_int("num_layers", num_layers)
        self.lstm = nn.LSTM(J * in_channels, hidden_size, num_layers, batch_first=True)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = x.flatten(2)
        if x.device.type == "cpu" and torch.is_autocast_enabled("cpu") and not cpu_bf16():
            # oneDNN has no bf16 LSTM without CPU bf16 support ("could not create a
            # primitive descriptor"): run this layer in float32 there
            with torch.autocast("cpu", enabled=False):
                return self.lstm(x.float())[0]
        return self.lstm(x)[0]  # (B, L, hidden)


@functools.lru_cache(maxsize=None)
def cpu_bf16() -> bool:
    """Whether oneDNN runs bf16 kernels on this CPU (AVX512-BF16 / AMX)."""
    try:
        return bool(torch.ops.mkldnn._is_mkldnn_bf16_supported())
    except (AttributeError, RuntimeError):
        return False


@register("classification", "lstm",
          "LSTM(52 -> 64, 2 layers) over the clip, Linear(64 -> 2) on the last step")
class LSTMClassifier(ClassificationModel):
    """The report's LSTM crossing classifier. (The original's dropout calls discarded
    their result, so there is no dropout.)"""

    def __init__(self, *, hidden_size: int = 64, num_layers: int = 2, use_visible: bool = False):
        super().__init__(locals())
        self._init_visible(use_visible)
        self.body = _LSTMBody(self.in_channels, hidden_size, num_layers)
        self.head = nn.Linear(hidden_size, 2)

    def compute(self, inputs, visible):
        h = self.body(self.pose_features(inputs, visible))
        return self.head(h[:, -1])


@register("lifting", "lstm",
          "LSTM(52 -> 64, 2 layers), Linear(64 -> 78) per frame: absolute 3D locations")
class LSTMLifting(LiftingModel):
    """The report's LSTM ``absolute_loc`` lifting model."""

    def __init__(self, *, hidden_size: int = 64, num_layers: int = 2, use_visible: bool = False):
        super().__init__(locals())
        self._init_visible(use_visible)
        self.body = _LSTMBody(self.in_channels, hidden_size, num_layers)
        self.head = nn.Linear(hidden_size, J * 3)

    def compute(self, inputs, visible):
        h = self.body(self.pose_features(inputs, visible))
        return self.head(h).unflatten(-1, (J, 3))


@register("lifting", "lstm_relative_rot",
          "LSTM(52 -> 64, 2 layers) -> a 6D rotation per joint -> forward kinematics of "
          "the clip's reference skeleton")
class LSTMRelativeRot(LiftingModel):
    """The report's LSTM ``relative_rot`` model.

    Per frame, ``Linear(64 -> 26 * 6)`` gives one 6D rotation per joint (Gram-Schmidt to a
    matrix ``C``); each bone's rotation relative to its parent is the reference T-pose's
    ``R_ref @ C`` (so the identity, the head's initial bias, reproduces the T-pose), and
    forward kinematics with the fixed bone offsets of the clip's (age, gender) reference
    skeleton and the mesh rotation (yaw -90 degrees) gives the joints in component space.
    Output: ``(p - p_hips) / hips_neck_ref`` with the reference skeleton's hips-neck length,
    so de-normalising with that length recovers the FK positions (metres, hips at 0).
    Needs ``age`` and ``gender`` (lists of strings, one per clip) as context;
    :meth:`forward_batch` takes them from ``batch["meta"]``. Leaf joints (hands, eyes, toe
    ends) have rotations that move no joint, as in the original.

    ``parameterisation="direct"`` is the original's (an ablation): the 6D output is the
    relative rotation itself (``R = C``) and the head keeps PyTorch's default
    initialisation, so training does not start at the reference T-pose.
    """

    context_keys = ("age", "gender")
    PARAMETERISATIONS = ("reference", "direct")

    def __init__(self, *, hidden_size: int = 64, num_layers: int = 2, use_visible: bool = False,
                 parameterisation: str = "reference"):
        if parameterisation not in self.PARAMETERISATIONS:
            raise ValueError(f"parameterisation must be one of {self.PARAMETERISATIONS}, "
                             f"got {parameterisation!r}")
        super().__init__(locals())
        self._init_visible(use_visible)
        self.direct = parameterisation == "direct"
        self.body = _LSTMBody(self.in_channels, hidden_size, num_layers)
        self.head = nn.Linear(hidden_size, J * 6)
        if not self.direct:  # start at the T-pose: C = identity for every joint
            with torch.no_grad():
                self.head.bias.copy_(torch.tensor([1.0, 0, 0, 0, 1, 0]).repeat(J))
        self.fk = ForwardKinematics()
        self.skeletons = ReferenceSkeletons()
        mesh = euler_to_matrix(torch.tensor([0.0, MESH_YAW, 0.0], dtype=torch.float64))
        self.register_buffer("mesh_rotation", mesh.float(), persistent=False)

    def compute(self, inputs, visible, age=None, gender=None):
        if age is None or gender is None:
            raise ValueError("lstm_relative_rot needs age and gender (one per clip) for the "
                             "reference skeleton; forward_batch takes them from batch['meta']")
        B, L = inputs.shape[:2]
        profile = profile_index(age, gender).to(inputs.device)
        if len(profile) != B:
            raise ValueError(f"age/gender: expected {B} values (one per clip), got {len(profile)}")
        h = self.body(self.pose_features(inputs, visible))  # (B, L, H)
        # the head straight into the poses-last layout (J, 6, B, L): W @ h^T + b
        y = torch.addmm(self.head.bias.unsqueeze(1), self.head.weight, h.reshape(B * L, -1).t())
        C = rotation_6d_to_matrix(y.view(J, 6, B, L), dim=1)  # (J, 3, 3, B, L), float32
        sk = self.skeletons
        if self.direct:
            R = C
        else:
            R = matmul3(sk.rotations[profile].permute(1, 2, 3, 0).unsqueeze(-1), C)
        offsets = sk.offsets[profile].permute(1, 2, 0).unsqueeze(-1)  # (J, 3, B, 1)
        pos = self.fk(R, offsets, self.mesh_rotation.view(3, 3, 1, 1), poses_last=True)
        pos = (pos - pos[_sk.HIPS:_sk.HIPS + 1]) / sk.hips_neck[profile].view(1, 1, B, 1)
        return pos.permute(2, 3, 0, 1)  # (B, L, J, 3) view
