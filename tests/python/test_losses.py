"""bsp_fast.losses on hand-worked values, masks, gradients and bad input."""
import pytest
import torch

from bsp_fast.losses import loc_2d, loc_3d
from bsp_fast.skeleton import HIPS, NECK

J = 26


def test_loc_2d_hand_values_and_mask():
    target = torch.zeros(1, 2, J, 2)
    pred = torch.zeros(1, 2, J, 2)
    pred[0, 0, 3] = torch.tensor([1.0, 2.0])  # squared error 5 on a present joint
    pred[0, 1, 7] = torch.tensor([10.0, 0.0])  # 100 on an absent joint
    pred[0, 1, HIPS] = torch.tensor([0.0, 3.0])  # 9 on the hips, absent but always kept
    assert loc_2d(pred, target).item() == pytest.approx((5 + 100 + 9) / (2 * J * 2))
    present = torch.zeros(1, 2, J, dtype=torch.bool)
    present[0, 0, 3] = True
    # kept coordinates: joint 3 of frame 0 and the hips of both frames -> 3 joints, 6 values
    assert loc_2d(pred, target, present).item() == pytest.approx((5 + 9) / 6)


def test_loc_2d_masked_entries_carry_no_gradient_even_nan():
    pred = torch.zeros(2, J, 2, requires_grad=True)
    target = torch.ones(2, J, 2)
    target[0, 5] = float("nan")
    present = torch.ones(2, J, dtype=torch.bool)
    present[0, 5] = False
    loss = loc_2d(pred, target, present)
    loss.backward()
    assert loss.item() == pytest.approx(1.0)
    assert torch.isfinite(pred.grad).all() and (pred.grad[0, 5] == 0).all()
    assert pred.grad[1, 0, 0].item() == pytest.approx(-2 / (2 * J * 2 - 2))


def test_loc_3d_normalised_and_plain():
    torch.manual_seed(0)
    target = torch.randn(3, 4, J, 3) * 0.3
    target[..., HIPS, :] = torch.tensor([1.0, 2.0, 3.0])
    target[..., NECK, :] = torch.tensor([1.0, 2.0, 3.5])  # hips-neck 0.5 m
    pred = target + 0.05
    # metres in: every coordinate is off by 0.05 m = 0.1 hips-neck units -> 0.01
    assert loc_3d(pred, target).item() == pytest.approx(0.01, rel=1e-5)
    assert loc_3d(pred, target, normalise=False).item() == pytest.approx(0.0025, rel=1e-5)
    # already normalised targets: the normalisation is the identity
    tn = (target - target[..., HIPS:HIPS + 1, :]) / 0.5
    pn = tn + 0.2
    assert loc_3d(pn, tn).item() == pytest.approx(loc_3d(pn, tn, normalise=False).item())
    p = pred.clone().requires_grad_(True)
    loc_3d(p, target).backward()
    assert torch.isfinite(p.grad).all()


@pytest.mark.parametrize("call, expected", [
    (lambda: loc_2d(torch.zeros(2, J, 2), torch.zeros(2, J, 3)), r"\(\.\.\., J, 2\)"),
    (lambda: loc_2d(torch.zeros(2, J, 2), torch.zeros(2, J, 2), torch.ones(2, 3, dtype=bool)),
     r"\(2, 26\)"),
    (lambda: loc_3d(torch.zeros(2, J, 2), torch.zeros(2, J, 2)), r"\(\.\.\., J, 3\)"),
    (lambda: loc_3d(torch.zeros(0, J, 3), torch.zeros(0, J, 3)), "non-empty"),
    (lambda: loc_3d(torch.zeros(1, J, 3), torch.zeros(1, J, 3), normalise="yes"), "True or False"),
])
def test_bad_input(call, expected):
    with pytest.raises(ValueError, match=expected):
        call()


def test_pose_loss_gives_finite_gradients_over_frames_without_a_crop():
    # a frame with no pedestrian pixel has no crop and NaN targets (crop_box "mask");
    # masked by `visible`, it must reach neither the loss nor the gradient
    import torch

    from bsp_fast.models.base import masked_mse

    pred = torch.zeros(1, 2, 26, 2, requires_grad=True)
    target = torch.ones(1, 2, 26, 2)
    target[0, 1] = float("nan")  # frame 1: no crop
    visible = torch.ones(1, 2, 26, dtype=torch.bool)
    visible[0, 1] = False
    loss = masked_mse(pred, target, visible)
    loss.backward()
    assert float(loss) == 1.0  # (1^2 + 1^2) / 2 per coordinate on the kept joints
    assert torch.isfinite(pred.grad).all()
    assert torch.all(pred.grad[0, 1] == 0) and torch.all(pred.grad[0, 0] != 0)
    # a "visible" joint whose target is NaN all the same is left out too
    visible[0, 1, 3] = True
    pred.grad = None
    loss = masked_mse(pred, target, visible)
    loss.backward()
    assert float(loss) == 1.0 and torch.isfinite(pred.grad).all()
