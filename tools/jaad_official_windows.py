"""The PedestrianActionBenchmark's crossing windows of JAAD, computed by the official code,
and compared with a clip file of ``bsp-interop import jaad`` (docs/interop.md, "Checked
against the official code").

The official code is not part of bsp_fast: give a checkout of JAAD (its annotations and
``jaad_data.py``, github.com/ykotseruba/JAAD) and of the benchmark (``action_predict.py``,
github.com/ykotseruba/PedestrianActionBenchmark). ``JAAD.generate_data_trajectory_sequence``
runs as ``train_test.py`` calls it (``seq_type`` crossing, ``min_track_size`` obs + TTE
max), and ``ActionPredict.get_data_sequence`` is taken from ``action_predict.py`` by
itself (that module imports TensorFlow; the function needs only NumPy)::

    python tools/jaad_official_windows.py JAAD_ROOT --benchmark PAB_DIR --out windows.json
    python tools/jaad_official_windows.py JAAD_ROOT --benchmark PAB_DIR --compare clips.h5 \\
        --subset beh

``windows.json``: ``{subset: {split: [{video, pid, frames, label, tte, boxes}]}}`` in the
official order (videos and pedestrian ids sorted, windows by start). ``--compare`` prints
the differences and exits 1 on any.
"""
from __future__ import annotations

import argparse
import ast
import importlib.util
import json
import sys
import tempfile
import types
from pathlib import Path

import numpy as np

SPLITS = ("train", "val", "test")
#: train_test.py's settings for JAAD (obs 16, TTE 30-60, overlap 0.8, min track obs + 60)
OPTS = dict(obs_length=16, time_to_event=[30, 60], overlap=0.8, balance_data=False,
            normalize_boxes=False)


def _stub(name: str, **attrs) -> None:
    """jaad_data.py imports OpenCV and scikit-learn at its top for functions the crossing
    sequences never call; a stand-in lets it load where they are not installed."""
    top = name.split(".")[0]
    if top not in sys.modules and importlib.util.find_spec(top) is None:
        parts = name.split(".")
        for i in range(len(parts)):
            part = ".".join(parts[:i + 1])
            sys.modules.setdefault(part, types.ModuleType(part))
        for k, v in attrs.items():
            setattr(sys.modules[name], k, v)


def load_jaad_class(code: Path):
    """The ``JAAD`` class of the official ``jaad_data.py``, its database cache redirected to
    a temporary folder (the official code writes ``ROOT/data_cache`` otherwise)."""
    _stub("cv2")
    _stub("sklearn.model_selection", train_test_split=None, KFold=None)
    spec = importlib.util.spec_from_file_location("official_jaad_data", code)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    cache = tempfile.mkdtemp(prefix="jaad-cache-")

    class JAAD(module.JAAD):
        cache_path = property(lambda self: cache)

    return JAAD


def load_get_data_sequence(action_predict: Path):
    """``ActionPredict.get_data_sequence`` compiled from the official source alone."""
    tree = ast.parse(Path(action_predict).read_text(encoding="utf-8"))
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef) and node.name == "get_data_sequence":
            namespace = {"np": np}
            exec(compile(ast.Module([node], []), str(action_predict), "exec"), namespace)
            return namespace["get_data_sequence"]
    raise SystemExit(f"{action_predict}: no get_data_sequence in it")


def official_windows(root: Path, code: Path, action_predict: Path, subset: str,
                     opts: dict = OPTS) -> dict:
    """``{split: [window]}`` as the benchmark's training script builds them."""
    import contextlib
    import io

    jaad = load_jaad_class(code)(data_path=str(root))
    get_data_sequence = load_get_data_sequence(action_predict)
    out = {}
    for split in SPLITS:
        with contextlib.redirect_stdout(io.StringIO()):
            raw = jaad.generate_data_trajectory_sequence(
                split, fstride=1, sample_type=subset, subset="default",
                data_split_type="default", seq_type="crossing", height_rng=[0, float("inf")],
                squarify_ratio=0, min_track_size=opts["obs_length"] + opts["time_to_event"][1])
            d, _, _ = get_data_sequence(None, split, raw, dict(opts))
        out[split] = [dict(video=Path(img[0]).parent.name, pid=str(pid[0][0]),
                           frames=[int(Path(p).stem) for p in img], label=int(c[0]),
                           tte=int(t[0]), boxes=np.asarray(b, float).tolist())
                      for img, pid, c, t, b in zip(d["image"], d["ped_id"], d["crossing"],
                                                   d["tte"], d["box"])]
    return out


def clip_windows(path) -> dict:
    """The windows of a clip file in the same form (``meta/tte`` as the TTE)."""
    import h5py

    out = {}
    with h5py.File(path, "r") as f:
        for split in SPLITS:
            g = f[split]
            boxes = (g["targets/annotated_bboxes"][()].reshape(len(g["labels"]), -1, 4)
                     if "targets/annotated_bboxes" in g else None)
            out[split] = [dict(video=v, pid=p, frames=fr.tolist(), label=int(lab), tte=int(t),
                               boxes=None if boxes is None else boxes[i].tolist())
                          for i, (v, p, fr, lab, t) in enumerate(zip(
                              g["meta/video_id"].asstr()[()], g["meta/pedestrian_id"].asstr()[()],
                              g["targets/frame_idx"][()], g["labels"][()], g["meta/tte"][()]))]
    return out


def compare(official: dict, ours: dict, box_tol: float = 1e-3) -> list:
    """Differences, one line each (empty: every window the same, in the same order)."""
    lines = []
    key = lambda w: (w["video"], w["pid"], w["frames"][0], w["frames"][-1])  # noqa: E731
    for split in SPLITS:
        a, b = official.get(split, []), ours.get(split, [])
        ka, kb = {key(w): w for w in a}, {key(w): w for w in b}
        if len(a) != len(b):
            lines.append(f"{split}: {len(a)} official windows, {len(b)} ours")
        lines += [f"{split}: only official: {k}" for k in sorted(set(ka) - set(kb))[:10]]
        lines += [f"{split}: only ours: {k}" for k in sorted(set(kb) - set(ka))[:10]]
        for k in sorted(set(ka) & set(kb)):
            wa, wb = ka[k], kb[k]
            for field in ("frames", "label", "tte"):
                if wa[field] != wb[field]:
                    lines.append(f"{split} {k}: {field} {wa[field]} (official) != {wb[field]}")
            if wb["boxes"] is not None and not np.allclose(wa["boxes"], wb["boxes"],
                                                           atol=box_tol):
                lines.append(f"{split} {k}: boxes differ")
    return lines


def synthetic_poses(root: Path, out: Path, seed: int = 0) -> None:
    """A pose pickle in the benchmark's format (``{video: {"<frame:05d>_<pid>": 36
    values}}``, COCO-18 normalised by the image size) with a pose inside every annotated
    box of ``root``'s annotations: the windows do not depend on pose values, only on
    there being poses for every video (the official pickles are not in its repository)."""
    import pickle
    import xml.etree.ElementTree as ET

    rng = np.random.default_rng(seed)
    doc = {}
    for path in sorted((root / "annotations").glob("*.xml")):
        tree = ET.parse(path)
        size = np.array([float(tree.findtext("./meta/task/original_size/width")),
                         float(tree.findtext("./meta/task/original_size/height"))])
        table = doc.setdefault(path.stem, {})
        for box in tree.iter("box"):
            pid = box.find('./attribute[@name="id"]').text
            lo = np.array([float(box.get("xtl")), float(box.get("ytl"))])
            hi = np.array([float(box.get("xbr")), float(box.get("ybr"))])
            pts = lo + (hi - lo) * rng.uniform(0.1, 0.9, (18, 2))
            table[f"{int(box.get('frame')):05d}_{pid}"] = (pts / size).ravel()
    out.write_bytes(pickle.dumps(doc))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("jaad", type=Path, help="JAAD checkout (annotations*/, split_ids/)")
    p.add_argument("--jaad-code", type=Path, help="jaad_data.py (default JAAD/jaad_data.py)")
    p.add_argument("--benchmark", type=Path,
                   help="PedestrianActionBenchmark checkout (action_predict.py)")
    p.add_argument("--official", type=Path, metavar="JSON",
                   help="the official windows written before by --out (instead of running "
                   "the official code again)")
    p.add_argument("--subset", choices=("beh", "all"), nargs="+", default=["beh", "all"])
    p.add_argument("--out", type=Path, help="write the official windows here (JSON)")
    p.add_argument("--compare", type=Path, metavar="CLIPS.h5",
                   help="compare with this clip file (one --subset)")
    p.add_argument("--write-poses", type=Path, metavar="PKL",
                   help="write a pose pickle with a pose in every annotated box, then stop")
    a = p.parse_args(argv)
    if a.benchmark is None and a.official is None and a.write_poses is None:
        p.error("give --benchmark (to run the official code) or --official JSON")
    if a.write_poses:
        synthetic_poses(a.jaad, a.write_poses)
        return 0
    code = a.jaad_code or a.jaad / "jaad_data.py"
    if a.official:
        stored = json.loads(a.official.read_text(encoding="utf-8"))
        result = {s: stored[s] for s in a.subset}
    else:
        result = {s: official_windows(a.jaad, code, a.benchmark / "action_predict.py", s)
                  for s in a.subset}
    for s, splits in result.items():
        print(f"{s}: " + ", ".join(f"{k} {len(v)} windows ({sum(w['label'] for w in v)} "
                                   "crossing)" for k, v in splits.items()))
    if a.out:
        a.out.write_text(json.dumps(result), encoding="utf-8")
    if a.compare:
        diff = compare(result[a.subset[0]], clip_windows(a.compare))
        print("\n".join(diff) if diff else "every window the same (frames, label, TTE, box)")
        return 1 if diff else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
