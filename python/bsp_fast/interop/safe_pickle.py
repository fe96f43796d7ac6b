"""A restricted unpickler for pose pickles from other projects (e.g. the pose ``.pkl`` files
of the PedestrianActionBenchmark): plain containers and NumPy arrays only.

``pickle.load`` runs whatever a file names (``os.system``, any class's ``__reduce__``), so
an untrusted pickle is never loaded with it. :class:`RestrictedUnpickler` resolves only
the globals that plain data needs (:data:`ALLOWED`); any other one raises
:class:`RefusedPickle` naming it, before anything is called.
"""
from __future__ import annotations

import io
import pickle
from pathlib import Path

__all__ = ["ALLOWED", "RefusedPickle", "RestrictedUnpickler", "loads", "load_file"]

#: (module, name) pairs a pickle may name: NumPy's array, scalar and dtype reconstruction
#: (NumPy 1 ``numpy.core`` and NumPy 2 ``numpy._core`` spellings), and built-in containers
#: and values that older pickle protocols build by name.
ALLOWED = frozenset(
    [(m, n) for m in ("numpy.core.multiarray", "numpy._core.multiarray")
     for n in ("_reconstruct", "scalar")]
    + [(m, "_frombuffer") for m in ("numpy.core.numeric", "numpy._core.numeric")]
    + [("numpy", "ndarray"), ("numpy", "dtype")]
    + [("builtins", n) for n in ("list", "dict", "tuple", "set", "frozenset", "bytearray",
                                 "bytes", "str", "int", "float", "complex", "bool")]
    + [("__builtin__", n) for n in ("list", "dict", "tuple", "set", "frozenset", "bytearray",
                                    "str", "unicode", "int", "long", "float", "complex", "bool")]
    + [("collections", "OrderedDict"),
       ("_codecs", "encode")])  # protocol 2 spells bytes as _codecs.encode(text, "latin1")


class RefusedPickle(pickle.UnpicklingError):
    """The pickle names a global outside :data:`ALLOWED` (or is not a valid pickle)."""


class RestrictedUnpickler(pickle.Unpickler):
    """``pickle.Unpickler`` whose ``find_class`` resolves only :data:`ALLOWED`."""

    def find_class(self, module, name):
        if (module, name) in ALLOWED:
            return super().find_class(module, name)
        raise RefusedPickle(f"refused class {module}.{name}: only plain containers and NumPy "
                            "arrays may be unpickled (the file may run code; not loaded)")


def loads(data: bytes, *, encoding: str = "latin1"):
    """Unpickles ``data`` with :class:`RestrictedUnpickler` (``encoding``: how Python 2
    strings are read; ``latin1`` keeps NumPy arrays of Python 2 pickles intact)."""
    try:
        return RestrictedUnpickler(io.BytesIO(data), encoding=encoding).load()
    except RefusedPickle:
        raise
    except (pickle.UnpicklingError, EOFError, ValueError, TypeError, AttributeError,
            IndexError, KeyError, OverflowError, MemoryError) as exc:
        raise RefusedPickle(f"not a valid pickle of plain data ({type(exc).__name__}: "
                            f"{exc})") from None


def load_file(path):
    """:func:`loads` of a file; a :class:`RefusedPickle` names the file."""
    path = Path(path)
    try:
        return loads(path.read_bytes())
    except RefusedPickle as exc:
        raise RefusedPickle(f"{path}: {exc}") from None
