"""bsp-synth's data.csv against the bytes the generator wrote at 4fba854, before the
poses-only mode stopped rendering whole frames (issue 59): a few clips of every preset
and two seeds, in both modes, must hash as they did then.

The hashes (tests/python/data/synth_reference.json) were written by this file's
``python3 tests/python/test_synth_reference.py --write`` with bsp_fast built from
4fba854; rewrite them only for a change meant to alter the generated data.
"""
from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

import pytest

REFERENCE = Path(__file__).with_name("data") / "synth_reference.json"

# (name, preset, options): the first clips of each preset, the default seed and another;
# the small images put distant walkers between pixel centres, so in_segmentation holds
# both values; bone_length_variation draws from a stream of its own.
CASES = [
    ("sample-22752", "sample", dict(clips=6)),
    ("sample-1", "sample", dict(clips=6, seed=1)),
    ("sample-160x96-0", "sample", dict(clips=4, frames=60, size="160x96", seed=0)),
    ("sample-bones-3", "sample", dict(clips=3, seed=3, bone_length_variation=0.2)),
    ("medium-22752", "medium", dict(clips=3)),
    ("medium-5", "medium", dict(clips=3, seed=5)),
    ("full-22752", "full", dict(clips=2)),
    ("full-9", "full", dict(clips=2, seed=9)),
]
# Cases also generated with media (the slow mode): its data.csv must be the same bytes.
MEDIA_CASES = ("sample-160x96-0",)


def digest(path: Path) -> dict:
    """sha256, size and the in_segmentation counts of a data.csv."""
    from bsp_fast.csvio import read_csv

    data = path.read_bytes()
    seg = read_csv(path, columns=["frame.pedestrian.pose.in_segmentation"])[
        "frame.pedestrian.pose.in_segmentation"]
    return {"sha256": hashlib.sha256(data).hexdigest(), "bytes": len(data),
            "rows": int(len(seg)), "in_segmentation": int(seg.sum())}


def make(root: Path, name: str, poses_only: bool = True, workers: int = 2) -> dict:
    from bsp_fast.synth import generate

    preset, opts = next((p, o) for n, p, o in CASES if n == name)
    out = root / f"{name}-{'poses' if poses_only else 'media'}"
    generate(out, preset, poses_only=poses_only, workers=workers, progress=False, **opts)
    return digest(out / "data.csv")


@pytest.fixture(scope="module")
def reference() -> dict:
    return json.loads(REFERENCE.read_text())["cases"]


@pytest.mark.parametrize("name", [c[0] for c in CASES])
def test_poses_only_data_csv_is_byte_identical_to_4fba854(name, reference, tmp_path):
    assert make(tmp_path, name) == reference[name]


@pytest.mark.parametrize("name", MEDIA_CASES)
def test_media_mode_data_csv_is_byte_identical_to_4fba854(name, reference, tmp_path):
    assert make(tmp_path, name, poses_only=False, workers=1) == reference[name]


def test_reference_covers_hidden_and_visible_frames(reference):
    # Otherwise the comparison could not tell a computed flag from a constant one.
    assert any(0 < r["in_segmentation"] < r["rows"] for r in reference.values())


def main(argv: list) -> int:
    import subprocess
    import tempfile

    if argv != ["--write"]:
        print(__doc__)
        return 2
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                            text=True, cwd=Path(__file__).parent).stdout.strip()
    with tempfile.TemporaryDirectory() as tmp:
        cases = {name: make(Path(tmp), name) for name, _, _ in CASES}
    REFERENCE.parent.mkdir(exist_ok=True)
    # Other keys (the whole presets' hashes, which take minutes to make) are kept.
    data = json.loads(REFERENCE.read_text()) if REFERENCE.exists() else {}
    data.update(commit=commit, cases=cases)
    REFERENCE.write_text(json.dumps(data, indent=1) + "\n")
    print(json.dumps(cases, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
