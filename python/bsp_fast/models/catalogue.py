"""The registered models, read from the model modules' source without importing torch:
``{task: {name: Entry(description, hparams)}}``. The commands check task, model and
hyper-parameter names with it and list the models in ``--help`` before PyTorch is
imported (seconds); ``models.available``/``hparams_of`` stay the registry's own answer, and
a test holds the two equal.

A model module declares a model as ``@register(TASK, NAME, DESCRIPTION)`` on a class whose
keyword-only ``__init__`` arguments are its hyper-parameters (inherited from a base class
of the same module when it has no ``__init__``); both are read from the syntax tree.
"""
from __future__ import annotations

import ast
import functools
from dataclasses import dataclass
from pathlib import Path

__all__ = ["Entry", "catalogue", "names", "hparams", "MODULES"]

#: the modules that register models (``models/__init__.py`` imports the same)
MODULES = ("graph", "lstm", "martinez", "pose_cnn", "pose_temporal", "poseformer",
           "transformer")


@dataclass(frozen=True)
class Entry:
    description: str
    hparams: dict  # {name: default}; a default that is not a literal is its source text


def _register_args(cls: ast.ClassDef):
    for deco in cls.decorator_list:
        if isinstance(deco, ast.Call) and getattr(deco.func, "id", None) == "register":
            return [ast.literal_eval(a) for a in deco.args[:3]]
    return None


def _init_hparams(cls: ast.ClassDef, classes: dict, source: str) -> dict:
    for node in cls.body:
        if isinstance(node, ast.FunctionDef) and node.name == "__init__":
            args = node.args
            out = {}
            for arg, default in zip(args.kwonlyargs, args.kw_defaults):
                if default is None:
                    continue
                try:
                    out[arg.arg] = ast.literal_eval(default)
                except ValueError:
                    out[arg.arg] = ast.get_source_segment(source, default)
            return out
    for base in cls.bases:  # no __init__ of its own: a base of the same module's
        if isinstance(base, ast.Name) and base.id in classes:
            return _init_hparams(classes[base.id], classes, source)
    return {}


@functools.lru_cache(maxsize=None)
def catalogue() -> dict:
    """``{task: {name: Entry}}`` of every registered model, names sorted."""
    out: dict = {}
    folder = Path(__file__).parent
    for module in MODULES:
        source = (folder / f"{module}.py").read_text(encoding="utf-8")
        tree = ast.parse(source)
        classes = {n.name: n for n in tree.body if isinstance(n, ast.ClassDef)}
        for cls in classes.values():
            reg = _register_args(cls)
            if reg is not None:
                task, name, text = reg
                out.setdefault(task, {})[name] = Entry(text, _init_hparams(cls, classes, source))
    return {t: dict(sorted(m.items())) for t, m in out.items()}


def names(task: str) -> list:
    """The model names of ``task`` (sorted)."""
    return list(catalogue().get(task, {}))


def hparams(task: str, name: str) -> dict:
    """``{hyper-parameter: default}`` of a registered model."""
    return dict(catalogue()[task][name].hparams)
