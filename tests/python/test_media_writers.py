"""VideoWriter and ApngWriter, checked with independent decoders (PyAV, Pillow)."""
from __future__ import annotations

import hashlib
import struct

import numpy as np
import pytest

from bsp_fast import media

av = pytest.importorskip("av")
Image = pytest.importorskip("PIL.Image")

W, H = 96, 64


def number_frames(n: int, w: int = W, h: int = H) -> np.ndarray:
    """Frame k shows k in binary: 8 big black/white blocks (robust to H.264 at 1 Mb/s)."""
    frames = np.zeros((n, h, w, 3), np.uint8)
    bw = w // 8
    for k in range(n):
        for bit in range(8):
            if (k >> bit) & 1:
                frames[k, :, bit * bw:(bit + 1) * bw] = 255
        frames[k, : h // 4, :, 0] = (k * 37) % 256  # some colour that changes too
    return frames


def read_number(rgb: np.ndarray) -> int:
    h, w = rgb.shape[:2]
    bw = w // 8
    grey = rgb[h // 4:, :, 1].astype(int)
    return sum(1 << b for b in range(8) if grey[:, b * bw + 2:(b + 1) * bw - 2].mean() > 127)


def write_video(path, frames, **kw):
    with media.VideoWriter(path, frames.shape[2], frames.shape[1], **kw) as w:
        w.write(frames)


def test_video_stream_properties(tmp_path):
    path = tmp_path / "clip.mp4"
    write_video(path, number_frames(45), fps=30)
    with av.open(str(path)) as c:
        s = c.streams.video[0]
        assert s.codec_context.name == "h264"
        assert s.codec_context.profile == "High"
        assert s.codec_context.pix_fmt == "yuv420p"
        assert (s.width, s.height) == (W, H)
        assert s.average_rate == 30
        assert s.frames == 45
        assert sum(1 for _ in c.decode(video=0)) == 45
    assert not list(tmp_path.glob("*.tmp-*"))


def test_video_frame_index_contract_pyav(tmp_path):
    path = tmp_path / "numbers.mp4"
    write_video(path, number_frames(80))
    with av.open(str(path)) as c:
        got = [read_number(f.to_ndarray(format="rgb24")) for f in c.decode(video=0)]
    assert got == list(range(80))


def test_video_is_deterministic(tmp_path):
    frames = number_frames(40)
    write_video(tmp_path / "a.mp4", frames)
    write_video(tmp_path / "b.mp4", frames)
    assert (tmp_path / "a.mp4").read_bytes() == (tmp_path / "b.mp4").read_bytes()


def test_video_bytes_do_not_depend_on_the_run(tmp_path):
    # Before x264 was kept off its AVX-512 code, 2-4 of 40 such writes in one process gave
    # other bytes on an avx512 machine (and a dataset bsp-synth made twice differed in one
    # MP4). Noise frames at a height that is not a multiple of 16.
    frames = (np.random.default_rng(0).random((30, 60, 160, 3)) * 255).astype(np.uint8)
    digests = set()
    for _ in range(60):
        write_video(tmp_path / "n.mp4", frames)
        # (a digest: the freed bytes are heap that x264's next buffers reuse, as in a run)
        digests.add(hashlib.sha256((tmp_path / "n.mp4").read_bytes()).hexdigest())
    assert len(digests) == 1


def test_video_single_frame_and_batches(tmp_path):
    frames = number_frames(6)
    with media.VideoWriter(tmp_path / "c.mp4", W, H) as w:
        w.write(frames[0])
        w.write(frames[1:])
        assert w.frames_written == 6
    with av.open(str(tmp_path / "c.mp4")) as c:
        assert sum(1 for _ in c.decode(video=0)) == 6


def test_video_interrupted_leaves_no_file(tmp_path):
    path = tmp_path / "broken.mp4"
    with pytest.raises(RuntimeError, match="boom"):
        with media.VideoWriter(path, W, H) as w:
            w.write(number_frames(3))
            raise RuntimeError("boom")
    assert list(tmp_path.iterdir()) == []


def test_video_writer_validates(tmp_path):
    with pytest.raises(ValueError, match="even"):
        media.VideoWriter(tmp_path / "x.mp4", 95, 64)
    with pytest.raises(ValueError, match="preset must be one of"):
        media.VideoWriter(tmp_path / "x.mp4", W, H, preset="warp")
    w = media.VideoWriter(tmp_path / "x.mp4", W, H)
    with pytest.raises(ValueError, match=r"expected shape \(64, 96, 3\)"):
        w.write(np.zeros((64, 96), np.uint8))
    with pytest.raises(ValueError, match="uint8"):
        w.write(np.zeros((64, 96, 3), np.float32))


# ---------------------------------------------------------------- APNG


def tag_frames(n: int, w: int = 80, h: int = 50, seed: int = 0) -> np.ndarray:
    """Road, sky and a pedestrian (tag 4) walking; static background like the recorder."""
    frames = np.empty((n, h, w), np.uint8)
    base = np.full((h, w), 13, np.uint8)
    base[h // 2:] = 7
    base[h // 2:, : w // 5] = 8
    for k in range(n):
        f = base.copy()
        x = 3 + 2 * k
        f[h // 3: h // 3 + 15, x % (w - 6): x % (w - 6) + 5] = 4
        frames[k] = f
    return frames


def chunks(path):
    data = open(path, "rb").read()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    pos, out = 8, []
    while pos < len(data):
        (n,) = struct.unpack(">I", data[pos:pos + 4])
        out.append((data[pos + 4:pos + 8].decode(), data[pos + 8:pos + 8 + n]))
        pos += 12 + n
    return out


def pillow_frames(path):
    im = Image.open(path)
    frames, durations = [], []
    for i in range(im.n_frames):
        im.seek(i)
        assert im.mode == "P"
        frames.append(np.array(im))
        durations.append(im.info["duration"])
    return np.stack(frames), durations


def test_apng_pillow_reads_exact_tags(tmp_path):
    path = tmp_path / "seg.apng"
    tags = tag_frames(12)
    with media.ApngWriter(path, 80, 50) as w:
        w.write(tags)
    got, durations = pillow_frames(path)
    np.testing.assert_array_equal(got, tags)
    assert durations == pytest.approx([1000 / 30] * 12)
    im = Image.open(path)
    pal = np.array(im.getpalette()[: 23 * 3], np.uint8).reshape(23, 3)
    np.testing.assert_array_equal(pal, media.CITYSCAPES_PALETTE)


def test_apng_layout_is_sub_rectangles(tmp_path):
    path = tmp_path / "seg.apng"
    with media.ApngWriter(path, 80, 50) as w:
        w.write(tag_frames(5))
    cs = chunks(path)
    names = [c[0] for c in cs]
    assert names[:4] == ["IHDR", "PLTE", "acTL", "fcTL"]
    assert names[-1] == "IEND" and names.count("IDAT") == 1 and names.count("fdAT") == 4
    ihdr = struct.unpack(">IIBBBBB", cs[0][1])
    assert ihdr == (80, 50, 8, 3, 0, 0, 0)
    assert struct.unpack(">II", cs[2][1]) == (5, 0)
    fctl = [struct.unpack(">IIIIIHHBB", d) for n, d in cs if n == "fcTL"]
    assert fctl[0][1:5] == (80, 50, 0, 0)
    for seq_, fw, fh, x, y, num, den, dispose, blend in fctl[1:]:
        assert fw < 80 and fh < 50 and (num, den) == (1, 30) and (dispose, blend) == (0, 0)
    seqs = [struct.unpack(">I", d[:4])[0] for n, d in cs if n in ("fcTL", "fdAT")]
    assert seqs == list(range(len(seqs)))


def test_apng_drop_duplicates_keeps_timing(tmp_path):
    tags = tag_frames(10)
    tags[3] = tags[2]
    tags[4] = tags[2]
    tags[9] = tags[8]
    path = tmp_path / "dd.apng"
    with media.ApngWriter(path, 80, 50, drop_duplicates=True) as w:
        w.write(tags)
        assert w.frames_written == 10
    got, durations = pillow_frames(path)
    keep = [0, 1, 2, 5, 6, 7, 8]
    np.testing.assert_array_equal(got, tags[keep])
    assert durations == pytest.approx([1000 / 30 * d for d in (1, 1, 3, 1, 1, 1, 2)])
    # Without dropping, an unchanged frame is stored as a 1x1 repeat and every frame stays.
    with media.ApngWriter(tmp_path / "all.apng", 80, 50) as w:
        w.write(tags)
    got, durations = pillow_frames(tmp_path / "all.apng")
    np.testing.assert_array_equal(got, tags)


def test_apng_custom_palette_and_fps(tmp_path):
    pal = np.arange(6 * 3, dtype=np.uint8).reshape(6, 3) * 10
    tags = (tag_frames(3) % 6).astype(np.uint8)
    with media.ApngWriter(tmp_path / "p.apng", 80, 50, palette=pal, fps=25) as w:
        w.write(tags)
    im = Image.open(tmp_path / "p.apng")
    assert im.getpalette()[:18] == pal.ravel().tolist()
    got, durations = pillow_frames(tmp_path / "p.apng")
    np.testing.assert_array_equal(got, tags)
    assert durations == pytest.approx([40.0] * 3)


def test_apng_errors_and_cleanup(tmp_path):
    with pytest.raises(ValueError, match="palette"):
        media.ApngWriter(tmp_path / "x.apng", 8, 8, palette=np.zeros((300, 3), np.uint8))
    w = media.ApngWriter(tmp_path / "empty.apng", 8, 8)
    with pytest.raises(media_error(), match="no frames"):
        w.close()
    del w
    with pytest.raises(KeyError):
        with media.ApngWriter(tmp_path / "y.apng", 8, 8) as w:
            w.write(np.zeros((8, 8), np.uint8))
            raise KeyError("stop")
    assert list(tmp_path.iterdir()) == []


def media_error():
    import bsp_fast
    return bsp_fast.ApngError
