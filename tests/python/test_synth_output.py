"""What bsp-synth prints: plain progress lines in a log file (the count every interval), the
bar kept on a terminal, and the clips whose walker never enters the view."""
from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PYTHON = str(ROOT / "python")


def _env(**extra) -> dict:
    return dict(os.environ, PYTHONPATH=os.pathsep.join([PYTHON] + sys.path), **extra)


def test_synth_in_a_log_file_writes_plain_lines(tmp_path):
    log = tmp_path / "synth.log"
    with open(log, "w") as fh:
        r = subprocess.run([sys.executable, "-m", "bsp_fast", "synth", str(tmp_path / "ds"),
                            "--clips", "3", "--frames", "30", "--size", "160x60",
                            "--poses-only", "--workers", "2", "--seed", "3"],
                           stdout=fh, stderr=subprocess.STDOUT, env=_env(), timeout=600)
    text = log.read_text()
    assert r.returncode == 0, text
    assert "\r" not in text and "\x1b[" not in text and "it/s" not in text
    assert re.search(r"^\[ *\d+\.\d s\] clips 3/3 done$", text, re.M), text
    assert "wrote 3 clips" in text


def test_plain_lines_say_the_count_every_interval(capsys):
    from bsp_fast._plain_progress import PlainLines

    bar = PlainLines(3, "clips", interval=0.0)
    for _ in range(3):
        bar.update(1)
    bar.close()
    bar.close()
    lines = [ln.split("] ", 1)[1] for ln in capsys.readouterr().err.splitlines()]
    assert lines == ["clips 1/3", "clips 2/3", "clips 3/3 done"]


def test_synth_keeps_its_bar_on_a_terminal(monkeypatch):
    import importlib

    g = importlib.import_module("bsp_fast.synth.generate")  # the module, not the function

    monkeypatch.setattr("bsp_fast._plain_progress.is_terminal", lambda stream: True)
    assert type(g._progress_bar(3, True)).__name__ != "PlainLines"
    monkeypatch.setattr("bsp_fast._plain_progress.is_terminal", lambda stream: False)
    assert type(g._progress_bar(3, True)).__name__ == "PlainLines"
    assert getattr(g._progress_bar(3, False), "disable", False)  # progress=False: nothing


def test_synth_says_which_clips_have_no_recording(tmp_path):
    r = subprocess.run([sys.executable, "-m", "bsp_fast", "synth", str(tmp_path / "s4"),
                        "--seed", "4", "--clips", "9", "--frames", "60", "--size", "320x120",
                        "--workers", "1"], env=_env(), capture_output=True, text=True,
                       timeout=600)
    assert r.returncode == 0, r.stderr
    assert ("8 recordings: in 1 clip(s) the walker never enters the view (no rows, no media "
            "files)") in r.stdout.splitlines()
