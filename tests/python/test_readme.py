"""The README as a new user reads it: the quick start, copied verbatim, runs and yields
usable splits; the pip install section matches the build's real requirements."""
import os
import re
import subprocess
import sys
from pathlib import Path

import h5py

ROOT = Path(__file__).resolve().parents[2]
README = (ROOT / "README.md").read_text(encoding="utf-8")


def _section(title: str) -> str:
    start = README.index(f"## {title}\n")
    end = README.find("\n## ", start + 1)
    return README[start:end if end > 0 else None]


def test_quick_start_runs_verbatim_and_gives_both_classes_in_every_split(tmp_path):
    code = re.search(r"```python\n(.*?)```", _section("Quick start"), re.S).group(1)
    (tmp_path / "quick_start.py").write_text(code)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    r = subprocess.run([sys.executable, "quick_start.py"], cwd=tmp_path, env=env,
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    with h5py.File(tmp_path / "clips.h5") as f:
        for split in ("train", "val", "test"):
            counts = f[split].attrs["class_counts"].tolist()
            assert min(counts) > 0, (split, counts)  # clips of both classes


def test_pip_install_section_matches_the_build():
    section = _section("Install with pip")
    apt = [line for line in section.splitlines() if "apt-get install" in line]
    assert len(apt) == 1  # one line to copy
    wanted = set(apt[0].split("install", 1)[1].split()) - {"-y"}
    script = (ROOT / "tools" / "install-deps.sh").read_text()
    listed = set(re.search(r"APT_PACKAGES=\((.*?)\)", script, re.S).group(1).split())
    assert wanted <= listed, wanted - listed
    assert "doctest-dev" not in wanted  # pip install . does not build the C++ tests
    assert {"libhdf5-dev", "libavcodec-dev", "libopencv-dev", "cmake"} <= wanted
    pyproject = (ROOT / "pyproject.toml").read_text()
    torch_extra = re.search(r"^torch = \[(.*?)\]", pyproject, re.M | re.S).group(1)
    assert "==" not in torch_extra and "lightning" in torch_extra
    assert "pip install '.[torch]'" in section
