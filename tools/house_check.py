#!/usr/bin/env python3
"""The house rules that a grep or a parse can check (docs/architecture.md, "What each stage
guarantees", "House rules a parse can check"):

* no import cycle between modules of ``python/bsp_fast`` (imports inside functions count:
  a lazy import only hides a cycle), and none between the C++ stages (the folders of
  ``cpp/src`` and ``cpp/include/bsp``, by their ``#include`` lines);
* no module imports another module's private (``_name``) function, class or variable
  (private *modules* such as ``_native`` are the package's own and may be imported);
* no Python function over FUNCTION_LIMIT lines, but the few of :data:`LONG_FUNCTIONS`,
  each with the reason it reads best whole (a file is split along its seams, not to fit a
  count), in Python and in C++ (a C++ function whose definition starts at column 0 and
  ends at the next ``}`` there);
* one temp-then-rename helper per language: ``os.replace``/``os.rename`` only in
  ``bsp_fast/atomic.py``, ``std::rename``/``::rename`` only in ``cpp/src/common/``;
* the default seed written as a literal only in ``bsp_fast/defaults.py`` and the C++
  defaults header.

Prints each violation and exits 1 if there is any. ``tests/python/test_code_rules.py`` runs it.
"""
from __future__ import annotations

import ast
import re
import sys
from pathlib import Path

FUNCTION_LIMIT = 60
#: functions allowed over FUNCTION_LIMIT lines, and why (``path:function``)
LONG_FUNCTIONS = {
}
ROOT = Path(__file__).resolve().parent.parent
PKG = ROOT / "python" / "bsp_fast"
SEED = "22742"


def module_name(path: Path) -> str:
    rel = path.relative_to(PKG.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _modules() -> dict:
    return {module_name(p): p for p in PKG.rglob("*.py")}


def _resolve(mod: str, is_pkg: bool, level: int, target: str | None) -> str:
    base = mod.split(".") if is_pkg else mod.split(".")[:-1]
    if level > 1:
        base = base[:len(base) - (level - 1)]
    return ".".join(base + ([target] if target else []))


def imports(mods: dict) -> tuple[dict, list]:
    """module -> set of imported bsp_fast modules; and the private-name imports found."""
    edges: dict = {m: set() for m in mods}
    private = []
    for mod, path in mods.items():
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        is_pkg = path.name == "__init__.py"
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                for a in node.names:
                    if a.name.startswith("bsp_fast"):
                        edges[mod].add(_nearest(a.name, mods))
            elif isinstance(node, ast.ImportFrom):
                src = (_resolve(mod, is_pkg, node.level, node.module) if node.level
                       else node.module or "")
                if not src.startswith("bsp_fast"):
                    continue
                for a in node.names:
                    sub = f"{src}.{a.name}"
                    if sub in mods or sub == "bsp_fast._core":  # the extension module
                        edges[mod].add(sub)
                        continue
                    edges[mod].add(_nearest(src, mods))
                    if a.name.startswith("_") and not a.name.startswith("__"):
                        private.append(f"{path.relative_to(ROOT)}:{node.lineno}: imports "
                                       f"private name {a.name} from {src}")
        edges[mod].discard(mod)
    return edges, private


def _nearest(name: str, mods: dict) -> str:
    while name not in mods and "." in name:
        name = name.rsplit(".", 1)[0]
    return name


def cycles(edges: dict) -> list:
    """Strongly connected components of more than one module (Tarjan), ignoring edges to
    a package's own ``__init__`` from inside it (Python runs it first anyway)."""
    def real(a, b):
        return not (a.startswith(b + ".") )

    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in edges.get(v, ()):
            if not real(v, w) or w not in edges:
                continue
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    sys.setrecursionlimit(10000)
    for v in edges:
        if v not in index:
            visit(v)
    return out


def cpp_stage_cycles() -> list:
    """Circles between the C++ stages: a stage's files including another stage's."""
    edges: dict = {}
    inc = re.compile(r'#include "(?:bsp/)?([a-z0-9_]+)/')
    for base, depth in ((ROOT / "cpp" / "src", 0), (ROOT / "cpp" / "include" / "bsp", 0)):
        for p in base.rglob("*.[ch]pp"):
            stage = p.relative_to(base).parts[depth]
            for line in p.read_text(encoding="utf-8").splitlines():
                m = inc.match(line)
                if m and m.group(1) != stage:
                    edges.setdefault(stage, set()).add(m.group(1))
    return [f"C++ include cycle: {' <-> '.join(c)}" for c in cycles(edges)]


def long_functions() -> list:
    out = []
    for p in PKG.rglob("*.py"):
        rel = p.relative_to(PKG).as_posix()
        for node in ast.walk(ast.parse(p.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = node.end_lineno - node.lineno + 1
                if n > FUNCTION_LIMIT and f"{rel}:{node.name}" not in LONG_FUNCTIONS:
                    out.append(f"python/bsp_fast/{rel}:{node.lineno}: {node.name} is {n} "
                               f"lines (limit {FUNCTION_LIMIT}; split it, or list it in "
                               "LONG_FUNCTIONS with why)")
    return out + long_cpp_functions()


def long_cpp_functions() -> list:
    out = []
    head = re.compile(r"^[A-Za-z].*\)\s*(const\s*)?(noexcept\s*)?\{\s*$")
    for p in (ROOT / "cpp").rglob("*.[ch]pp"):
        start = None
        for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1):
            if start is None and head.match(line) and not line.startswith(
                    ("namespace", "struct", "class", "enum", "extern")):
                start = i
            elif start is not None and line.startswith("}"):
                where = f"{p.relative_to(ROOT)}:{start}"
                if i - start + 1 > FUNCTION_LIMIT and where not in LONG_FUNCTIONS:
                    out.append(f"{where}: a function of {i - start + 1} lines (limit "
                               f"{FUNCTION_LIMIT})")
                start = None
    return out


def renames() -> list:
    out = []
    py = re.compile(r"\bos\.(replace|rename)\(|\.replace\(\s*\w+\s*\)\s*$|Path\([^)]*\)\.rename\(")
    for p in PKG.rglob("*.py"):
        if p.name == "atomic.py" and p.parent == PKG:
            continue
        for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1):
            if re.search(r"\bos\.(replace|rename)\(", line) or re.search(r"\.rename\(", line):
                out.append(f"{p.relative_to(ROOT)}:{i}: rename outside bsp_fast/atomic.py")
    cpp = re.compile(r"(std::rename|[^:\w]::rename|\brename)\s*\(")
    for p in (ROOT / "cpp").rglob("*.cpp"):
        if p.parent.name == "common":
            continue
        for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1):
            code = line.split("//", 1)[0]
            if cpp.search(code):
                out.append(f"{p.relative_to(ROOT)}:{i}: rename outside cpp/src/common/")
    return out


def seeds() -> list:
    out = []
    allowed = {PKG / "defaults.py"}
    for p in list(PKG.rglob("*.py")) + list((ROOT / "cpp").rglob("*.[ch]pp")):
        if p in allowed or p.match("cpp/include/bsp/clips/clips.hpp"):
            continue
        for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1):
            if SEED in line:
                out.append(f"{p.relative_to(ROOT)}:{i}: literal seed {SEED} outside the defaults")
    return out


def main() -> int:
    mods = _modules()
    edges, private = imports(mods)
    problems = [f"import cycle: {' <-> '.join(c)}" for c in cycles(edges)]
    problems += cpp_stage_cycles() + private + long_functions() + renames() + seeds()
    for p in problems:
        print(p)
    print(f"house_check: {len(mods)} modules, {len(problems)} problem(s)")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
