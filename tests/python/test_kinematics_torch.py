"""The torch forward-kinematics layer against the C++ core (bsp_fast.forward_kinematics)."""
import numpy as np
import pytest
import torch

import bsp_fast
from bsp_fast import skeleton as sk
from bsp_fast.models import create
from bsp_fast.models.kinematics import (PROFILES, ForwardKinematics, euler_to_matrix,
                                        matrix_to_rotation_6d, profile_index,
                                        rotation_6d_to_matrix)

torch.set_num_threads(1)


def random_relative(n, seed=0):
    rng = np.random.default_rng(seed)
    rel = np.zeros((n, 26, 6))
    rel[..., :3] = rng.normal(0, 0.3, (n, 26, 3))
    rel[..., 3:] = rng.uniform(-180, 180, (n, 26, 3))
    root = np.concatenate([rng.normal(0, 1, (n, 3)), rng.uniform(-180, 180, (n, 3))], -1)
    return rel, root


def test_euler_to_matrix_is_the_core_convention():
    rel, _ = random_relative(20)
    ours = euler_to_matrix(torch.tensor(rel[..., 3:]))
    np.testing.assert_allclose(ours.numpy(), bsp_fast.rotation_matrix(rel[..., 3:]), atol=1e-12)


def test_fk_equals_the_core_on_random_rotations_float64():
    rel, root = random_relative(64)
    want = bsp_fast.forward_kinematics(rel, root=root)
    fk = ForwardKinematics()
    R = torch.tensor(bsp_fast.rotation_matrix(rel[..., 3:]))
    M = torch.tensor(bsp_fast.rotation_matrix(root[:, 3:]))
    pos, rot = fk(R, torch.tensor(rel[..., :3]), M, torch.tensor(root[:, :3]),
                  return_rotations=True)
    assert pos.dtype == torch.float64
    assert np.abs(pos.numpy() - want[..., :3]).max() < 1e-5
    pos_only = fk(R, torch.tensor(rel[..., :3]), M, torch.tensor(root[:, :3]))
    assert np.abs(pos_only.numpy() - want[..., :3]).max() < 1e-5
    np.testing.assert_allclose(rot.numpy(), bsp_fast.rotation_matrix(want[..., 3:]), atol=1e-9)


def test_fk_poses_last_layout_and_broadcast_offsets():
    rel, root = random_relative(12, seed=1)
    rel = rel.reshape(3, 4, 26, 6)
    rel[..., :3] = rel[:, :1, :, :3]  # one skeleton per clip, broadcast over 4 frames
    want = bsp_fast.forward_kinematics(rel)[..., :3]
    R = torch.tensor(bsp_fast.rotation_matrix(rel[..., 3:]))
    off = torch.tensor(rel[:, :1, :, :3])  # (3, 1, 26, 3)
    fk = ForwardKinematics()
    np.testing.assert_allclose(fk(R, off).numpy(), want, atol=1e-9)
    out = fk(R.permute(2, 3, 4, 0, 1), off.permute(2, 3, 0, 1), poses_last=True)
    assert out.shape == (26, 3, 3, 4)
    np.testing.assert_allclose(out.permute(2, 3, 0, 1).numpy(), want, atol=1e-9)


def test_reference_relative_pose_reproduces_the_absolute_reference():
    rel = sk.reference_pose("sk_female", "relative")
    want = sk.reference_pose("sk_female", "absolute")[:, :3]
    R = torch.tensor(bsp_fast.rotation_matrix(rel[:, 3:]), dtype=torch.float32)
    pos = ForwardKinematics()(R, torch.tensor(rel[:, :3], dtype=torch.float32))
    assert np.abs(pos.numpy() - want).max() < 1e-5


@pytest.mark.parametrize("profile", PROFILES)
def test_zero_relative_rotations_give_the_reference_skeleton(profile):
    """lstm_relative_rot with a zero head (identity rotation changes) outputs the clip's
    reference T-pose (mesh yaw -90), hips-centred and divided by its hips-neck length."""
    model = create("lifting", "lstm_relative_rot").eval()
    with torch.no_grad():
        model.head.weight.zero_()
    rel = sk.reference_pose(profile)
    comp = bsp_fast.forward_kinematics(rel, root=[0, 0, -0.9, 0, -90, 0])[:, :3]
    hn = np.linalg.norm(comp[sk.NECK] - comp[sk.HIPS])
    want = (comp - comp[sk.HIPS]) / hn
    with torch.no_grad():
        out = model(torch.randn(2, 5, 26, 2), age=[profile[0]] * 2, gender=[profile[1]] * 2)
    assert out.shape == (2, 5, 26, 3)
    assert np.abs(out.numpy() - want).max() < 1e-5
    assert abs(hn - {"sk_female": 0.467, "sk_male": 0.467, "sk_girl": 0.284,
                     "sk_kid": 0.320}[sk.model_name(*profile)]) < 0.01


def test_gradients_match_finite_differences():
    rel, root = random_relative(3, seed=2)
    fk = ForwardKinematics()
    R = torch.tensor(bsp_fast.rotation_matrix(rel[..., 3:])).requires_grad_()
    t = torch.tensor(rel[..., :3]).requires_grad_()
    M = torch.tensor(bsp_fast.rotation_matrix(root[:, 3:])).requires_grad_()
    assert torch.autograd.gradcheck(lambda R, t, M: fk(R, t, M), (R, t, M), fast_mode=True)
    # one skeleton for a (2, 3) batch: the offset gradient sums over the broadcast
    R2 = R.detach().repeat(2, 1, 1, 1).view(2, 3, 26, 3, 3).requires_grad_()
    t2 = torch.tensor(rel[0, :, :3]).requires_grad_()
    assert torch.autograd.gradcheck(lambda R, t: fk(R, t), (R2, t2), fast_mode=True)


def test_analytic_backward_equals_autograd_path():
    rel, root = random_relative(8, seed=3)
    fk = ForwardKinematics()
    R = torch.tensor(bsp_fast.rotation_matrix(rel[..., 3:])).requires_grad_()
    t = torch.tensor(rel[..., :3]).requires_grad_()
    g = torch.randn(8, 26, 3, dtype=torch.float64)
    a = torch.autograd.grad((fk(R, t) * g).sum(), (R, t))
    b = torch.autograd.grad((fk(R, t, return_rotations=True)[0] * g).sum(), (R, t))
    for x, y in zip(a, b):
        torch.testing.assert_close(x, y, atol=1e-12, rtol=0)
    # leaf joints (hands, eyes, toe ends) have no rotation gradient
    leaves = [j for j in range(26) if j not in sk.PARENTS]
    assert a[0][:, leaves].abs().max() == 0 and a[0].abs().sum() > 0


def test_rotation_6d():
    d6 = torch.randn(100, 6, dtype=torch.float64)
    R = rotation_6d_to_matrix(d6)
    eye = torch.eye(3, dtype=torch.float64).expand(100, 3, 3)
    torch.testing.assert_close(R @ R.transpose(-1, -2), eye)
    torch.testing.assert_close(torch.linalg.det(R), torch.ones(100, dtype=torch.float64))
    torch.testing.assert_close(rotation_6d_to_matrix(matrix_to_rotation_6d(R)), R)
    torch.testing.assert_close(rotation_6d_to_matrix(torch.tensor([1.0, 0, 0, 0, 1, 0])),
                               torch.eye(3))
    # any axis: (6, N) -> (3, 3, N)
    torch.testing.assert_close(rotation_6d_to_matrix(d6.t(), dim=0).permute(2, 0, 1), R)
    with pytest.raises(ValueError, match="6 values"):
        rotation_6d_to_matrix(torch.zeros(4, 5))


def test_fk_under_bf16_autocast_stays_float32():
    rel, _ = random_relative(4, seed=4)
    R = torch.tensor(bsp_fast.rotation_matrix(rel[..., 3:]), dtype=torch.float32)
    t = torch.tensor(rel[..., :3], dtype=torch.float32)
    fk = ForwardKinematics()
    with torch.autocast("cpu", dtype=torch.bfloat16):
        out = fk(R, t)
    assert out.dtype == torch.float32
    torch.testing.assert_close(out, fk(R, t))


def test_bad_inputs_raise():
    fk = ForwardKinematics()
    with pytest.raises(ValueError, match="rotations"):
        fk(torch.zeros(2, 25, 3, 3), torch.zeros(2, 25, 3))
    with pytest.raises(ValueError, match="must come before"):
        ForwardKinematics([1, -1])
    with pytest.raises(ValueError, match="allowed ages"):
        profile_index(["adult"], ["robot"])
    assert profile_index(["child", "adult"], ["male", "female"]).tolist() == [3, 0]


def test_reference_hips_neck_matches_the_skeleton_module():
    from bsp_fast.models.kinematics import ReferenceSkeletons

    ref = ReferenceSkeletons()
    for i, (age, gender) in enumerate(PROFILES):
        assert abs(ref.hips_neck[i].item() - sk.hips_neck_length(age, gender)) < 1e-6


def test_direct_parameterisation_is_the_original_s():
    """parameterisation="direct" (the original's, an ablation): the 6D output is the
    relative rotation itself. A head forced to identity 6D then gives every bone the
    identity rotation relative to its parent (FK of the bare offsets), not the T-pose; the
    head keeps PyTorch's default initialisation; an unknown value is refused."""
    profile = ("adult", "female")
    model = create("lifting", "lstm_relative_rot", parameterisation="direct").eval()
    assert not torch.allclose(model.head.bias[:6], torch.tensor([1.0, 0, 0, 0, 1, 0]))
    with torch.no_grad():
        model.head.weight.zero_()
        model.head.bias.copy_(torch.tensor([1.0, 0, 0, 0, 1, 0]).repeat(26))
    rel = np.array(sk.reference_pose(profile), float)
    rel[:, 3:] = 0.0  # identity relative rotations, the reference bone offsets
    comp = bsp_fast.forward_kinematics(rel, root=[0, 0, -0.9, 0, -90, 0])[:, :3]
    ref = bsp_fast.forward_kinematics(sk.reference_pose(profile),
                                      root=[0, 0, -0.9, 0, -90, 0])[:, :3]
    hn = np.linalg.norm(ref[sk.NECK] - ref[sk.HIPS])  # the model divides by the reference's
    want = (comp - comp[sk.HIPS]) / hn
    with torch.no_grad():
        out = model(torch.randn(1, 3, 26, 2), age=[profile[0]], gender=[profile[1]])
    assert np.abs(out.numpy() - want).max() < 1e-5
    assert np.abs(want - (ref - ref[sk.HIPS]) / hn).max() > 0.1  # not the T-pose
    with pytest.raises(ValueError, match="parameterisation must be one of"):
        create("lifting", "lstm_relative_rot", parameterisation="euler")
