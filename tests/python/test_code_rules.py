"""The code's rules a parse can check (tools/house_check.py): no import cycle in Python or
between the C++ stages, no private names imported across modules, no function over the
line limit but the listed ones, one temp-then-rename helper per language, the default seed
written only in the defaults; and docs/architecture.md names only paths that exist."""
import importlib.util
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
spec = importlib.util.spec_from_file_location("house_check", ROOT / "tools" / "house_check.py")
house = importlib.util.module_from_spec(spec)
spec.loader.exec_module(house)


def test_cycle_finder_finds_a_lazy_cycle_and_ignores_parent_packages():
    edges = {"p.a": {"p.b"}, "p.b": {"p.a"}, "p": {"p.a"}, "p.c": {"p"}, "p.d": {"p.c"}}
    assert house.cycles(edges) == [["p.a", "p.b"]]


def test_the_tree_keeps_the_house_rules():
    p = subprocess.run([sys.executable, str(ROOT / "tools" / "house_check.py")],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stdout + p.stderr


def test_architecture_page_names_only_paths_that_exist(tmp_path):
    tool = [sys.executable, str(ROOT / "tools" / "check_doc_paths.py")]
    p = subprocess.run(tool + ["docs/architecture.md"], capture_output=True, text=True,
                       timeout=120, cwd=ROOT)
    assert p.returncode == 0, p.stdout + p.stderr
    page = ROOT / "docs" / "_check_doc_paths_probe.md"  # the checker does find a stale path
    page.write_text("see `python/bsp_fast/no_such_module.py`\n")
    try:
        p = subprocess.run(tool + ["docs/_check_doc_paths_probe.md"], capture_output=True,
                           text=True, timeout=120, cwd=ROOT)
    finally:
        page.unlink()
    assert p.returncode == 1 and "no_such_module.py" in p.stdout
