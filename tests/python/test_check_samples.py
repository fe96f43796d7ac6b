"""bsp-check on generated samples: the documented sample's output blocks are what the
command prints, generated samples check clean, warnings pass unless --strict."""
from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PYTHON = str(ROOT / "python")


def _env(**extra) -> dict:
    return dict(os.environ, PYTHONPATH=os.pathsep.join([PYTHON] + sys.path), **extra)


def _normalise(text: str) -> str:
    """Output with its time values (``0.21 s``) masked."""
    return re.sub(r"\b\d+\.\d+ s\b", "#.## s", text)


@pytest.fixture(scope="module")
def sample_ds(tmp_path_factory):
    """The documented sample, made as the README makes it: ``bsp-synth sample-ds``."""
    root = tmp_path_factory.mktemp("readme")
    r = subprocess.run([sys.executable, "-m", "bsp_fast", "synth", "sample-ds", "--quiet",
                        "--workers", "2"], cwd=root, env=_env(), capture_output=True,
                       text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    return root


def test_documented_sample_output_blocks_match_their_commands(sample_ds):
    """The output blocks shown for the documented sample (the README had one; issue 54
    moved it to docs/check.md) are what their commands print now."""
    runnable = {"$ bsp-check sample-ds": ["check", "sample-ds"]}
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    # every output block of the README is regenerated here: a new one needs its command
    assert set(re.findall(r"```\n(\$ [^\n]*)\n", readme)) <= set(runnable)
    page = (ROOT / "docs" / "check.md").read_text(encoding="utf-8")
    blocks = [(cmd, shown) for cmd, shown in re.findall(r"```\n(\$ [^\n]*)\n(.*?)```", page,
                                                         re.S) if cmd in runnable]
    assert [cmd for cmd, _ in blocks] == list(runnable), [cmd for cmd, _ in blocks]
    for cmd, shown in blocks:
        r = subprocess.run([sys.executable, "-m", "bsp_fast", *runnable[cmd]], cwd=sample_ds,
                           env=_env(), capture_output=True, text=True, timeout=600)
        assert _normalise(r.stdout) == _normalise(shown), (cmd, r.stdout)
        assert r.returncode == 0


def test_generated_samples_check_clean(sample_ds, tmp_path, capsys):
    from bsp_fast.check import check_dataset
    from bsp_fast.check.cli import main
    from bsp_fast.synth import generate

    rep = check_dataset(sample_ds / "sample-ds")
    assert rep["findings"] == [] and rep["clean"]
    # seed 4: clip 8 has no row (its walker never enters the view): no media for it, and
    # the occlusion warnings of other clips pass without --strict
    s = generate(tmp_path / "s4", "sample", seed=4, clips=9, frames=60, size="320x120",
                 workers=2, progress=False)
    assert s["clips"] == 9 and s["recordings"] == 8
    rep = check_dataset(tmp_path / "s4")
    assert [f for f in rep["findings"] if f["kind"] == "unreferenced_media"] == []
    assert rep["counts"]["error"] == 0
    media = sorted(p.name for p in (tmp_path / "s4" / "clips").iterdir())
    assert len(media) == 2 * 8 and not any(p.startswith(s["ids"][8][:36]) for p in media)
    assert main([str(tmp_path / "s4"), "--quiet"]) == 0
    capsys.readouterr()


def test_warnings_pass_unless_strict(sample_ds, tmp_path, capsys):
    from bsp_fast.check.cli import main

    ds = tmp_path / "ds"
    shutil.copytree(sample_ds / "sample-ds", ds)
    (ds / "clips" / "stray-0.mp4").write_bytes(b"x")  # a warning: unreferenced media
    assert main([str(ds), "--quiet"]) == 0
    assert capsys.readouterr().out == ("Result: no errors, 1 warning(s) (--strict fails on "
                                       "warnings)\n")
    assert main([str(ds), "--quiet", "--strict"]) == 1
    (ds / "clips" / sorted(p.name for p in (ds / "clips").glob("*.apng"))[0]).unlink()
    assert main([str(ds), "--quiet"]) == 1  # an error fails either way
    assert capsys.readouterr().out.endswith("Result: 2 problem(s) found\n")
