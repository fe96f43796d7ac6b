"""bsp-synth --motion: a BVH written here drives a generated clip through assimp."""
from __future__ import annotations

import numpy as np
import pytest
import yaml

import bsp_fast
from bsp_fast import geometry as geo
from bsp_fast.csvio import read_csv
from bsp_fast.skeleton import JOINT_INDEX as J
from bsp_fast.synth import generate
from bsp_fast.synth.cli import main as cli_main
from bsp_fast.synth.motion import Motion, match_joints, normalise_name

# (name, parent, offset in cm) in the BVH convention: Y up, facing +Z, left = +X.
BONES = [
    ("Hips", None, (0, 95, 0)), ("Spine", "Hips", (0, 10, 0)), ("Spine1", "Spine", (0, 15, 0)),
    ("Neck", "Spine1", (0, 20, 0)), ("Head", "Neck", (0, 10, 0)),
    ("LeftShoulder", "Spine1", (3, 17, 0)), ("LeftArm", "LeftShoulder", (14, 0, 0)),
    ("LeftForeArm", "LeftArm", (27, 0, 0)), ("LeftHand", "LeftForeArm", (25, 0, 0)),
    ("RightShoulder", "Spine1", (-3, 17, 0)), ("RightArm", "RightShoulder", (-14, 0, 0)),
    ("RightForeArm", "RightArm", (-27, 0, 0)), ("RightHand", "RightForeArm", (-25, 0, 0)),
    ("LeftUpLeg", "Hips", (9, -5, 0)), ("LeftLeg", "LeftUpLeg", (0, -43, 0)),
    ("LeftFoot", "LeftLeg", (0, -42, 0)), ("LeftToeBase", "LeftFoot", (0, -6, 13)),
    ("RightUpLeg", "Hips", (-9, -5, 0)), ("RightLeg", "RightUpLeg", (0, -43, 0)),
    ("RightFoot", "RightLeg", (0, -42, 0)), ("RightToeBase", "RightFoot", (0, -6, 13)),
]
PERIOD, AMP = 30, 25.0  # thigh swing: frames per cycle, degrees


def thigh_angle(f):
    """Forward swing of the left thigh in frame f (degrees). A BVH X rotation of -a swings
    a downward bone towards +Z (forward) by a."""
    return AMP * np.sin(2 * np.pi * f / PERIOD)


def write_bvh(path, frames=60, rename=None):
    kids, offsets = {}, {}
    for name, parent, off in BONES:
        kids.setdefault(parent, []).append(name)
        offsets[name] = off
    lines, order = ["HIERARCHY"], []

    def node(name, depth):
        ind = "  " * depth
        order.append(name)
        label = (rename or {}).get(name, name)
        lines.append(f"{ind}{'ROOT' if depth == 0 else 'JOINT'} {label}")
        lines.append(ind + "{")
        lines.append(f"{ind}  OFFSET " + " ".join(f"{v:.4f}" for v in offsets[name]))
        lines.append(f"{ind}  CHANNELS " + ("6 Xposition Yposition Zposition " if depth == 0
                                             else "3 ") + "Zrotation Xrotation Yrotation")
        for child in kids.get(name, []):
            node(child, depth + 1)
        if name not in kids:
            lines.extend([f"{ind}  End Site", ind + "  {", f"{ind}    OFFSET 0 -5 0", ind + "  }"])
        lines.append(ind + "}")

    node("Hips", 0)
    lines += ["MOTION", f"Frames: {frames}", f"Frame Time: {1 / 30:.8f}"]
    for f in range(frames):
        rot = {"LeftUpLeg": (0, -thigh_angle(f), 0), "RightUpLeg": (0, thigh_angle(f), 0),
               "LeftLeg": (0, 10 + 10 * np.cos(2 * np.pi * f / PERIOD), 0),
               "RightLeg": (0, 10 - 10 * np.cos(2 * np.pi * f / PERIOD), 0),
               "LeftArm": (-75, 0, 0), "RightArm": (75, 0, 0)}
        vals = [0.0, 95.0, 4.0 * f]  # root motion along +Z: dropped by the retargeting
        for name in order:
            vals += list(rot.get(name, (0.0, 0.0, 0.0)))
        lines.append(" ".join(f"{v:.6f}" for v in vals))
    path.write_text("\n".join(lines) + "\n")
    return path


def test_name_normalisation_and_map():
    assert normalise_name("mixamorig:LeftUpLeg") == "leftupleg"
    assert normalise_name("upperarm_L") == "leftupperarm"
    assert normalise_name("thigh.R") == "rightthigh"
    assert normalise_name("RFoot") == "rightfoot" and normalise_name("lShldr") == "leftshldr"
    assert normalise_name("LowerBack") == "lowerback"  # not a left-side name
    assert normalise_name("Bip01 L Thigh") == "leftthigh"
    assert normalise_name("DEF-forearm.R") == "rightforearm"
    m = match_joints([b[0] for b in BONES])
    assert m["crl_thigh__L"] == 13 and m["crl_foot__R"] == 19 and m["crl_spine01__C"] == 2
    # no hips by name: the thighs' nearest common ancestor stands in
    names = ["RootNode", "Bip01 L Thigh", "Bip01 L Calf", "Bip01 R Thigh", "Bip01 R Calf"]
    m = match_joints(names, [-1, 0, 1, 0, 3])
    assert m["crl_hips__C"] == 0 and m["crl_leg__R"] == 4


def test_loader_reads_the_file(tmp_path):
    path = write_bvh(tmp_path / "walk.bvh")
    data = bsp_fast._core.load_motion(str(path), 30.0, 0)
    assert data["local"].shape[0] == 60 and data["local"].shape[2:] == (4, 4)
    assert data["names"][0] == "Hips" and data["parents"][0] == -1
    with pytest.raises(bsp_fast.MotionError, match="no_such.bvh"):
        bsp_fast._core.load_motion(str(tmp_path / "no_such.bvh"), 30.0, 0)


def test_retargeted_thigh_follows_the_bvh(tmp_path):
    mo = Motion(str(write_bvh(tmp_path / "walk.bvh")))
    for stem in ("sk_female", "sk_kid"):
        rel = mo.relative_poses(stem, 60, 30.0, phase=0.0)
        mesh = geo.forward_kinematics(rel)
        v = mesh[:, J["crl_leg__L"], :3] - mesh[:, J["crl_thigh__L"], :3]
        np.testing.assert_allclose(np.degrees(np.arctan2(v[:, 1], -v[:, 2])),
                                   thigh_angle(np.arange(60)), atol=0.2)
        hand = mesh[:, J["crl_hand__L"], 2] - mesh[:, J["crl_arm__L"], 2]
        assert np.all(hand < -0.2)  # arms lowered 75 degrees from the T-pose


def write_gltf(path, frames=60):
    """The same skeleton as a glTF 2.0 file (metres, Y up, +Z forward): thigh rotations as
    LINEAR quaternion samplers in an embedded buffer."""
    import base64
    import json

    index = {b[0]: i for i, b in enumerate(BONES)}
    nodes = [{"name": n, "translation": [v / 100 for v in off]} for n, _, off in BONES]
    for n, parent, _ in BONES:
        if parent:
            nodes[index[parent]].setdefault("children", []).append(index[n])
    t = np.arange(frames, dtype=np.float32) / 30
    blobs = [t.tobytes()]
    acc = [{"bufferView": 0, "componentType": 5126, "count": frames, "type": "SCALAR",
            "min": [0.0], "max": [float(t[-1])]}]
    channels, samplers = [], []
    for name, sign in (("LeftUpLeg", -1), ("RightUpLeg", 1)):
        half = np.radians(sign * thigh_angle(np.arange(frames))) / 2
        q = np.stack([np.sin(half), 0 * half, 0 * half, np.cos(half)], -1).astype(np.float32)
        blobs.append(q.tobytes())
        acc.append({"bufferView": len(blobs) - 1, "componentType": 5126, "count": frames,
                    "type": "VEC4"})
        samplers.append({"input": 0, "output": len(acc) - 1, "interpolation": "LINEAR"})
        channels.append({"sampler": len(samplers) - 1,
                         "target": {"node": index[name], "path": "rotation"}})
    views, offset = [], 0
    for b in blobs:
        views.append({"buffer": 0, "byteOffset": offset, "byteLength": len(b)})
        offset += len(b)
    data = b"".join(blobs)
    uri = "data:application/octet-stream;base64," + base64.b64encode(data).decode()
    path.write_text(json.dumps({
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": nodes,
        "animations": [{"name": "walk", "channels": channels, "samplers": samplers}],
        "accessors": acc, "bufferViews": views,
        "buffers": [{"byteLength": len(data), "uri": uri}]}))
    return path


def test_gltf_animation_is_retargeted(tmp_path):
    mo = Motion(str(write_gltf(tmp_path / "walk.gltf")))
    assert mo.frames == 60
    rel = mo.relative_poses("sk_male", 60, 30.0, phase=0.0)
    mesh = geo.forward_kinematics(rel)
    v = mesh[:, J["crl_leg__R"], :3] - mesh[:, J["crl_thigh__R"], :3]
    np.testing.assert_allclose(np.degrees(np.arctan2(v[:, 1], -v[:, 2])),
                               -thigh_angle(np.arange(60)), atol=0.2)


def test_missing_joints_are_named(tmp_path):
    path = write_bvh(tmp_path / "odd.bvh", frames=5, rename={"LeftLeg": "Knee_Thing"})
    with pytest.raises(bsp_fast.MotionError, match="crl_leg__L"):
        Motion(str(path))


def test_bvh_drives_a_generated_clip(tmp_path):
    path = write_bvh(tmp_path / "walk.bvh")
    s = generate(tmp_path / "ds", clips=2, frames=90, size="160x96", seed=27, workers=1,
                 motion=path, progress=False)
    cfg = yaml.safe_load((tmp_path / "ds" / "config.yaml").read_text())
    assert cfg["motion"] == str(path) and len(cfg["motion_sha256"]) == 64
    t = read_csv(tmp_path / "ds" / "data.csv")
    assert len(t) > 0 and s["annotated_frames"] == len(t)
    rel = t["frame.pedestrian.pose.relative"].astype(np.float64)
    mesh = geo.forward_kinematics(rel)
    v = mesh[:, J["crl_leg__L"], :3] - mesh[:, J["crl_thigh__L"], :3]
    got = np.degrees(np.arctan2(v[:, 1], -v[:, 2]))
    ids, frames = np.asarray(t["id"]), t["frame.idx"]
    for cid in dict.fromkeys(ids):
        rows = ids == cid
        # clip frame f shows source frame (offset + f) mod 60 for some offset
        errs = [np.max(np.abs(got[rows] - thigh_angle(frames[rows] + o))) for o in range(60)]
        assert min(errs) < 0.2
    # the consistency of the three pose columns holds for retargeted motion too
    comp = t["frame.pedestrian.pose.component"].astype(np.float64)
    fk = geo.forward_kinematics(rel, root=geo.mesh_offset(rel, comp))
    np.testing.assert_allclose(fk[..., :3], comp[..., :3], atol=1e-4)


def test_cli_motion_error_exit_code(tmp_path, capsys):
    bad = tmp_path / "bad.bvh"
    bad.write_text("HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0 0\n")
    assert cli_main([str(tmp_path / "o"), "--motion", str(bad), "--quiet"]) == 1
    assert "MotionError" in capsys.readouterr().err
