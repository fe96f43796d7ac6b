"""Clip planning (docs/dataset-format.md, "7. From rows to clips and splits") against counts
and splits worked out by hand."""
import numpy as np
import pytest

from bsp_fast._native import core

W, H = 100, 50


def rows(spec):
    """spec: list of (recording_code, frame_idx, crossing, inside) -> plan_clips arguments."""
    n = len(spec)
    ids = np.array([s[0] for s in spec], np.int32)
    frames = np.array([s[1] for s in spec], np.int64)
    crossing = np.array([s[2] for s in spec], np.uint8)
    uv = np.full((n, 26, 2), 10.0, np.float32)
    for i, s in enumerate(spec):
        if not s[3]:
            uv[i, 5] = (-1.0, 10.0)  # one joint left of the image
    z = np.zeros(n, np.int64)
    return ids, z, z, frames, crossing, uv, np.full(n, W, np.int64), np.full(n, H, np.int64)


def plan(spec, **kw):
    kw.setdefault("val_frac", 0.0)
    kw.setdefault("test_frac", 0.0)
    return core.plan_clips(*rows(spec), **kw)


def all_clips(p):
    return sum(len(p[s]["first"]) for s in ("train", "val", "test"))


def gap_recording(code=0, crossing_from=None):
    frames = list(range(0, 10)) + list(range(12, 21))  # segments of 10 and 9 frames
    return [(code, f, crossing_from is not None and f >= crossing_from, True) for f in frames]


def test_windows_restart_in_each_segment_and_never_span_gaps():
    p = plan(gap_recording(), clip_length=3, clip_stride=3, test_frac=0.0)
    # segment 1 (10 frames): starts 0, 3, 6; segment 2 (9 frames): starts 0, 3, 6.
    clips = []
    for s in ("train", "val", "test"):
        d = p[s]
        clips += list(zip(d["segment"], d["index"], d["first"]))
    assert sorted(clips) == [(0, 0, 0), (0, 1, 3), (0, 2, 6), (1, 0, 10), (1, 1, 13), (1, 2, 16)]


def test_overlapping_windows():
    p = plan(gap_recording(), clip_length=3, clip_stride=2)
    assert all_clips(p) == 4 + 4  # starts 0,2,4,6 in both segments


def test_in_image_filter_drops_windows_touching_a_bad_frame():
    spec = gap_recording()
    spec[4] = (0, 4, False, False)  # frame 4 has a joint outside the image
    p = plan(spec, clip_length=3, clip_stride=1)
    # segment 1 starts 0..7 = 8 windows, those covering frame 4 start at 2, 3, 4.
    assert all_clips(p) == (8 - 3) + 7
    assert p["clips_rejected_out_of_image"] == 3


def test_labels_last_frame_and_any_of_tail():
    spec = [(0, f, f == 4, True) for f in range(6)]  # only frame 4 crossing
    last = plan(spec, clip_length=3, clip_stride=1)
    by_first = dict(zip(last["train"]["first"], last["train"]["label"]))
    assert by_first == {0: 0, 1: 0, 2: 1, 3: 0}
    anyf = plan(spec, clip_length=3, clip_stride=1, label_fraction=0.5)  # last ceil(1.5) = 2
    by_first = dict(zip(anyf["train"]["first"], anyf["train"]["label"]))
    assert by_first == {0: 0, 1: 0, 2: 1, 3: 1}


def test_min_video_length_skips_short_recordings():
    spec = [(0, f, False, True) for f in range(5)] + [(1, f, False, True) for f in range(8)]
    p = plan(spec, clip_length=2, min_video_length=6)
    assert [s[0] for s in p["skipped"]] == [0]
    assert "min_video_length" in p["skipped"][0][1]
    assert all_clips(p) == 4


def test_benchmark_time_to_event_windows():
    L = 4
    # crosser: 120 frames, first crossing at frame 100 -> keep frames 100-4-60=36 .. 70
    crosser = [(0, f, f >= 100, True) for f in range(120)]
    # non-crosser: frames 0..99 -> event = 99 - 3 = 96 -> keep 32 .. 66
    walker = [(1, f, False, True) for f in range(100)]
    short = [(2, f, False, True) for f in range(L + 59)]  # needs >= L + 60 rows
    p = plan(crosser + walker + short, clip_length=L, clip_stride=6, benchmark=True)
    firsts = {}
    for s in ("train", "val", "test"):
        for r, first, lab in zip(p[s]["recording"], p[s]["first"], p[s]["label"]):
            firsts.setdefault(int(r), []).append((int(first), int(lab)))
    rr = p["recording_rows"]
    # 35 kept frames (36..70): starts 36, 42, ..., 66 (66 + 4 - 1 = 69 <= 70) -> 6 clips
    assert sorted(rr[0][f] for f, _ in firsts[0]) == [36, 42, 48, 54, 60, 66]
    assert all(lab == 1 for _, lab in firsts[0])  # video-level label
    assert sorted(rr[1][f] - 120 for f, _ in firsts[1]) == [32 + 6 * i for i in range(6)]
    assert all(lab == 0 for _, lab in firsts[1])
    assert [s[0] for s in p["skipped"]] == [2]
    # time to event: the event minus the window's last frame (first + L - 1)
    tte = {}
    for s in ("train", "val", "test"):
        for r, first, t in zip(p[s]["recording"], p[s]["first"], p[s]["time_to_event"]):
            tte.setdefault(int(r), []).append((int(rr[r][first]) % 120 + L - 1, int(t)))
    assert sorted(tte[0]) == [(39 + 6 * i, 61 - 6 * i) for i in range(6)]  # event 100
    assert sorted(tte[1]) == [(35 + 6 * i, 61 - 6 * i) for i in range(6)]  # event 96
    plain = plan(crosser + walker, clip_length=L, clip_stride=6)
    assert {int(t) for s in ("train", "val", "test") for t in plain[s]["time_to_event"]} == {-1}


def test_split_by_recording_follows_the_fill_rule():
    # Recordings (each its own id) with 10, 6, 4, 3, 2 clips of L=1 frames: N = 25.
    counts = [10, 6, 4, 3, 2]
    spec = []
    for code, c in enumerate(counts):
        spec += [(code, f, False, True) for f in range(c)]
    p = core.plan_clips(*rows(spec), clip_length=1, val_frac=0.2, test_frac=0.2)
    # test = floor(0.2*25) = 5, val = floor(0.2*20) = 4, train = 16.
    # Sorted: 10, 6, 4, 3, 2. Round 1: train takes 10 (need 16 -> 6); val needs 4: first
    # fitting is 4 -> val; test needs 5: first fitting is 3 -> test (need 2).
    # Round 2: train needs 6: 6 fits -> train (0); val needs 0: nothing fits, not empty;
    # test needs 2: 2 fits -> test.
    assert sorted(p["train"]["recordings"]) == [0, 1]
    assert p["val"]["recordings"] == [2]
    assert sorted(p["test"]["recordings"]) == [3, 4]
    assert [len(p[s]["first"]) for s in ("train", "val", "test")] == [16, 4, 5]


def test_every_recording_in_exactly_one_split_and_seeded_shuffle():
    spec = []
    for code in range(12):
        spec += [(code, f, f > 20 and code % 2 == 0, True) for f in range(40)]
    a = core.plan_clips(*rows(spec), clip_length=5, seed=1)
    b = core.plan_clips(*rows(spec), clip_length=5, seed=1)
    c = core.plan_clips(*rows(spec), clip_length=5, seed=2)
    recs = [r for s in ("train", "val", "test") for r in a[s]["recordings"]]
    assert sorted(recs) == list(range(12))
    for s in ("train", "val", "test"):
        assert set(a[s]["recording"]) <= set(a[s]["recordings"])
        np.testing.assert_array_equal(a[s]["first"], b[s]["first"])
        np.testing.assert_array_equal(a[s]["recording"], b[s]["recording"])
    assert not np.array_equal(a["train"]["recording"], c["train"]["recording"])


def test_balance_keeps_min_class_count_in_train():
    spec = []
    for code in range(10):
        spec += [(code, f, code < 3, True) for f in range(20)]  # 3 crossing recordings
    p = core.plan_clips(*rows(spec), clip_length=5, balance=True, val_frac=0.2, test_frac=0.2)
    labels = p["train"]["label"]
    assert (labels == 1).sum() == (labels == 0).sum()
    assert p["clips_dropped_by_balance"] > 0


def test_eval_offset_applies_to_val_and_test_only():
    spec = []
    for code in range(6):
        spec += [(code, f, False, True) for f in range(12)]
    p = core.plan_clips(*rows(spec), clip_length=4, clip_stride=2, eval_clip_stride=4,
                        val_frac=0.2, test_frac=0.2)
    per_rec = {"train": 5, "val": 3, "test": 3}  # starts 0,2,4,6,8 vs 0,4,8
    for s, n in per_rec.items():
        assert len(p[s]["first"]) == n * len(p[s]["recordings"])


def test_bad_options_raise():
    with pytest.raises(ValueError, match="unknown option"):
        plan(gap_recording(), clip_lenght=3)
