"""The README as a new user reads it: the quick start, copied verbatim into an empty
folder, runs twice and yields usable splits; the install section matches the build's real
requirements."""
import os
import re
import subprocess
import sys
from pathlib import Path

import h5py
import pytest

ROOT = Path(__file__).resolve().parents[2]
README = (ROOT / "README.md").read_text(encoding="utf-8")
COMMANDS = ("synth", "convert", "train", "eval", "predict", "reproduce", "preview", "check",
            "cache", "interop")


def _section(title: str) -> str:
    start = README.index(f"## {title}\n")
    end = README.find("\n## ", start + 1)
    return README[start:end if end > 0 else None]


def _env(bin_dir: Path = None) -> dict:
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    if bin_dir is not None:
        env["PATH"] = f"{bin_dir}{os.pathsep}{env.get('PATH', '')}"
    return env


def quick_start_code() -> str:
    """The quick start's shell block, as a user copies it."""
    return re.search(r"```\n(.*?)```", _section("Quick start"), re.S).group(1)


def _commands_of_this_tree(bin_dir: Path) -> Path:
    """``bsp-*`` on PATH running this interpreter and this tree (``python -m bsp_fast``),
    not whatever an earlier install left on PATH."""
    bin_dir.mkdir()
    for name in COMMANDS:
        script = bin_dir / f"bsp-{name}"
        script.write_text(f"#!{sys.executable}\nimport sys\nfrom bsp_fast.__main__ import main\n"
                          f"if __name__ == '__main__':  # bsp-synth's workers are spawned\n"
                          f"    sys.exit(main([{name!r}] + sys.argv[1:]))\n")
        script.chmod(0o755)
    return bin_dir


def _splits(h5) -> dict:
    with h5py.File(h5) as f:
        return {s: f[s].attrs["class_counts"].tolist() for s in ("train", "val", "test")}


@pytest.fixture(scope="module")
def quick_start(tmp_path_factory):
    """The Quick start copied verbatim, run twice in one empty folder (a new user runs it
    again), each command stopping the script when it fails: the two runs, and the folder."""
    pytest.importorskip("torch")
    pytest.importorskip("cv2")  # bsp-preview: the 'preview' extra
    env = _env(_commands_of_this_tree(tmp_path_factory.mktemp("bin") / "bin"))
    folder = tmp_path_factory.mktemp("quick_start")
    script = "set -euo pipefail\n" + quick_start_code()
    runs = []
    for _ in range(2):
        runs.append(subprocess.run(["bash", "-c", script], cwd=folder, env=env,
                                   capture_output=True, text=True, timeout=1200))
        assert runs[-1].returncode == 0, runs[-1].stdout[-3000:] + runs[-1].stderr[-3000:]
    return runs, folder


def test_quick_start_runs_verbatim_and_gives_both_classes_in_every_split(quick_start):
    runs, folder = quick_start
    for split, counts in _splits(folder / "clips.h5").items():
        assert min(counts) > 0, (split, counts)  # clips of both classes
    for made in ("clips.png", "preds.h5", "runs/lifting-lstm/metrics.json",
                 "runs/autoencoder-quick/results.md"):
        assert (folder / made).is_file(), made


def test_quick_start_runs_twice_in_the_same_folder(quick_start):
    runs, _ = quick_start
    for run in runs:
        assert "Traceback" not in run.stderr and "FileExistsError" not in run.stderr
    first, second = (r.stdout.splitlines() for r in runs)
    shown = [line for line in first if line.startswith(("train ", "val ", "test "))]
    assert shown and shown == [line for line in second
                               if line.startswith(("train ", "val ", "test "))]  # same splits


def test_pip_install_section_matches_the_build():
    section = _section("Install")
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
