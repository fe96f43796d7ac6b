"""Hostile and broken datasets (issue 15): each defect answered with a typed error naming the
file and the reason, exit 1 (bad data) or 2 (bad arguments), and no input ever destroyed."""
import csv
import io
import os

import pytest

import bsp_fast as bf
from bsp_fast import conversion as cv
from bsp_fast.media import ApngReader
from bsp_testdata import png_chunk as chunk, png_chunks as chunks, recording, write_dataset

pytestmark = pytest.mark.filterwarnings("ignore::UserWarning")  # tiny datasets: empty splits

U1 = "094b9fe1-babe-48d5-bd17-3ba3185690c5-0"


@pytest.fixture()
def ds(tmp_path):
    return write_dataset(tmp_path / "ds", recording(U1, range(20)))


def convert(ds, out, **kw):
    return cv.convert(ds, out, clip_length=10, media=False, **kw)


def cli(ds, out, *extra):
    return cv.main(["--no-media", "--quiet", "--clip-length", "10", str(ds), str(out), *extra])


# ---------------------------------------------------------------- item 8: outputs that are inputs

def test_force_never_overwrites_data_csv(ds, capsys):
    data_csv = ds / "data.csv"
    before = data_csv.read_bytes()
    with pytest.raises(ValueError, match=r"is the dataset's input .*data\.csv"):
        convert(ds, data_csv, force=True)
    assert cli(ds, data_csv, "--force") == 2
    assert "refusing to overwrite it" in capsys.readouterr().err
    assert data_csv.read_bytes() == before
    assert sorted(p.name for p in ds.iterdir()) == ["data.csv"]  # no temporary left


def test_force_never_overwrites_an_input_through_a_symlink(ds, tmp_path):
    data_csv = ds / "data.csv"
    before = data_csv.read_bytes()
    link = tmp_path / "out.h5"
    link.symlink_to(data_csv)
    with pytest.raises(ValueError, match="is the dataset's input"):
        convert(ds, link, force=True)
    hard = tmp_path / "hard.h5"
    os.link(data_csv, hard)  # the same file under another name
    with pytest.raises(ValueError, match="is the dataset's input"):
        convert(ds, hard, force=True)
    (ds / "config.yaml").write_text("fov: 70\n")
    with pytest.raises(ValueError, match=r"is the dataset's input .*config\.yaml"):
        convert(ds, ds / "sub" / ".." / "config.yaml", force=True)
    (ds / "clips").mkdir()
    video = ds / "clips" / "a.mp4"
    video.write_bytes(b"not really a video")
    with pytest.raises(ValueError, match=r"would replace the dataset's \.mp4 file"):
        convert(ds, video, force=True)
    assert data_csv.read_bytes() == before and video.read_bytes() == b"not really a video"
    # An HDF5 output inside the dataset directory stays allowed.
    assert convert(ds, ds / "clips.h5")["output"] == str(ds / "clips.h5")


# ---------------------------------------------------------------- item 13: config.yaml

@pytest.mark.parametrize("text,match", [
    ("- fov: 70\n", "expected a mapping .* at the top level, found a list"),
    ("just words\n", "expected a mapping .* at the top level, found a str"),
    ("camera_fov: wide\n", r"camera_fov must be a number of degrees in \(0, 180\), got 'wide'"),
    ("camera_fov: 0\n", r"camera_fov must be a number of degrees in \(0, 180\), got 0"),
    ("fov: 180\n", r"fov must be a number of degrees in \(0, 180\), got 180"),
    ("fov: -30.5\n", r"got -30\.5"),
    ("fov: .nan\n", r"got nan"),
    ("fov: true\n", r"got True"),
    ("fov: [70]\n", r"got \[70\]"),
    ("fov: 70\n  bad: [\n", "not a readable YAML file"),
])
def test_malformed_config_yaml_is_a_clear_error(ds, tmp_path, capsys, text, match):
    (ds / "config.yaml").write_text(text)
    with pytest.raises(cv.BadDataset, match=match) as e:
        convert(ds, tmp_path / "o.h5")
    assert str(ds / "config.yaml") in str(e.value)
    assert cli(ds, tmp_path / "o.h5") == 1  # bad data, not bad arguments
    err = capsys.readouterr().err
    assert "config.yaml" in err and "Traceback" not in err
    assert not list(tmp_path.glob("*.h5")) and not list(tmp_path.glob(".o.h5*"))


def test_good_config_yaml_still_gives_the_fov(ds, tmp_path):
    (ds / "config.yaml").write_text("camera_fov: 72.5\nother: [1, 2]\n")
    assert convert(ds, tmp_path / "o.h5")["settings"]["fov"] == 72.5
    (ds / "config.yaml").write_text("")  # empty: no FOV, the default
    assert convert(ds, tmp_path / "p.h5")["settings"]["fov_source"] == "default"
    # An explicit fov= needs no config.yaml look-up at all.
    (ds / "config.yaml").write_text("- not a mapping\n")
    assert convert(ds, tmp_path / "q.h5", fov=60)["settings"]["fov"] == 60.0


# ---------------------------------------------------------------- items 2, 9, 10: data.csv

def rewrite_cell(path, column, line, value):
    """Sets one cell of data.csv (`line` counts the header as line 1)."""
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    rows[line - 1][rows[0].index(column)] = value
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerows(rows)
    path.write_text(buf.getvalue())


@pytest.mark.parametrize("column,value,match", [
    ("frame.idx", "-3", "expected a frame index from 0 to 10000000, found '-3'"),
    ("frame.idx", "99999999999", "found '99999999999' \\(out of range: too large\\)"),
    ("camera.width", "0", "expected a picture size in pixels from 1 to 16384, found '0'"),
    ("camera.height", "-600", "expected a picture size in pixels from 1 to 16384, found '-600'"),
    ("camera.width", "1000000", "found '1000000' \\(out of range: too large\\)"),
    ("pedestrian.idx", "-1", "found '-1' \\(out of range: too small\\)"),
])
def test_out_of_range_integers_are_csv_errors_with_the_line(ds, tmp_path, capsys, column, value,
                                                            match):
    rewrite_cell(ds / "data.csv", column, 7, value)
    with pytest.raises(bf.CsvParseError, match=f"data.csv, line 7, column '{column}': .*{match}"):
        convert(ds, tmp_path / "o.h5")
    assert cli(ds, tmp_path / "o.h5") == 1
    assert "CsvParseError" in capsys.readouterr().err
    assert not list(tmp_path.glob("*.h5")) and not list(tmp_path.glob(".o.h5*"))


def test_cr_only_line_ends_are_refused(ds, tmp_path):
    path = ds / "data.csv"
    path.write_bytes(path.read_bytes().replace(b"\n", b"\r"))
    with pytest.raises(bf.CsvParseError, match="line 1 \\(header\\): .*CR-only line ends"):
        convert(ds, tmp_path / "o.h5")
    with pytest.raises(bf.CsvParseError, match="CR-only"):
        bf.read_csv(path)
    assert cli(ds, tmp_path / "o.h5") == 1


# ---------------------------------------------------------------- items 1, 7, 12: APNG files

@pytest.fixture(scope="module")
def media_ds(tmp_path_factory):
    from bsp_fast.synth import generate

    out = tmp_path_factory.mktemp("hostile") / "ds"
    generate(out, "sample", clips=2, frames=40, size="160x96", seed=2, workers=1,
             progress=False)
    return out


@pytest.fixture()
def mds(media_ds, tmp_path):
    import shutil

    return shutil.copytree(media_ds, tmp_path / "copy")


def apng_of(ds):
    return sorted((ds / "clips").glob("*.apng"))[0]


def ihdr(w, h):
    return chunk(b"IHDR", w.to_bytes(4, "big") + h.to_bytes(4, "big") + bytes([8, 3, 0, 0, 0]))


def convert_error(ds, tmp_path, capsys):
    with pytest.raises(bf.ApngError) as e:
        cv.convert(ds, tmp_path / "o.h5", clip_length=10, crop_size=16)
    assert cli_media(ds, tmp_path / "o.h5") == 1
    assert "ApngError" in capsys.readouterr().err
    assert not list(tmp_path.glob("*.h5")) and not list(tmp_path.glob(".o.h5*"))
    return str(e.value)


def cli_media(ds, out):
    return cv.main(["--quiet", "--clip-length", "10", "--crop-size", "16", str(ds), str(out)])


def test_second_ihdr_is_refused_naming_the_file(mds, tmp_path, capsys):
    apng = apng_of(mds)
    data = apng.read_bytes()
    fctl = [pos for pos, kind, _ in chunks(data) if kind == b"fcTL"]
    # A larger canvas announced before frame 5: frames are still drawn at 160x96.
    apng.write_bytes(data[:fctl[5]] + ihdr(4000, 4000) + data[fctl[5]:])
    msg = convert_error(mds, tmp_path, capsys)
    assert msg.startswith(f"{apng}: frame 4: second IHDR chunk at byte {fctl[5]}")
    with pytest.raises(bf.ApngError, match="second IHDR"):
        ApngReader(apng)


def test_apng_bomb_is_refused_before_allocating(mds, tmp_path, capsys):
    apng = apng_of(mds)
    sig = apng.read_bytes()[:8]
    apng.write_bytes(sig + ihdr(100000, 100000) + chunk(b"PLTE", bytes(768))
                     + chunk(b"IDAT", b"\x78\x9c\x03\x00") + chunk(b"IEND", b""))
    msg = convert_error(mds, tmp_path, capsys)
    assert msg == (f"{apng}: image size 100000x100000 exceeds the limit (16384 pixels a side, "
                   "67108864 pixels in all)")
    # Within the reader's limits but not what data.csv says: refused by the size check.
    apng.write_bytes(sig + ihdr(4096, 4096) + chunk(b"PLTE", bytes(768))
                     + chunk(b"IDAT", b"\x78\x9c\x03\x00") + chunk(b"IEND", b""))
    msg = convert_error(mds, tmp_path, capsys)
    assert msg.startswith(f"{apng}: expected an 8-bit palette-indexed 160x96 APNG")


def test_damaged_apng_names_the_real_cause(mds, tmp_path, capsys):
    apng = apng_of(mds)
    data = apng.read_bytes()
    fctl = [pos for pos, kind, _ in chunks(data) if kind == b"fcTL"]
    apng.write_bytes(data[:fctl[20] + 20])  # cut inside frame 20's fcTL
    msg = convert_error(mds, tmp_path, capsys)
    assert "after the animation's end" not in msg
    assert f"{apng}: video frame " in msg
    assert "cannot be decoded: the file is damaged at frame 20: truncated file" in msg


def test_delays_of_a_damaged_apng_with_an_absurd_frame_count(mds):
    apng = apng_of(mds)
    data = bytearray(apng.read_bytes())
    pos = next(p for p, kind, _ in chunks(data) if kind == b"acTL")
    data[pos + 8:pos + 12] = (20_000_000).to_bytes(4, "big")
    data[pos + 16:pos + 20] = chunk(b"acTL", bytes(data[pos + 8:pos + 16]))[-4:]
    data[-30] ^= 0x40  # damage near the end, so the frame count check does not run
    apng.write_bytes(bytes(data))
    with pytest.raises(bf.ApngError, match="acTL declares 20000000 frames, more than the limit"):
        ApngReader(apng).delays


# ---------------------------------------------------------------- item 6: files outside the dataset

def test_symlink_leading_out_of_the_dataset_is_refused(mds, tmp_path):
    import shutil

    mp4 = sorted((mds / "clips").glob("*.mp4"))[0]
    outside = tmp_path / "elsewhere" / "foreign.mp4"
    outside.parent.mkdir()
    shutil.move(mp4, outside)
    mp4.symlink_to(outside)
    with pytest.raises(bf.Error, match=f"media path .* resolves to {outside}, outside the "
                                       "dataset root .*refused, not opened"):
        cv.convert(mds, tmp_path / "o.h5", clip_length=10, crop_size=16)
    # A symlink that stays inside the dataset is fine.
    inside = mds / "clips" / "moved.mp4"
    shutil.move(outside, inside)
    mp4.unlink()
    mp4.symlink_to(inside)
    assert cv.convert(mds, tmp_path / "o.h5", clip_length=10, crop_size=16)["rows"] > 0


def test_hls_playlist_named_mp4_cannot_pull_in_other_files(mds, tmp_path):
    import shutil

    mp4 = sorted((mds / "clips").glob("*.mp4"))[0]
    outside = tmp_path / "foreign.mp4"
    shutil.copy(mp4, outside)
    mp4.write_text(f"#EXTM3U\n#EXT-X-TARGETDURATION:10\n#EXTINF:10.0,\n{outside}\n"
                   "#EXT-X-ENDLIST\n")
    with pytest.raises(bf.VideoDecodeError, match=f"{mp4}: cannot open as an MP4/MOV file"):
        cv.convert(mds, tmp_path / "o.h5", clip_length=10, crop_size=16)
    assert not (tmp_path / "o.h5").exists()


# ---------------------------------------------------------------- item 4: Ctrl-C and SIGTERM

class _InterruptingBars:
    """Stands in for the progress bars: the first poll while the C++ conversion runs raises
    KeyboardInterrupt in the main thread, as Ctrl-C would."""

    def __init__(self, show):
        pass

    def poll(self, stage, total, done):
        raise KeyboardInterrupt

    def close(self, completed):
        pass


def test_ctrl_c_stops_and_joins_the_conversion(mds, tmp_path, monkeypatch):
    import threading

    monkeypatch.setattr(cv.report, "ProgressBars", _InterruptingBars)
    with pytest.raises(KeyboardInterrupt):
        cv.convert(mds, tmp_path / "o.h5", clip_length=10, crop_size=16, threads=1,
                   progress=True)
    # Nothing of the conversion runs on after the interrupt, and nothing is left behind.
    assert not [t for t in threading.enumerate() if t.name == "bsp-convert"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["copy"]


def test_sigterm_removes_the_temporary_output(mds, tmp_path):
    import subprocess
    import sys

    script = f"""
import os, signal, sys
from bsp_fast import conversion as cv

class Bars:
    def __init__(self, show): pass
    def poll(self, stage, total, done): os.kill(os.getpid(), signal.SIGTERM)
    def close(self, completed): pass

cv.report.ProgressBars = Bars
cv.api._is_terminal = lambda stream: True
sys.exit(cv.main(["--clip-length", "10", "--crop-size", "16", "--threads", "1",
                  {str(mds)!r}, {str(tmp_path / "o.h5")!r}]))
"""
    p = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                       env={**os.environ}, timeout=120)
    assert p.returncode == 143, p.stderr
    assert "terminated; no output written" in p.stderr
    assert sorted(x.name for x in tmp_path.iterdir()) == ["copy"]


# ---------------------------------------------------------------- item 3: disk full while writing

def test_disk_full_is_a_clean_error_not_a_crash_at_exit(mds, tmp_path):
    import subprocess
    import sys

    # A file size limit makes every write past 200 kB fail (EFBIG), as a full disk would.
    script = f"""
import resource, signal, sys
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
resource.setrlimit(resource.RLIMIT_FSIZE, (200_000, 200_000))
from bsp_fast import conversion as cv
sys.exit(cv.main(["--quiet", "--clip-length", "10", "--crop-size", "64", "--threads", "1",
                  {str(mds)!r}, {str(tmp_path / "o.h5")!r}]))
"""
    p = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                       env={**os.environ}, timeout=120)
    assert p.returncode == 1, p.stderr  # not 139 (SIGSEGV in libhdf5's exit handler)
    assert "Hdf5Error" in p.stderr and ".o.h5.tmp-" in p.stderr
    assert sorted(x.name for x in tmp_path.iterdir()) == ["copy"]


# ---------------------------------------------------------------- item 5: data.csv truncated while mapped

def test_data_csv_truncated_while_read_is_an_error_not_sigbus(media_ds, tmp_path):
    import subprocess
    import sys

    lines = (media_ds / "data.csv").read_text().splitlines()
    big = tmp_path / "data.csv"
    big.write_text(lines[0] + "\n" + "\n".join(lines[1:] * 40) + "\n")  # about 35 MB
    script = f"""
import os, shutil, threading, time
import bsp_fast as bf
outcomes = []
for delay in (0.0, 0.02, 0.05, 0.1):
    shutil.copy({str(big)!r}, {str(tmp_path / "c.csv")!r})
    cut = threading.Thread(target=lambda: (time.sleep(delay), os.truncate({str(tmp_path / "c.csv")!r}, 1000)))
    cut.start()
    try:
        bf.read_csv({str(tmp_path / "c.csv")!r})
        outcomes.append("read")
    except bf.CsvParseError as e:
        outcomes.append("changed" if "the file changed while it was being read" in str(e) else "other")
    cut.join()
print(" ".join(outcomes))
"""
    p = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                       env={**os.environ}, timeout=300)
    assert p.returncode == 0, (p.returncode, p.stderr)  # today: -7 (SIGBUS)
    outcomes = p.stdout.split()
    assert len(outcomes) == 4 and set(outcomes) <= {"read", "changed", "other"}


# ---------------------------------------------------------------- item 11: bytes that are not UTF-8

def _put_bytes(path, line, column, value: bytes):
    """Sets one cell to raw bytes (latin-1 maps each byte to one character and back)."""
    rows = list(csv.reader(io.StringIO(path.read_bytes().decode("latin-1"), newline="")))
    rows[line - 1][rows[0].index(column)] = value.decode("latin-1")
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerows(rows)
    path.write_bytes(buf.getvalue().encode("latin-1"))


@pytest.mark.parametrize("column,value,match", [
    ("id", b"clip\xff\xfe", r"line 6, column 'id': value 'clip\\xff\\xfe' is not valid UTF-8"),
    ("pedestrian.model", b"walker\xc3", r"line 6, column 'pedestrian.model': value 'walker\\xc3'"),
    ("frame.idx", b"5\xff", r"line 6, column 'frame.idx': expected an integer, found '5\\xff'"),
])
def test_non_utf8_bytes_are_bad_input_with_line_and_column(ds, tmp_path, capsys, column, value,
                                                          match):
    _put_bytes(ds / "data.csv", 6, column, value)
    with pytest.raises(bf.CsvParseError, match=match):
        convert(ds, tmp_path / "o.h5")
    assert cli(ds, tmp_path / "o.h5") == 1  # bad input, not bad arguments
    err = capsys.readouterr().err
    assert "CsvParseError" in err and "line 6" in err
    assert not list(tmp_path.glob("*.h5")) and not list(tmp_path.glob(".o.h5*"))


# ---------------------------------------------------------------- item 13: --quiet is quiet

def test_ffmpeg_log_lines_do_not_reach_stderr_under_quiet(mds, tmp_path):
    import subprocess
    import sys

    mp4 = sorted((mds / "clips").glob("*.mp4"))[0]
    mp4.write_bytes(mp4.read_bytes()[:2000])  # truncated: FFmpeg logs "moov atom not found"
    p = subprocess.run([sys.executable, "-m", "bsp_fast", "convert", "--quiet", "--clip-length",
                        "10", "--crop-size", "16", str(mds), str(tmp_path / "o.h5")],
                       capture_output=True, text=True, env={**os.environ}, timeout=120)
    assert p.returncode == 1
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("bsp-convert: VideoDecodeError: "), p.stderr
    assert str(mp4) in lines[0]
