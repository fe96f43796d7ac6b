"""VideoReader against PyAV and the frame-index contract, plus typed errors."""
from __future__ import annotations

import shutil
import subprocess

import numpy as np
import pytest

import bsp_fast
from bsp_fast import media
from test_media_writers import number_frames, read_number

av = pytest.importorskip("av")

W, H = 96, 64
needs_ffmpeg = pytest.mark.skipif(shutil.which("ffmpeg") is None, reason="ffmpeg CLI missing")


def moving_frames(n: int, w: int = 128, h: int = 80) -> np.ndarray:
    """Smooth gradients and a moving square: real chroma detail for the conversion check."""
    yy, xx = np.mgrid[0:h, 0:w]
    out = np.empty((n, h, w, 3), np.uint8)
    for k in range(n):
        out[k, ..., 0] = (xx * 2 + k * 3) % 256
        out[k, ..., 1] = (yy * 3 + k) % 256
        out[k, ..., 2] = ((xx + yy) * 2) % 256
        x0 = (5 * k) % (w - 20)
        out[k, 20:40, x0:x0 + 20] = (250, 30, 60)
    return out


def pyav_rgb(path) -> np.ndarray:
    with av.open(str(path)) as c:
        return np.stack([f.to_ndarray(format="rgb24") for f in c.decode(video=0)])


def ffmpeg_encode(frames: np.ndarray, path, *args: str) -> None:
    """Encodes raw RGB frames with the ffmpeg CLI (for GOP sizes our writer does not set)."""
    n, h, w, _ = frames.shape
    cmd = ["ffmpeg", "-v", "error", "-y", "-f", "rawvideo", "-pix_fmt", "rgb24", "-s", f"{w}x{h}",
           "-r", "30", "-i", "-", *args, str(path)]
    subprocess.run(cmd, input=frames.tobytes(), check=True)


@pytest.fixture(scope="module")
def numbers_mp4(tmp_path_factory):
    path = tmp_path_factory.mktemp("video") / "numbers.mp4"
    with media.VideoWriter(path, W, H) as w:
        w.write(number_frames(90))
    return path


def test_reader_properties(numbers_mp4):
    r = media.VideoReader(numbers_mp4)
    assert len(r) == 90 and r.size == (W, H) and r.fps == 30 and r.codec == "h264"


def test_reader_equals_pyav(tmp_path):
    path = tmp_path / "moving.mp4"
    frames = moving_frames(40)
    with media.VideoWriter(path, 128, 80) as w:
        w.write(frames)
    ours = media.VideoReader(path).read(np.arange(40))
    ref = pyav_rgb(path)
    assert ours.shape == ref.shape == (40, 80, 128, 3)
    assert np.abs(ours.astype(int) - ref).max() <= 1
    assert np.abs(ours.astype(int) - frames).mean() < 12  # and it is the picture we wrote


def test_frame_index_contract_random_order(numbers_mp4):
    r = media.VideoReader(numbers_mp4)
    rng = np.random.default_rng(7)
    idx = rng.integers(0, 90, 40)
    idx[5] = idx[6]  # a repeat
    got = r.read(idx)
    assert [read_number(f) for f in got] == idx.tolist()
    assert [read_number(f) for f in r] == list(range(90))
    assert read_number(r[89]) == 89 and read_number(r[0]) == 0


@needs_ffmpeg
def test_frame_index_contract_short_gop_and_bframes(tmp_path):
    """Keyframe seeks forward and back; B-frames reorder; frame k is still number k."""
    path = tmp_path / "gop.mp4"
    ffmpeg_encode(number_frames(120), path, "-c:v", "libx264", "-g", "12", "-bf", "3",
                  "-pix_fmt", "yuv420p")
    r = media.VideoReader(path, threads=2)
    assert len(r) == 120
    for idx in ([100, 3, 57, 58, 20, 119, 0], list(range(119, -1, -17)), [64] * 3):
        assert [read_number(f) for f in r.read(idx)] == list(idx)


@needs_ffmpeg
def test_edit_list_first_shown_frame_is_frame_zero(tmp_path, numbers_mp4):
    """A stream cut without re-encoding keeps earlier packets but an edit list hides them:
    frame 0 is the first frame shown (as PyAV shows it), not the first packet."""
    cut = tmp_path / "cut.mp4"
    subprocess.run(["ffmpeg", "-v", "error", "-y", "-ss", "1.0", "-i", str(numbers_mp4), "-c",
                    "copy", str(cut)], check=True)
    ref = [read_number(f) for f in pyav_rgb(cut)]
    r = media.VideoReader(cut)
    assert len(r) == len(ref)
    assert ref[0] != 0  # the cut really starts later
    assert [read_number(f) for f in r.read(np.arange(len(r)))] == ref


def test_crop_is_exact_slice(tmp_path):
    path = tmp_path / "moving.mp4"
    with media.VideoWriter(path, 128, 80) as w:
        w.write(moving_frames(12))
    r = media.VideoReader(path)
    full = r.read(np.arange(12))
    for x, y, cw, ch in [(0, 0, 128, 80), (1, 1, 7, 5), (33, 17, 64, 40), (127, 79, 1, 1),
                         (8, 2, 16, 2)]:
        got = r.read([3, 11, 3], crop=(x, y, cw, ch))
        np.testing.assert_array_equal(got, full[[3, 11, 3], y:y + ch, x:x + cw])
    crops = r.read_crops([4, 2], [(0, 0, 10, 6), (5, 7, 10, 6)])
    np.testing.assert_array_equal(crops[1], full[2, 7:13, 5:15])
    with pytest.raises(bsp_fast.VideoDecodeError, match="outside the 128x80 picture"):
        r.read([0], crop=(120, 0, 10, 10))


def test_errors_name_file_and_frame(tmp_path, numbers_mp4):
    with pytest.raises(bsp_fast.VideoDecodeError, match="missing.mp4: cannot open"):
        media.VideoReader(tmp_path / "missing.mp4")
    r = media.VideoReader(numbers_mp4)
    with pytest.raises(bsp_fast.VideoDecodeError,
                       match=r"numbers.mp4: frame 90 requested but file has 90 frames"):
        r.read([3, 90])
    with pytest.raises(bsp_fast.VideoDecodeError, match="frame -1 requested"):
        r.read([-1])
    assert read_number(r.read([10])[0]) == 10  # still usable after an error


def test_truncated_mp4(tmp_path, numbers_mp4):
    data = numbers_mp4.read_bytes()
    # Our writer puts the index (moov) last: cutting the file loses it entirely.
    cut = tmp_path / "cut.mp4"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(bsp_fast.VideoDecodeError, match="cut.mp4: cannot open"):
        media.VideoReader(cut)


@needs_ffmpeg
def test_truncated_faststart_mp4_names_the_frame(tmp_path, numbers_mp4):
    fast = tmp_path / "fast.mp4"
    subprocess.run(["ffmpeg", "-v", "error", "-y", "-i", str(numbers_mp4), "-c", "copy",
                    "-movflags", "+faststart", str(fast)], check=True)
    data = fast.read_bytes()
    cut = tmp_path / "fastcut.mp4"
    cut.write_bytes(data[: int(len(data) * 0.6)])
    r = media.VideoReader(cut)
    assert 0 < len(r) < 90
    assert read_number(r.read([0])[0]) == 0
    with pytest.raises(bsp_fast.VideoDecodeError, match=r"fastcut.mp4: frame 89 requested but "
                       r"file has \d+ frames \(truncated"):
        r.read([89])


def test_corrupted_mp4_names_the_frame(tmp_path, numbers_mp4):
    data = bytearray(numbers_mp4.read_bytes())
    start = data.find(b"mdat") + 4
    # Damage the middle of the stream (past the first keyframe's header).
    for i in range(start + 900, start + 1400, 7):
        data[i] ^= 0x5A
    bad = tmp_path / "bad.mp4"
    bad.write_bytes(bytes(data))
    r = media.VideoReader(bad)
    with pytest.raises(bsp_fast.VideoDecodeError, match=r"bad.mp4: frame \d+: decoding failed"):
        r.read(np.arange(len(r)))
