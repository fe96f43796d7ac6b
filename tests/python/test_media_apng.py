"""ApngReader against Pillow and FFmpeg's APNG decoder, drop-duplicate timing, errors."""
from __future__ import annotations

import shutil
import struct
import subprocess
import zlib

import numpy as np
import pytest

import bsp_fast
from bsp_fast import media
from test_media_writers import chunks, tag_frames

Image = pytest.importorskip("PIL.Image")
needs_ffmpeg = pytest.mark.skipif(shutil.which("ffmpeg") is None, reason="ffmpeg CLI missing")

NONE, BACKGROUND, PREVIOUS = 0, 1, 2
SOURCE, OVER = 0, 1


def pillow_read(path):
    """Pillow's composited frames: palette INDICES for mode P (np.array of a P image gives
    the indices, never the colours), pixel values otherwise."""
    im = Image.open(path)
    out = []
    for i in range(im.n_frames):
        im.seek(i)
        out.append(np.array(im))
    return im.mode, np.stack(out)


def pillow_save(path, frames, mode, **kw):
    ims = [Image.fromarray(f, mode) for f in frames]
    ims[0].save(path, save_all=True, append_images=ims[1:], **kw)


def sprite_rgba(n=8, w=40, h=30, seed=1):
    """Moving opaque and fully transparent blocks (alpha 0 or 255 only)."""
    rng = np.random.default_rng(seed)
    frames = np.zeros((n, h, w, 4), np.uint8)
    frames[..., :3] = rng.integers(0, 256, 3, dtype=np.uint8)
    frames[..., 3] = 255
    for k in range(n):
        frames[k, 5:15, 2 + 3 * k:12 + 3 * k] = (*rng.integers(0, 256, 3), 255)
        frames[k, 18:26, 30 - 2 * k:36 - 2 * k, 3] = 0
    return frames


@pytest.mark.parametrize("disposal,blend", [
    (NONE, SOURCE), (BACKGROUND, SOURCE), (PREVIOUS, SOURCE), (NONE, OVER), (BACKGROUND, OVER),
    ([NONE, PREVIOUS, BACKGROUND, NONE, PREVIOUS, NONE, BACKGROUND, NONE],
     [SOURCE, SOURCE, OVER, SOURCE, SOURCE, OVER, SOURCE, OVER]),
])
def test_rgba_equals_pillow(tmp_path, disposal, blend):
    path = tmp_path / "rgba.apng"
    pillow_save(path, sprite_rgba(), "RGBA", disposal=disposal, blend=blend, duration=40)
    mode, ref = pillow_read(path)
    r = media.ApngReader(path)
    assert mode == "RGBA" and r.channels == 4 and not r.indexed
    np.testing.assert_array_equal(r.read(np.arange(len(r))), ref)
    assert r.delays == pytest.approx([0.04] * len(r))


def patch_ops(path, disposal, blend):
    """Rewrites every fcTL's dispose_op/blend_op (and its CRC): any combination of ops on
    the same pixels, including ones Pillow's writer cannot produce."""
    data = bytearray(path.read_bytes())
    pos, frame = 8, 0
    for name, body in chunks(path):
        if name == "fcTL":
            data[pos + 8 + 24] = disposal[frame]
            data[pos + 8 + 25] = blend[frame]
            crc = zlib.crc32(bytes(data[pos + 4:pos + 8 + len(body)]))
            data[pos + 8 + len(body):pos + 12 + len(body)] = struct.pack(">I", crc)
            frame += 1
        pos += 12 + len(body)
    path.write_bytes(bytes(data))


# Pillow's reader restores the wrong canvas for PREVIOUS after OVER on the same frame
# (it composites OVER into its saved copy), so those two never meet on one frame here.
OPS = [
    ([NONE] * 8, [SOURCE] * 8),
    ([BACKGROUND] * 8, [SOURCE] * 8),
    ([PREVIOUS] * 8, [SOURCE] * 8),
    ([NONE] * 8, [OVER] * 8),
    ([BACKGROUND] * 8, [OVER] * 8),
    ([NONE, PREVIOUS, BACKGROUND, NONE, PREVIOUS, NONE, BACKGROUND, NONE],
     [SOURCE, SOURCE, OVER, SOURCE, SOURCE, OVER, OVER, OVER]),
]


@pytest.mark.parametrize("disposal,blend", OPS)
def test_palette_equals_pillow(tmp_path, disposal, blend):
    tags = tag_frames(8, w=40, h=30)
    tags[3, :4, :4] = 0  # index 0 is transparent below: OVER must keep the canvas there
    path = tmp_path / "pal.apng"
    pal = media.CITYSCAPES_PALETTE.ravel().tolist()
    ims = [Image.fromarray(t, "P") for t in tags]
    for im in ims:
        im.putpalette(pal)
    ims[0].save(path, save_all=True, append_images=ims[1:], duration=33, transparency=0)
    patch_ops(path, disposal, blend)
    mode, ref = pillow_read(path)
    r = media.ApngReader(path)
    assert mode == "P" and r.indexed and r.palette.shape[1] == 3
    assert list(r.dispose_ops) == disposal[:len(r)]
    np.testing.assert_array_equal(r.read(np.arange(len(r))), ref)


# Pillow's writer itself cannot save palette frames after a BACKGROUND (or first-frame
# PREVIOUS) disposal, hence patch_ops above; these combinations it can write.
@pytest.mark.parametrize("disposal,blend", [
    (NONE, OVER),
    ([NONE, PREVIOUS, NONE, PREVIOUS, PREVIOUS, NONE, NONE, NONE], SOURCE),
])
def test_palette_pillow_written_ops(tmp_path, disposal, blend):
    tags = tag_frames(8, w=40, h=30)
    tags[3, :4, :4] = 0
    path = tmp_path / "pal.apng"
    ims = [Image.fromarray(t, "P") for t in tags]
    for im in ims:
        im.putpalette(media.CITYSCAPES_PALETTE.ravel().tolist())
    ims[0].save(path, save_all=True, append_images=ims[1:], duration=33, transparency=0,
                disposal=disposal, blend=blend)
    _, ref = pillow_read(path)
    np.testing.assert_array_equal(media.ApngReader(path).read(np.arange(len(ref))), ref)


@pytest.mark.parametrize("disposal,blend", OPS)
def test_rgba_patched_ops_equal_pillow(tmp_path, disposal, blend):
    path = tmp_path / "rgba.apng"
    pillow_save(path, sprite_rgba(), "RGBA", duration=40)
    patch_ops(path, disposal, blend)
    _, ref = pillow_read(path)
    np.testing.assert_array_equal(media.ApngReader(path).read(np.arange(8)), ref)


def test_our_drop_duplicate_files(tmp_path):
    tags = tag_frames(30)
    for k in (4, 5, 6, 12, 29):
        tags[k] = tags[k - 1]
    path = tmp_path / "dd.apng"
    with media.ApngWriter(path, 80, 50, drop_duplicates=True) as w:
        w.write(tags)
    _, ref = pillow_read(path)
    r = media.ApngReader(path)
    assert len(r) == 25
    np.testing.assert_array_equal(r.read(np.arange(len(r))), ref)
    np.testing.assert_array_equal(np.stack(list(r)), ref)
    # Video frame k -> APNG frame shown at k / 30 s recovers every written frame.
    mapping = r.video_to_apng_frames(30, 30)
    assert mapping[:8].tolist() == [0, 1, 2, 3, 3, 3, 3, 4]
    np.testing.assert_array_equal(r.read(mapping), tags)
    assert media.video_to_apng_frames(path, 32, 30)[-2:].tolist() == [-1, -1]
    # Any order, repeats, backwards.
    idx = [24, 0, 13, 13, 2, 24]
    np.testing.assert_array_equal(r.read(idx), ref[idx])


def test_long_drop_keeps_exact_timing(tmp_path):
    tags = np.repeat(tag_frames(2, w=16, h=8), [3, 70000], axis=0)
    path = tmp_path / "long.apng"
    w = media.ApngWriter(path, 16, 8, fps=1, drop_duplicates=True)
    for start in range(0, len(tags), 10000):
        w.write(tags[start:start + 10000])
    w.close()
    r = media.ApngReader(path)
    assert r.delays.sum() == pytest.approx(70003.0)
    mapping = r.video_to_apng_frames(70003, 1)
    np.testing.assert_array_equal(r.read(mapping[[0, 2, 3, 65000, 70002]]),
                                  tags[[0, 2, 3, 65000, 70002]])


@needs_ffmpeg
@pytest.mark.parametrize("pix_fmt", ["rgba", "rgb24"])
def test_ffmpeg_written_equals_pillow_and_ffmpeg(tmp_path, pix_fmt):
    frames = sprite_rgba(10)
    # Partial alpha too: checked against FFmpeg's own decoder, which blends like the spec.
    frames[6:, 2:8, 2:8, 3] = 100
    if pix_fmt == "rgb24":
        frames = np.ascontiguousarray(frames[..., :3])
    n, h, w, c = frames.shape
    path = tmp_path / "ff.apng"
    subprocess.run(["ffmpeg", "-v", "error", "-y", "-f", "rawvideo", "-pix_fmt", pix_fmt,
                    "-s", f"{w}x{h}", "-r", "25", "-i", "-", "-plays", "0", "-f", "apng",
                    str(path)], input=frames.tobytes(), check=True)
    r = media.ApngReader(path)
    ours = r.read(np.arange(len(r)))
    dec = subprocess.run(["ffmpeg", "-v", "error", "-i", str(path), "-f", "rawvideo",
                          "-pix_fmt", pix_fmt, "-"], capture_output=True, check=True).stdout
    np.testing.assert_array_equal(ours, np.frombuffer(dec, np.uint8).reshape(ours.shape))
    np.testing.assert_array_equal(ours, frames)
    if pix_fmt == "rgb24":
        _, ref = pillow_read(path)
        np.testing.assert_array_equal(ours, ref)
    else:
        # Pillow mixes alpha differently for partial alpha; equal where alpha is 0 or 255.
        _, ref = pillow_read(path)
        binary = (frames[..., 3] == 0) | (frames[..., 3] == 255)
        np.testing.assert_array_equal(ours[binary], ref[binary])


@needs_ffmpeg
def test_ffmpeg_written_palette(tmp_path):
    tags = tag_frames(6, w=40, h=30)
    pal = media.CITYSCAPES_PALETTE.ravel().tolist()
    for k, t in enumerate(tags):
        im = Image.fromarray(t, "P")
        im.putpalette(pal)
        im.save(tmp_path / f"f{k:03d}.png")
    path = tmp_path / "ffpal.apng"
    subprocess.run(["ffmpeg", "-v", "error", "-y", "-i", str(tmp_path / "f%03d.png"),
                    "-plays", "0", "-f", "apng", str(path)], check=True)
    r = media.ApngReader(path)
    mode, ref = pillow_read(path)
    assert r.indexed and mode == "P"
    ours = r.read(np.arange(len(r)))
    np.testing.assert_array_equal(ours, ref)
    # FFmpeg may renumber the palette; the colours must be those written.
    np.testing.assert_array_equal(r.palette[ours], media.CITYSCAPES_PALETTE[tags])


def test_plain_png_and_grey(tmp_path):
    img = (np.arange(30 * 20) % 251).astype(np.uint8).reshape(20, 30)
    Image.fromarray(img, "L").save(tmp_path / "g.png")
    r = media.ApngReader(tmp_path / "g.png")
    assert len(r) == 1 and r.channels == 1
    np.testing.assert_array_equal(r[0], img)
    rgb = np.dstack([img, img[::-1], 255 - img])
    Image.fromarray(rgb, "RGB").save(tmp_path / "c.png", optimize=True)  # Paeth etc.
    np.testing.assert_array_equal(media.ApngReader(tmp_path / "c.png")[0], rgb)


# ---------------------------------------------------------------- errors


@pytest.fixture()
def seg_file(tmp_path):
    path = tmp_path / "seg.apng"
    with media.ApngWriter(path, 80, 50) as w:
        w.write(tag_frames(40))
    return path


def test_index_past_the_end(seg_file):
    r = media.ApngReader(seg_file)
    with pytest.raises(bsp_fast.ApngError,
                       match=r"seg.apng: frame 57 requested but file has 40 frames"):
        r.read([1, 57])
    with pytest.raises(bsp_fast.ApngError, match="frame -2 requested"):
        r.read([-2])


def test_bad_crc_names_chunk_and_frame(tmp_path, seg_file):
    data = bytearray(seg_file.read_bytes())
    pos, frame = 8, -1
    for name, body in chunks(seg_file):
        if name == "fcTL":
            frame += 1
        if name == "fdAT" and frame == 12:
            data[pos + 8 + len(body) // 2] ^= 0x01
            break
        pos += 12 + len(body)
    bad = tmp_path / "bad.apng"
    bad.write_bytes(bytes(data))
    r = media.ApngReader(bad)
    assert len(r) == 40
    assert r.read(np.arange(12)).shape == (12, 50, 80)  # earlier frames still readable
    with pytest.raises(bsp_fast.ApngError, match=r"bad.apng: frame 12: bad CRC in chunk fdAT"):
        r.read([12])
    with pytest.raises(bsp_fast.ApngError,
                       match=r"frame 30 cannot be decoded: frame 12: bad CRC in chunk fdAT"):
        r.read([30])


def test_truncated_apng(tmp_path, seg_file):
    data = seg_file.read_bytes()
    cut = tmp_path / "cut.apng"
    cut.write_bytes(data[: len(data) * 2 // 3])
    r = media.ApngReader(cut)
    with pytest.raises(bsp_fast.ApngError,
                       match=r"cut.apng: frame 39 cannot be decoded: frame \d+: truncated file"):
        r.read([39])
    assert r.read([0]).shape == (1, 50, 80)
    cut.write_bytes(data[:20])
    with pytest.raises(bsp_fast.ApngError, match="cut.apng: truncated file"):
        media.ApngReader(cut)


def corrupt_zlib(path, out, frame: int):
    """Flips bits inside frame `frame`'s zlib data and fixes the chunk CRC, so only the
    zlib stream's own checks can notice."""
    data = bytearray(path.read_bytes())
    pos, current = 8, -1
    for name, body in chunks(path):
        if name == "fcTL":
            current += 1
        if name in ("IDAT", "fdAT") and current == frame:
            new = bytearray(body)
            new[len(new) // 2] ^= 0xFF
            crc = zlib.crc32(name.encode() + bytes(new))
            data[pos + 8:pos + 8 + len(body)] = new
            data[pos + 8 + len(body):pos + 12 + len(body)] = struct.pack(">I", crc)
            break
        pos += 12 + len(body)
    out.write_bytes(bytes(data))


@pytest.mark.parametrize("frame", [0, 20])
def test_corrupt_zlib_data(tmp_path, seg_file, frame):
    bad = tmp_path / "zlib.apng"
    corrupt_zlib(seg_file, bad, frame)
    r = media.ApngReader(bad)
    pattern = rf"zlib.apng: frame {frame}: .*(zlib|short|long)"
    with pytest.raises(bsp_fast.ApngError, match=pattern):
        r.read(np.arange(40))  # decoded ahead on a second thread
    with pytest.raises(bsp_fast.ApngError, match=pattern):
        r.read([frame])
    np.testing.assert_array_equal(r.read(np.arange(frame)), tag_frames(40)[:frame])


def test_unsupported_files(tmp_path):
    Image.new("I;16", (4, 4)).save(tmp_path / "d16.png")
    with pytest.raises(bsp_fast.ApngError, match="d16.png: unsupported bit depth 16"):
        media.ApngReader(tmp_path / "d16.png")
    with pytest.raises(bsp_fast.ApngError, match="nothere.apng: cannot open"):
        media.ApngReader(tmp_path / "nothere.apng")
    (tmp_path / "text.apng").write_text("hello, not a png")
    with pytest.raises(bsp_fast.ApngError, match="not a PNG file"):
        media.ApngReader(tmp_path / "text.apng")
