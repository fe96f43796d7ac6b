"""bsp-interop import openpose --tracks best on hand-made folders of two untracked people
whose paths meet: the followed person hidden by the other, two people of equal size
crossing, two people of different sizes crossing. However the tracker resolves them, a
track never holds two people, and every change of track is listed with its frame."""
import json

import numpy as np
import pytest

from bsp_fast import interop as I
from bsp_fast.interop.cli import main

W, H = 1280, 720
FRAMES = 60


def pose(x, y, scale, marker):
    """(25, 3) BODY_25 joints of a person whose box starts at (x, y); ``marker`` (the
    confidence) tells the test who it is: the tracker never compares confidences."""
    kp = np.zeros((25, 3))
    kp[:, 0] = x + scale * 3 * np.arange(25) % (scale * 60)
    kp[:, 1] = y + scale * 8 * np.arange(25)
    kp[:, 2] = marker
    return kp


def write(folder, people_at):
    """``people_at(frame)`` -> list of (25, 3) poses; one JSON file per frame."""
    folder.mkdir()
    for f in range(FRAMES):
        doc = {"version": 1.3, "people": [{"person_id": [-1],
                                           "pose_keypoints_2d": p.reshape(-1).tolist()}
                                          for p in people_at(f)]}
        (folder / f"street_{f:012d}_keypoints.json").write_text(json.dumps(doc))


A, B = 0.92, 0.91  # the markers (A, scored higher, is followed first)


def hidden_by(f):
    """A walks slowly right; B, nearer the camera (1.2x), walks left in front of it and
    hides it for 8 frames (26-33): A is not detected there."""
    a = pose(400 + 1.0 * f, 200, 1.0, A)
    b = pose(900 - 12.0 * f, 190, 1.2, B)
    return [b] if 26 <= f < 34 else [a, b]


def equal_size(f):
    """A walks right, B walks left, same size, same height: their paths cross at f 25."""
    return [pose(200 + 10.0 * f, 200, 1.0, A), pose(700 - 10.0 * f, 200, 1.0, B)]


def cross_paths(f):
    """A walks right and down, B (0.85x) walks left and up: paths cross near f 30."""
    return [pose(150 + 9.0 * f, 150 + 2.0 * f, 1.0, A),
            pose(700 - 9.0 * f, 270 - 2.0 * f, 0.85, B)]


@pytest.mark.parametrize("scene", [hidden_by, equal_size, cross_paths])
def test_a_track_never_holds_two_people_and_every_switch_is_listed(tmp_path, scene):
    op = tmp_path / "op"
    write(op, scene)
    det = I.read_openpose(op, (W, H), tracks="best")
    tracks = sorted(set(det.track), key=int)
    for t in tracks:
        rows = [k for k, x in enumerate(det.track) if x == t]
        who = set(np.round(det.scores[rows, 0], 2))
        assert len(who) == 1, (scene.__name__, t, who, det.frame[rows])
    switches = det.notes["identity_switches"]
    assert len(switches) == len(tracks) - 1
    starts = [int(det.frame[[k for k, x in enumerate(det.track) if x == t]].min())
              for t in tracks[1:]]
    assert [f" frame {s}:" in line for s, line in zip(starts, switches)] == [True] * len(starts)


def test_equal_size_crossing_follows_a_by_its_motion(tmp_path):
    """Before, the nearest-to-previous rule followed A to frame 24 and B after, reporting
    nothing; the followed person's own motion tells them apart where they do not overlap."""
    op = tmp_path / "op"
    write(op, equal_size)
    det = I.read_openpose(op, (W, H), tracks="best")
    first = [k for k, x in enumerate(det.track) if x == "0"]
    assert set(np.round(det.scores[first, 0], 2)) == {A}
    assert all(set(np.round(det.scores[[k for k, x in enumerate(det.track) if x == t], 0], 2))
               == {A} for t in set(det.track))  # A throughout, B never followed


def test_summary_lists_the_switches(tmp_path, capsys):
    op = tmp_path / "op"
    write(op, hidden_by)
    out = tmp_path / "o.h5"
    assert main(["import", "openpose", str(op), str(out), "--image-size", f"{W}x{H}",
                 "--tracks", "best", "--clip-length", "4", "--val-frac", "0", "--test-frac",
                 "0", "--skip-short-tracks"]) == 0
    text = capsys.readouterr().out
    n = int(text.split("identity switches: ")[1].split(";")[0])
    assert n >= 1
    assert text.count("  identity switch: video 'street' frame ") == n
