"""3D helpers: hips-neck denormalisation, CARLA camera intrinsics, CARLA <-> OpenCV axes."""
import numpy as np
import pytest
import torch

import bsp_fast as bf
from bsp_fast.data import (
    ClipDataset,
    camera_intrinsics,
    carla_to_opencv,
    denormalize_hips_neck_3d,
    focal_length,
    normalize_hips_neck_3d,
    opencv_to_carla,
)
from bsp_fast.data.testing import write_clip_file


@pytest.fixture(scope="module")
def h5file(tmp_path_factory):
    path = tmp_path_factory.mktemp("camera") / "clips.h5"
    write_clip_file(path, clips=(8, 8, 8), clip_length=4)
    return path


def test_intrinsics_and_axes_reproduce_the_projection(h5file):
    K = camera_intrinsics(1600, 600, 90)
    np.testing.assert_allclose(K, [[800, 0, 800], [0, 800, 300], [0, 0, 1]], atol=1e-9)
    assert focal_length(640, 60) == pytest.approx(320 / np.tan(np.radians(30)))
    b = ClipDataset(h5file, "val", "lifting", lifting_target="camera", with_pixels=True)[:8]
    cam = b["targets_m"].numpy().astype(np.float64)  # CARLA camera frame, metres
    cv = carla_to_opencv(cam)
    assert (cv[..., 2] > 0).all()  # OpenCV z is the depth
    uvw = cv @ K.T
    np.testing.assert_allclose(uvw[..., :2] / uvw[..., 2:], b["pixels"].numpy(), atol=1e-2)
    np.testing.assert_allclose(opencv_to_carla(cv), cam, atol=1e-12)
    # the same as bsp_fast.project on world points with the camera at the origin
    world = np.array([[5.0, 1.0, -0.5], [12.0, -2.0, 1.0]])
    uv = bf.project(world, np.zeros(6), 1600, 600, fov=90)
    p = carla_to_opencv(world) @ K.T
    np.testing.assert_allclose(p[:, :2] / p[:, 2:], uv, atol=1e-9)
    t = carla_to_opencv(torch.tensor(world))
    assert isinstance(t, torch.Tensor) and torch.equal(opencv_to_carla(t), torch.tensor(world))
    with pytest.raises(ValueError, match="fov must lie"):
        camera_intrinsics(1600, 600, 180)
    with pytest.raises(ValueError, match=r"\(\.\.\., 3\)"):
        carla_to_opencv(np.zeros((4, 2)))


def test_denormalize_hips_neck_3d_inverts_the_normalisation(h5file):
    b = ClipDataset(h5file, "val", "lifting")[[0, 3]]
    back = denormalize_hips_neck_3d(b["targets"], b["target_shift"], b["target_scale"])
    assert isinstance(back, torch.Tensor)
    np.testing.assert_allclose(back.numpy(), b["targets_m"].numpy(), atol=1e-5)
    pts = np.random.default_rng(0).normal(size=(3, 5, 26, 3)).astype(np.float32)
    n, shift, scale = normalize_hips_neck_3d(pts)
    np.testing.assert_allclose(denormalize_hips_neck_3d(n, shift, scale), pts, atol=1e-5)
    # the reference skeleton's length instead of the ground truth's: a scaled copy
    half = denormalize_hips_neck_3d(n, shift, scale / 2)
    np.testing.assert_allclose(half - shift[..., None, :], (pts - shift[..., None, :]) / 2,
                               atol=1e-5)
    with pytest.raises(ValueError, match="shift must have shape"):
        denormalize_hips_neck_3d(n, shift[0], scale)
