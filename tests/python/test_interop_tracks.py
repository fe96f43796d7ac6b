"""bsp-interop import openpose --tracks best: one person followed by position, identity
switches, empty and missing frames in the summary, CLI wording of messages."""
import json

import h5py
import numpy as np

from bsp_fast import interop as I
from bsp_fast.interop.cli import main
from bsp_fast.skeleton import JOINT_INDEX as J

W, H = 640, 360


def person(x0, frame, conf):
    """(25, 3) BODY_25 joints of a person standing at x0, drifting 1 px per frame."""
    kp = np.zeros((25, 3))
    kp[:, 0] = x0 + 3 * np.arange(25) + frame
    kp[:, 1] = 80 + 8 * np.arange(25)
    kp[:, 2] = conf
    return kp


def two_people(folder):
    """Untracked people A (x 100) and B (x 400): both in frames 0-11, B scored higher from
    frame 6 on; frame 12 has nobody; A is gone from frame 13 on; no file for frame 21."""
    folder.mkdir()
    for f in [f for f in range(26) if f != 21]:
        people = []
        if f < 12:
            people.append(person(100, f, 0.9))
        if f != 12:
            people.append(person(400, f, 0.95 if f >= 6 else 0.5))
        doc = {"version": 1.3, "people": [{"person_id": [-1],
                                           "pose_keypoints_2d": p.reshape(-1).tolist()}
                                          for p in people]}
        (folder / f"cam_{f:012d}_keypoints.json").write_text(json.dumps(doc))


def test_best_follows_the_nearest_person_and_lists_the_switch(tmp_path):
    op = tmp_path / "op"
    two_people(op)
    det = I.read_openpose(op, (W, H), tracks="best")
    x = {t: det.points[[k for k, tt in enumerate(det.track) if tt == t], 0, 0]
         for t in set(det.track)}
    frames = {t: det.frame[[k for k, tt in enumerate(det.track) if tt == t]] for t in x}
    # track 0 is A in every frame 0-11 although B scores higher from frame 6: no jump
    assert list(frames["0"]) == list(range(12)) and np.all(x["0"] < 200)
    # A gone: the nearest is far, so B starts track 1 (listed), not a jump inside track 0
    assert list(frames["1"]) == [f for f in range(13, 26) if f != 21] and np.all(x["1"] > 300)
    notes = det.notes
    assert len(notes["identity_switches"]) == 1 and "frame 13" in notes["identity_switches"][0]
    assert notes["empty_frames"] == {"cam": 1} and notes["dropped_frames"] == {"cam": [21]}
    assert notes["dropped_detections"] == 12  # B in frames 0-11


def test_summary_reports_switches_frames_and_explains_the_counts(tmp_path, capsys):
    op = tmp_path / "op"
    two_people(op)
    out = tmp_path / "o.h5"
    rc = main(["import", "openpose", str(op), str(out), "--image-size", f"{W}x{H}",
               "--tracks", "best", "--clip-length", "4", "--val-frac", "0", "--test-frac", "0"])
    text = capsys.readouterr().out
    assert rc == 0, text
    assert "identity switches: 1; frames without a person: 1; missing frame numbers: 1" in text
    assert "identity switch: video 'cam' frame 13" in text
    assert "video 'cam': frames missing: 21" in text
    assert "train 6 clips (not-crossing 6, crossing 0)" in text  # issue 40 item 9
    assert "[" not in text.split("\n")[0]
    with h5py.File(out) as f:
        ids = set(f["train/meta/pedestrian_id"].asstr()[()])
        uv = f["train/projection_2d"][()]
    assert ids == {"0", "1"}
    # no clip mixes the two people: the head moves by 1 px per frame within every clip
    head = uv[:, :, J["crl_Head__C"], 0]
    assert np.all(np.abs(np.diff(head, axis=1)) <= 2)


def test_cli_messages_name_command_line_options(tmp_path, capsys):
    op = tmp_path / "op"
    two_people(op)
    out = tmp_path / "o.h5"
    base = ["import", "openpose", str(op), str(out), "--image-size", f"{W}x{H}"]
    assert main(base + ["--clip-length", "4"]) == 1
    err = capsys.readouterr().err.replace(str(tmp_path), "TMP")
    assert "people without person_id in this frame" in err and "--tracks best" in err
    assert "tracks='best'" not in err and "track_id" not in err and "image holds" not in err
    assert main(base + ["--tracks", "best", "--clip-length", "12"]) == 1
    err = capsys.readouterr().err.replace(str(tmp_path), "TMP")
    assert "--skip-short-tracks" in err and "skip_short" not in err
    assert not out.exists()
