"""bsp-interop export videopose3d against VideoPose3D's own loading steps.

VideoPose3D (facebookresearch/VideoPose3D) is not installed here; the parts of it that
read our files are re-implemented below from its code: ``common/skeleton.py`` (Skeleton,
remove_joints), ``common/mocap_dataset.py``, ``common/h36m_dataset.py`` (h36m_skeleton),
``common/custom_dataset.py`` (CustomDataset), ``common/camera.py``
(normalize_screen_coordinates, world_to_camera through quaternions) and the data-loading
part of ``run.py`` (``-d custom -k NAME``: the dataset, 3D preparation, keypoints,
normalisation by w/h, ``fetch`` over subjects and actions). The dataset class of
docs/interop.md (``BSPDataset``) is taken from the docs and run on top of them."""
import re
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from bsp_fast.data.testing import write_clip_file
from bsp_fast.interop import export_videopose3d
from bsp_fast.interop.cli import main
from bsp_fast.skeleton import joint_set

DOCS = Path(__file__).resolve().parents[2] / "docs" / "interop.md"

_COMMON = {
    "__init__.py": "",
    "skeleton.py": '''
import numpy as np

class Skeleton:
    def __init__(self, parents, joints_left, joints_right):
        assert len(joints_left) == len(joints_right)
        self._parents = np.array(parents)
        self._joints_left = joints_left
        self._joints_right = joints_right

    def num_joints(self):
        return len(self._parents)

    def parents(self):
        return self._parents

    def remove_joints(self, joints_to_remove):
        valid_joints = [j for j in range(len(self._parents)) if j not in joints_to_remove]
        for i in range(len(self._parents)):
            while self._parents[i] in joints_to_remove:
                self._parents[i] = self._parents[self._parents[i]]
        index_offsets = np.zeros(len(self._parents), dtype=int)
        new_parents = []
        for i, parent in enumerate(self._parents):
            if i not in joints_to_remove:
                new_parents.append(parent - index_offsets[parent])
            else:
                index_offsets[i:] += 1
        self._parents = np.array(new_parents)
        self._joints_left = [j - index_offsets[j] for j in self._joints_left if j in valid_joints]
        self._joints_right = [j - index_offsets[j] for j in self._joints_right if j in valid_joints]
        return valid_joints

    def joints_left(self):
        return self._joints_left

    def joints_right(self):
        return self._joints_right
''',
    "mocap_dataset.py": '''
class MocapDataset:
    def __init__(self, fps, skeleton):
        self._skeleton = skeleton
        self._fps = fps
        self._data = None
        self._cameras = None

    def remove_joints(self, joints_to_remove):
        kept_joints = self._skeleton.remove_joints(joints_to_remove)
        for subject in self._data.keys():
            for action in self._data[subject].keys():
                s = self._data[subject][action]
                if 'positions' in s:
                    s['positions'] = s['positions'][:, kept_joints]

    def __getitem__(self, key):
        return self._data[key]

    def subjects(self):
        return self._data.keys()

    def skeleton(self):
        return self._skeleton

    def cameras(self):
        return self._cameras

    def supports_semi_supervised(self):
        return False
''',
    "h36m_dataset.py": '''
from common.skeleton import Skeleton
h36m_skeleton = Skeleton(parents=[-1,  0,  1,  2,  3,  4,  0,  6,  7,  8,  9,  0, 11, 12, 13, 14, 12,
       16, 17, 18, 19, 20, 19, 22, 12, 24, 25, 26, 27, 28, 27, 30],
       joints_left=[6, 7, 8, 9, 10, 16, 17, 18, 19, 20, 21, 22, 23],
       joints_right=[1, 2, 3, 4, 5, 24, 25, 26, 27, 28, 29, 30, 31])
''',
    "camera.py": '''
import numpy as np

def normalize_screen_coordinates(X, w, h):
    assert X.shape[-1] == 2
    return X/w*2 - [1, h/w]

def qrot(q, v):
    qvec = q[..., 1:]
    uv = np.cross(qvec, v)
    uuv = np.cross(qvec, uv)
    return v + 2 * (q[..., :1] * uv + uuv)

def qinverse(q):
    return q * np.array([1, -1, -1, -1])

def world_to_camera(X, R, t):
    Rt = qinverse(np.asarray(R, dtype=np.float64))
    return qrot(np.tile(Rt, (*X.shape[:-1], 1)), X - t)
''',
    "custom_dataset.py": '''
import numpy as np
from common.mocap_dataset import MocapDataset
from common.h36m_dataset import h36m_skeleton

custom_camera_params = {
    'id': None, 'res_w': None, 'res_h': None, 'azimuth': 70,
    'orientation': [0.1407056450843811, -0.1500701755285263, -0.755240797996521, 0.6223280429840088],
    'translation': [1841.1070556640625, 4955.28466796875, 1563.4454345703125],
}

class CustomDataset(MocapDataset):
    def __init__(self, detections_path, remove_static_joints=True):
        super().__init__(fps=None, skeleton=h36m_skeleton)
        data = np.load(detections_path, allow_pickle=True)
        resolutions = data['metadata'].item()['video_metadata']
        self._cameras = {}
        self._data = {}
        for video_name, res in resolutions.items():
            cam = {}
            cam.update(custom_camera_params)
            cam['orientation'] = np.array(cam['orientation'], dtype='float32')
            cam['translation'] = np.array(cam['translation'], dtype='float32')
            cam['translation'] = cam['translation']/1000
            cam['id'] = video_name
            cam['res_w'] = res['w']
            cam['res_h'] = res['h']
            self._cameras[video_name] = [cam]
            self._data[video_name] = {'custom': {'cameras': cam}}
        if remove_static_joints:
            self.remove_joints([4, 5, 9, 10, 11, 16, 20, 21, 22, 23, 24, 28, 29, 30, 31])
            self._skeleton._parents[11] = 8
            self._skeleton._parents[14] = 8
''',
}


def docs_dataset_class() -> str:
    """The ``common/bsp_dataset.py`` code block of docs/interop.md."""
    text = DOCS.read_text(encoding="utf-8")
    m = re.search(r"```python\n(# VideoPose3D/common/bsp_dataset\.py\n.*?)```", text, re.S)
    assert m, "docs/interop.md lost its BSPDataset code block"
    return m.group(1)


@pytest.fixture
def vp3d(tmp_path, monkeypatch):
    """A folder with VideoPose3D's ``common`` package (re-implemented) and the docs'
    ``common/bsp_dataset.py``, importable; ``data/`` for the npz files."""
    root = tmp_path / "VideoPose3D"
    (root / "common").mkdir(parents=True)
    (root / "data").mkdir()
    for name, code in _COMMON.items():
        (root / "common" / name).write_text(textwrap.dedent(code))
    (root / "common" / "bsp_dataset.py").write_text(docs_dataset_class())
    monkeypatch.syspath_prepend(str(root))
    for mod in [m for m in sys.modules if m == "common" or m.startswith("common.")]:
        monkeypatch.delitem(sys.modules, mod)
    return root


def run_py_loading(root: Path, dataset_name: str, keypoints_name: str, subjects_train: str,
                   subjects_test: str, with_3d: bool):
    """run.py's data loading for ``-d custom -k NAME`` (with the docs' one-line change
    when ``with_3d``): returns (dataset, keypoints, kps_left, kps_right, fetch)."""
    import importlib

    camera = importlib.import_module("common.camera")
    path_2d = str(root / "data" / f"data_2d_{dataset_name}_{keypoints_name}.npz")
    if with_3d:
        BSPDataset = importlib.import_module("common.bsp_dataset").BSPDataset
        dataset = BSPDataset(path_2d,
                             str(root / "data" / f"data_3d_{dataset_name}_{keypoints_name}.npz"))
    else:
        CustomDataset = importlib.import_module("common.custom_dataset").CustomDataset
        dataset = CustomDataset(path_2d)
    for subject in dataset.subjects():
        for action in dataset[subject].keys():
            anim = dataset[subject][action]
            if 'positions' in anim:
                positions_3d = []
                for cam in anim['cameras']:
                    pos_3d = camera.world_to_camera(anim['positions'], R=cam['orientation'],
                                                    t=cam['translation'])
                    pos_3d[:, 1:] -= pos_3d[:, :1]
                    positions_3d.append(pos_3d)
                anim['positions_3d'] = positions_3d
    keypoints = np.load(path_2d, allow_pickle=True)
    keypoints_metadata = keypoints['metadata'].item()
    keypoints_symmetry = keypoints_metadata['keypoints_symmetry']
    kps_left, kps_right = list(keypoints_symmetry[0]), list(keypoints_symmetry[1])
    keypoints = keypoints['positions_2d'].item()
    for subject in dataset.subjects():
        assert subject in keypoints, f'Subject {subject} is missing from the 2D detections'
        for action in dataset[subject].keys():
            assert action in keypoints[subject]
            if 'positions_3d' not in dataset[subject][action]:
                continue
            for cam_idx in range(len(keypoints[subject][action])):
                mocap_length = dataset[subject][action]['positions_3d'][cam_idx].shape[0]
                assert keypoints[subject][action][cam_idx].shape[0] >= mocap_length
            assert len(keypoints[subject][action]) == len(dataset[subject][action]['positions_3d'])
    for subject in keypoints.keys():
        for action in keypoints[subject]:
            for cam_idx, kps in enumerate(keypoints[subject][action]):
                cam = dataset.cameras()[subject][cam_idx]
                kps[..., :2] = camera.normalize_screen_coordinates(kps[..., :2], w=cam['res_w'],
                                                                   h=cam['res_h'])
                keypoints[subject][action][cam_idx] = kps

    def fetch(subjects):
        out_poses_3d, out_poses_2d = [], []
        for subject in subjects:
            for action in keypoints[subject].keys():
                poses_2d = keypoints[subject][action]
                out_poses_2d.extend(poses_2d)
                if subject in dataset.cameras():
                    assert len(dataset.cameras()[subject]) == len(poses_2d)
                if 'positions_3d' in dataset[subject][action]:
                    poses_3d = dataset[subject][action]['positions_3d']
                    assert len(poses_3d) == len(poses_2d), 'Camera count mismatch'
                    out_poses_3d.extend(poses_3d)
        return out_poses_3d or None, out_poses_2d

    return dataset, keypoints, kps_left, kps_right, fetch, subjects_train.split(','), \
        subjects_test.split(',')


@pytest.fixture
def clips(tmp_path):
    path = tmp_path / "clips.h5"
    write_clip_file(path, clips=(8, 4, 4), clip_length=8)
    return path


@pytest.mark.parametrize("joints,layout", [("coco17", "coco"), ("h36m17", "h36m")])
def test_run_py_custom_loads_the_export_with_3d(vp3d, clips, joints, layout):
    out2, out3 = vp3d / "data" / "data_2d_custom_bsp.npz", vp3d / "data" / "data_3d_custom_bsp.npz"
    assert main(["export", "videopose3d", str(clips), str(out2), "--out-3d", str(out3),
                 "--joints", joints, "--quiet"]) == 0
    meta = np.load(out2, allow_pickle=True)["metadata"].item()
    assert meta["layout_name"] == layout and meta["num_joints"] == 17
    js = joint_set(joints)
    assert meta["keypoints_symmetry"] == [list(js.left), list(js.right)]
    if layout == "coco":  # VideoPose3D's data/data_utils.py coco_metadata
        assert meta["keypoints_symmetry"] == [[1, 3, 5, 7, 9, 11, 13, 15],
                                              [2, 4, 6, 8, 10, 12, 14, 16]]
    else:  # h36m_metadata
        assert meta["keypoints_symmetry"] == [[4, 5, 6, 11, 12, 13], [1, 2, 3, 14, 15, 16]]
    train, test = ",".join(meta["subjects"]["train"]), ",".join(meta["subjects"]["test"])
    dataset, keypoints, kl, kr, fetch, s_train, s_test = run_py_loading(
        vp3d, "custom", "bsp", train, test, with_3d=True)
    assert set(dataset.subjects()) == set(meta["video_metadata"]) == set(keypoints)
    for subject in dataset.subjects():
        assert list(dataset[subject]) == ["custom"]  # one subject per video/track, action custom
    poses_3d, poses_2d = fetch(s_train)
    assert poses_3d is not None and len(poses_3d) == len(poses_2d) == len(s_train)
    for p2, p3 in zip(poses_2d, poses_3d):
        assert p2.shape[1:] == (17, 2) and p3.shape[1:] == (17, 3) and len(p2) == len(p3)
        assert np.isfinite(p2).all() and np.isfinite(p3).all()  # no NaN anywhere
        assert np.abs(p2).max() < 2  # normalised by w/h
        assert np.allclose(p3[:, 1:] + p3[:, :1], p3[:, 1:] + p3[:, :1])
    assert dataset.skeleton().num_joints() == 17
    # flipping by the symmetry swaps left and right joint names (run.py's augmentation)
    names = np.array(js.joints)
    flipped = names.copy()
    flipped[kl + kr] = names[kr + kl]
    swap = {"left": "right", "right": "left"}
    assert [re.sub(r"left|right", lambda m: swap[m.group()], n) for n in names] == list(flipped)


def test_3d_is_the_camera_frame_of_the_clip_file(vp3d, clips):
    out2, out3 = vp3d / "data" / "data_2d_custom_g.npz", vp3d / "data" / "data_3d_custom_g.npz"
    r = export_videopose3d(clips, out2, out3, joints="h36m17")
    assert r["dropped"] == [] and r["filled_joints"] == {
        "spine": "0.5*pelvis + 0.5*thorax", "head": "2*neck_nose + -1*thorax"}
    d2 = np.load(out2, allow_pickle=True)
    pos2d, meta = d2["positions_2d"].item(), d2["metadata"].item()
    pos3d = np.load(out3, allow_pickle=True)["positions_3d"].item()
    from bsp_fast.data import camera_intrinsics
    import h5py

    with h5py.File(clips, "r") as f:
        fov = float(f.attrs["fov"])
    for subject, (w_h) in meta["video_metadata"].items():
        uv, xyz = pos2d[subject]["custom"][0], pos3d[subject]["custom"].astype(np.float64)
        assert uv.dtype == np.float32 and len(uv) == len(xyz)
        K = camera_intrinsics(w_h["w"], w_h["h"], fov)
        proj = xyz @ K.T
        proj = proj[..., :2] / proj[..., 2:]
        direct = [0, 1, 2, 3, 4, 5, 6, 8, 9, 11, 12, 13, 14, 15, 16]  # not spine, head
        np.testing.assert_allclose(proj[:, direct], uv[:, direct], atol=2e-2)
        src = meta["source"][subject]
        assert src["end_frame"] - src["start_frame"] == len(uv)


def test_missing_joints_are_interpolated_and_never_seen_runs_left_out(tmp_path):
    import h5py

    path = tmp_path / "c.h5"
    write_clip_file(path, clips=(4, 2, 2), clip_length=8)
    with h5py.File(path, "r+") as f:
        uv = f["train/projection_2d"][()]
        uv[0, 2:4, 7] = 0  # left hand missing in two frames of one clip: interpolated
        vids = f["train/meta/video_id"].asstr()[()]
        victim = vids[1] if vids[1] != vids[0] else None
        if victim is not None:  # right hand never seen in a whole track: left out
            uv[vids == victim, :, 15] = 0
        f["train/projection_2d"][...] = uv
    r = export_videopose3d(path, tmp_path / "o.npz")
    assert r["interpolated"] == 2
    d = np.load(tmp_path / "o.npz", allow_pickle=True)["positions_2d"].item()
    assert all(np.isfinite(v["custom"][0]).all() for v in d.values())
    if victim is not None:
        assert len(r["dropped"]) == 1 and "right_wrist" in r["dropped"][0]


def test_out_3d_of_an_imported_file_is_one_clear_error(tmp_path, capsys):
    import h5py

    path = tmp_path / "c.h5"
    write_clip_file(path, clips=(4, 2, 2), clip_length=8)
    with h5py.File(path, "r+") as f:
        for s in ("train", "val", "test"):
            del f[s]["targets/world_pose_loc"]
    rc = main(["export", "videopose3d", str(path), str(tmp_path / "a.npz"),
               "--out-3d", str(tmp_path / "b.npz")])
    err = capsys.readouterr().err.replace(str(tmp_path), "TMP")
    assert rc == 1 and "leave out --out-3d" in err and "out_3d" not in err
    assert len(err.strip().splitlines()) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.h5"]
    assert main(["export", "videopose3d", str(path), str(tmp_path / "a.npz"), "--quiet"]) == 0
