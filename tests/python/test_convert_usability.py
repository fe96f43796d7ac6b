"""bsp-convert tells its user what it is doing and when the result is unusable: warnings
and --strict, honest help texts, progress bars that end at 100 % with sane rates."""
import io
import re
import time

import h5py
import pytest

from bsp_fast import conversion as cv
from bsp_fast.conversion.report import ProgressBars
from bsp_testdata import recording, write_dataset


def _uuid(k: int) -> str:
    return f"{k:08x}-0000-4000-8000-000000000000-0"


@pytest.fixture(scope="module")
def one_class(tmp_path_factory):
    """Six walkers, none crossing: every split has a single class."""
    rows = []
    for k in range(6):
        rows += recording(_uuid(k), range(30), seed=k)
    return write_dataset(tmp_path_factory.mktemp("ds") / "one_class", rows)


def test_single_class_and_empty_splits_are_warned_about(one_class, tmp_path):
    with pytest.warns(UserWarning, match="train split has a single class"):
        rep = cv.convert(one_class, tmp_path / "a.h5", clip_length=10, media=False)
    assert "train split has a single class: all 12 clips are not-crossing" in rep["warnings"]
    assert len(rep["warnings"]) == 3  # val and test too
    text = cv.format_report(rep)
    assert "WARNING: train split has a single class" in text and "--strict" in text
    with pytest.warns(UserWarning, match="no clips"):
        rep = cv.convert(one_class, tmp_path / "b.h5", clip_length=40, min_video_length=1,
                         media=False)
    assert {"train split has no clips", "val split has no clips",
            "test split has no clips"} <= set(rep["warnings"])


def test_strict_is_exit_code_1_and_writes_nothing(one_class, tmp_path, capsys):
    out = tmp_path / "c.h5"
    code = cv.main([str(one_class), str(out), "--clip-length", "10", "--no-media", "--strict"])
    err = capsys.readouterr().err
    assert code == 1 and not out.exists() and not list(tmp_path.iterdir())
    assert "unusable conversion (strict)" in err and "single class" in err
    assert cv.main([str(one_class), str(out), "--clip-length", "10", "--no-media"]) == 0
    printed = capsys.readouterr().out
    assert "WARNING: val split has a single class" in printed and out.exists()
    with pytest.raises(cv.UnusableConversion, match="test split has a single class"):
        cv.convert(one_class, tmp_path / "d.h5", clip_length=10, media=False, strict=True)


def test_help_has_no_none_defaults_and_explains_the_split(capsys):
    with pytest.raises(SystemExit):
        cv.main(["--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "(default: None)" not in text and "(default: False)" not in text
    assert "F of the clips LEFT AFTER the test split" in text and "16% val" in text
    assert "It does not balance the train split: add --balance" in text
    assert "--strict" in text


def test_val_frac_default_gives_the_documented_share(tmp_path):
    rows = []
    for k in range(20):  # 20 recordings x 3 clips = 60 clips
        rows += recording(_uuid(k), range(30), crossing_from=15 if k % 2 else None, seed=k)
    ds = write_dataset(tmp_path / "ds", rows)
    rep = cv.convert(ds, tmp_path / "o.h5", clip_length=10, media=False)
    n = {s: rep["splits"][s]["clips"] for s in ("train", "val", "test")}
    assert n == {"test": 12, "val": 9, "train": 39}  # 20 % of 60; 20 % of the 48 left
    with h5py.File(tmp_path / "o.h5") as f:
        assert f.attrs["val_frac"] == 0.2


def test_synth_help_states_the_preset_it_generates(capsys):
    from bsp_fast.synth import cli
    from bsp_fast.synth.config import PRESETS

    with pytest.raises(SystemExit):
        cli.main(["--help"])
    text = " ".join(capsys.readouterr().out.split())
    p = PRESETS["sample"]
    assert (f"sample: {p['number_of_clips']} clips x {p['clip_length_in_frames']} frames"
            in text)


def _final(text: str, desc: str) -> str:
    return [seg for seg in re.split(r"[\r\n]", text) if seg.startswith(desc)][-1]


def test_progress_bars_end_full_with_rates_of_the_real_speed():
    out = io.StringIO()
    bars = ProgressBars(True, file=out)
    bars.poll(0, 1000, 0)
    for done in range(0, 1001, 100):  # 1000 rows at ~10,000 rows/s
        bars.poll(0, 1000, done)
        time.sleep(0.01)
    bars.poll(6, 400, 290)  # first seen at 73 %: that part was not watched
    for done in (300, 310):
        time.sleep(0.05)
        bars.poll(6, 400, done)
    bars.close(completed=True)  # the stage finished between two polls
    text = out.getvalue()
    frames = _final(text, "cropping media frames")
    assert "100%" in frames and "400/400" in frames
    assert "100%" in _final(text, "reading data.csv")
    rate = float(re.search(r"([\d.]+)\s*frame/s", frames).group(1))
    assert rate < 5000  # not the ~millions of the 290 frames it did not watch
    unfinished = io.StringIO()
    b = ProgressBars(True, file=unfinished)
    b.poll(3, 50, 10)
    b.close(completed=False)  # an error: the bar stays where it was
    assert "100%" not in unfinished.getvalue()


def test_convert_progress_default_follows_the_terminal(one_class, tmp_path, monkeypatch):
    seen = {}
    real = cv.api._run

    def spy(csv, tmp, options, show_progress):
        seen["progress"] = show_progress
        return real(csv, tmp, options, False)

    monkeypatch.setattr(cv.api, "_run", spy)

    class Tty(io.StringIO):
        def isatty(self):
            return True

    monkeypatch.setattr("sys.stderr", Tty())
    cv.convert(one_class, tmp_path / "t.h5", clip_length=10, media=False)
    assert seen["progress"] is True
    monkeypatch.setattr("sys.stderr", io.StringIO())
    cv.convert(one_class, tmp_path / "n.h5", clip_length=10, media=False)
    assert seen["progress"] is False


def test_make_demo_converts_strictly():
    from pathlib import Path

    makefile = (Path(__file__).resolve().parents[2] / "Makefile").read_text()
    demo = makefile[makefile.index("\ndemo:"):].split("\n\n")[0]
    convert = [line for line in demo.splitlines() if "convert" in line]
    assert len(convert) == 1 and "--strict" in convert[0].split()
