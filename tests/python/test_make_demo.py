"""``make demo`` prints the commands a user types: the console scripts, not ``python -m`` or
the build's interpreter."""
from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _console_scripts() -> dict:
    """[project.scripts] of pyproject.toml: {name: "module:function"}."""
    text = (ROOT / "pyproject.toml").read_text()
    block = text.split("[project.scripts]\n", 1)[1].split("\n[", 1)[0]
    return dict(re.findall(r'^(bsp-[\w-]+) = "([\w.:]+)"', block, re.M))



@pytest.mark.skipif(shutil.which("make") is None, reason="needs make")
def test_make_demo_prints_the_commands_a_user_types():
    scripts = _console_scripts()
    # -o install: do not install; PY=true: run nothing, only the echoed commands print
    r = subprocess.run(["make", "--no-print-directory", "-o", "install", "demo", "PY=true"],
                       cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    assert len(lines) == 5, r.stdout
    for line in lines:
        assert line.startswith("$ "), line
        assert "$(" not in line and "-m bsp_fast" not in line and "build/.python" not in line
        prog = line.split()[1]
        assert prog in scripts or line.startswith("$ python tools/"), line
    assert lines[0] == "$ bsp-synth demo-out/dataset --preset sample --force"
    assert lines[-1] == "$ bsp-eval --table demo-out/runs/lifting-lstm"
