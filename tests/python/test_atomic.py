"""bsp_fast.atomic: the one temp-then-rename helper. A writer killed (SIGKILL) at any step
of publishing leaves the target holding the old output or the new one, never neither."""
import os
import signal
import subprocess
import sys

import pytest

from bsp_fast import atomic


def _folder(path, text):
    path.mkdir()
    (path / "data.csv").write_text(text)


def test_file_published_and_temp_gone(tmp_path):
    out = tmp_path / "o.txt"
    with atomic.atomic_output(out) as tmp:
        assert tmp.parent == tmp_path and tmp.name.startswith(".o.txt.tmp-")
        tmp.write_text("new")
        assert not out.exists()
    assert out.read_text() == "new" and os.listdir(tmp_path) == ["o.txt"]


def test_exception_removes_temp_and_keeps_old(tmp_path):
    out = tmp_path / "d"
    _folder(out, "old")
    with pytest.raises(KeyboardInterrupt):
        with atomic.atomic_output(out, force=True, folder=True) as tmp:
            (tmp / "data.csv").write_text("half")
            raise KeyboardInterrupt
    assert (out / "data.csv").read_text() == "old" and os.listdir(tmp_path) == ["d"]


def test_existing_needs_force(tmp_path):
    out = tmp_path / "o.txt"
    out.write_text("old")
    with pytest.raises(FileExistsError, match="--force"):
        with atomic.atomic_output(out):
            pass
    assert out.read_text() == "old"


def test_folder_replaced_with_force(tmp_path):
    out = tmp_path / "d"
    _folder(out, "old")
    with atomic.atomic_output(out, force=True, folder=True) as tmp:
        (tmp / "data.csv").write_text("new")
    assert (out / "data.csv").read_text() == "new" and os.listdir(tmp_path) == ["d"]


@pytest.mark.parametrize("folder", [False, True])
def test_output_that_appeared_meanwhile_is_not_replaced(tmp_path, folder):
    """Two runs with the same output and no --force: the second one to finish refuses."""
    out = tmp_path / "o"
    tmp = atomic.temp_path(out)
    if folder:
        _folder(tmp, "second")
        _folder(out, "first")
    else:
        tmp.write_text("second")
        out.write_text("first")
    with pytest.raises(FileExistsError, match="refusing to replace|exists"):
        atomic.publish(tmp, out, force=False)
    assert (out / "data.csv" if folder else out).read_text() == "first"


_KILLED = """
import sys
from pathlib import Path
from bsp_fast import atomic
out = Path(sys.argv[1])
with atomic.atomic_output(out, force=True, folder=sys.argv[2] == "dir") as tmp:
    if sys.argv[2] == "dir":
        (tmp / "data.csv").write_text("new")
    else:
        tmp.write_text("new")
"""


@pytest.mark.parametrize("kind", ["dir", "file"])
@pytest.mark.parametrize("step", ["before", "swapped"])
def test_killed_between_steps_leaves_old_or_new(tmp_path, kind, step):
    out = tmp_path / "out"
    if kind == "dir":
        _folder(out, "old")
    else:
        out.write_text("old")
    env = dict(os.environ, BSP_ATOMIC_TEST_KILL=step, PYTHONPATH=os.pathsep.join(sys.path))
    p = subprocess.run([sys.executable, "-c", _KILLED, str(out), kind], env=env, timeout=60,
                       capture_output=True, text=True)
    assert p.returncode == -signal.SIGKILL, p.stderr
    content = (out / "data.csv" if kind == "dir" else out).read_text()
    assert content == ("old" if step == "before" else "new")


def test_fallback_without_renameat2(tmp_path, monkeypatch):
    """Where the kernel call is missing: a folder is moved aside, then replaced; a new file
    is hard-linked (refusing an existing target)."""
    monkeypatch.setattr(atomic, "_renameat2", None)
    out = tmp_path / "d"
    _folder(out, "old")
    with atomic.atomic_output(out, force=True, folder=True) as tmp:
        (tmp / "data.csv").write_text("new")
    assert (out / "data.csv").read_text() == "new" and os.listdir(tmp_path) == ["d"]
    f = tmp_path / "f"
    atomic.write_text(f, "x", force=False)
    assert f.read_text() == "x"
    tmp = atomic.temp_path(f)
    tmp.write_text("y")
    with pytest.raises(FileExistsError):
        atomic.publish(tmp, f, force=False)
    assert f.read_text() == "x"
