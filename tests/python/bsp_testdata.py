"""Small, consistent CARLA-BSP data.csv files written independently of the core's writer.

Poses follow the dataset's relations (docs/dataset-format.md, "5. Geometry conventions"):
component = M ∘ FK(relative), world = walker ∘ component, pose.camera = projection of world.
Cells are formatted the way pandas wrote the original (Python str() of float lists).
"""
from __future__ import annotations

import zlib

import numpy as np

import bsp_fast as bf
from bsp_fast import skeleton as sk

# The 24 columns in the original writer's order (docs/dataset-format.md, "2. data.csv"),
# written out independently of the core so tests compare against the spec, not against the
# code under test.
COLUMNS = [
    "id", "world.map", "camera.idx", "camera.transform", "camera.width", "camera.height",
    "pedestrian.idx", "pedestrian.model", "pedestrian.age", "pedestrian.gender",
    "pedestrian.spawn_point", "frame.idx", "camera.recording", "camera.semantic_segmentation",
    "world.frame", "frame.pedestrian.transform", "frame.pedestrian.velocity",
    "frame.pedestrian.pose.world", "frame.pedestrian.pose.component",
    "frame.pedestrian.pose.relative", "frame.pedestrian.is_crossing",
    "frame.pedestrian.pose.camera", "frame.pedestrian.pose.in_frame",
    "frame.pedestrian.pose.in_segmentation",
]
W, H = 1600, 600


def f32list(a) -> str:
    a = np.asarray(a, np.float32)
    if a.ndim == 1:
        return "[" + ", ".join(repr(float(x)) for x in a) + "]"
    return "[" + ", ".join(f32list(x) for x in a) + "]"


def recording(uuid: str, frames, crossing_from=None, seed=0, age="adult", gender="female",
              camera_distance=8.0):
    """Rows (dicts of column -> value) of one recording walking across the camera's view."""
    rng = np.random.default_rng(seed)
    frames = np.asarray(frames)
    n = len(frames)
    rel = np.broadcast_to(sk.reference_pose((age, gender)), (n, 26, 6)).copy()
    rel[:, 1:, 3:] += rng.normal(0, 3, (n, 25, 3))
    M = np.array([0, 0, -0.92, 0, -90, 0])
    comp = bf.forward_kinematics(rel, root=M)
    walker = np.zeros((n, 6))
    walker[:, 0] = 100 + camera_distance
    walker[:, 1] = 50 - 1.5 + 0.03 * frames
    walker[:, 2] = 0.92
    walker[:, 4] = 90.0
    world = bf.to_world(comp, walker)
    cam = np.array([100.0, 50.0, 1.2, 0.0, 0.0, 0.0])  # looking along +x at the walker
    uv = bf.project(world[..., :3], cam, W, H)
    rows = []
    for i, f in enumerate(frames):
        rows.append({
            "id": uuid, "world.map": "/Game/Carla/Maps/Town04", "camera.idx": 0,
            "camera.transform": f32list(cam), "camera.width": W, "camera.height": H,
            "pedestrian.idx": 0, "pedestrian.model": "walker.pedestrian.0001",
            "pedestrian.age": age, "pedestrian.gender": gender,
            "pedestrian.spawn_point": f32list([100 + camera_distance, 48.5, 0.92, 0, 0, 0]),
            "frame.idx": int(f), "camera.recording": f"clips/{uuid}-0.mp4",
            "camera.semantic_segmentation": f"clips/{uuid}-1.apng", "world.frame": 1000 + int(f),
            "frame.pedestrian.transform": f32list(walker[i]),
            "frame.pedestrian.velocity": f32list([0, 0.9, 0]),
            "frame.pedestrian.pose.world": f32list(world[i]),
            "frame.pedestrian.pose.component": f32list(comp[i]),
            "frame.pedestrian.pose.relative": f32list(rel[i]),
            "frame.pedestrian.is_crossing": bool(crossing_from is not None and f >= crossing_from),
            "frame.pedestrian.pose.camera": f32list(uv[i]).replace("nan", "nan"),
            "frame.pedestrian.pose.in_frame": True, "frame.pedestrian.pose.in_segmentation": True,
        })
    return rows


def csv_text(rows, columns=None, newline="\n", crossing_name="frame.pedestrian.is_crossing"):
    columns = list(columns or COLUMNS)
    out = [",".join(crossing_name if c == "frame.pedestrian.is_crossing" else c for c in columns)]
    for r in rows:
        cells = []
        for c in columns:
            v = r[c]
            s = "" if v is None else (str(v) if not isinstance(v, str) else v)
            cells.append(f'"{s}"' if "," in s or '"' in s else s)
        out.append(",".join(cells))
    return newline.join(out) + newline


def write_dataset(root, rows, **kw):
    root.mkdir(parents=True, exist_ok=True)
    (root / "data.csv").write_bytes(csv_text(rows, **kw).encode())
    return root


# ---------------------------------------------------------------- PNG / APNG bytes
def png_chunk(kind: bytes, data: bytes) -> bytes:
    """One PNG chunk: length, type, data, CRC."""
    return len(data).to_bytes(4, "big") + kind + data + zlib.crc32(kind + data).to_bytes(4, "big")


def png_chunks(data: bytes) -> list:
    """(offset, type, data length) of every chunk of a PNG."""
    pos, out = 8, []
    while pos + 12 <= len(data):
        n = int.from_bytes(data[pos:pos + 4], "big")
        out.append((pos, data[pos + 4:pos + 8], n))
        pos += 12 + n
    return out


def corrupt_apng_frame(path, j: int) -> None:
    """Flips a byte in the middle of APNG frame j's image data (j >= 1: its fdAT chunk), so
    that its CRC check fails there."""
    data = bytearray(path.read_bytes())
    fctl = -1
    for pos, kind, n in png_chunks(bytes(data)):
        fctl += kind == b"fcTL"
        if kind == b"fdAT" and fctl == j:
            data[pos + 8 + 4 + n // 2] ^= 0x55
            path.write_bytes(bytes(data))
            return
    raise AssertionError(f"no fdAT for frame {j}")


def table_clip_files(root) -> dict:
    """One small clip file per report table's task (the reproduce tests' data): lifting
    and classification at L 16, autoencoder at L 30, pose estimation with media at L 4;
    the classification file marked as benchmark windows."""
    import h5py

    from bsp_fast.data.testing import write_clip_file

    files = {"lifting": root / "l16.h5", "classification": root / "bench.h5",
             "autoencoder": root / "l30.h5", "pose_estimation": root / "media.h5"}
    write_clip_file(files["lifting"], clips=(24, 12, 12), clip_length=16, seed=1)
    write_clip_file(files["autoencoder"], clips=(24, 12, 12), clip_length=30, seed=2)
    write_clip_file(files["pose_estimation"], clips=(16, 8, 8), clip_length=4, seed=4,
                    media=True)
    write_clip_file(files["classification"], clips=(24, 12, 12), clip_length=16, seed=3)
    with h5py.File(files["classification"], "a") as f:  # stands in for benchmark windows
        f.attrs["benchmark"] = 1
    return files
