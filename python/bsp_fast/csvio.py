"""Read and write CARLA-BSP ``data.csv`` files (docs/dataset-format.md, "2. data.csv") with
the C++ core.

``read_csv`` memory-maps the file and parses it in parallel into numpy arrays; ``write_csv``
writes exactly the bytes pandas ``DataFrame.to_csv(index=False)`` wrote for the original
recorder's DataFrame. Columns go by NAME (any order in the file); the crossing column may be
called ``frame.pedestrian.is_crossing`` or ``frame.pedestrian.is_on_driving_lane`` and is
always exposed under the first name.

Array layout of a table (N rows):

===========================================================  =========================
``camera.transform``, ``pedestrian.spawn_point``,              (N, 6) float32
``frame.pedestrian.transform``
``frame.pedestrian.velocity``                                  (N, 3) float32
``frame.pedestrian.pose.world|component|relative``             (N, 26, 6) float32
``frame.pedestrian.pose.camera``                               (N, 26, 2) float32
``camera.idx|width|height``, ``pedestrian.idx``, ``frame.idx``,  (N,) int64
``world.frame``
``frame.pedestrian.is_crossing``, ``...pose.in_frame``,         (N,) bool, plus
``...pose.in_segmentation``                                    ``table.valid(col)``
``id``, ``world.map``, ``pedestrian.model|age|gender``,          (N,) object (str), plus
``camera.recording``, ``camera.semantic_segmentation``          ``codes``/``categories``
===========================================================  =========================

An empty list cell reads as NaNs; an empty boolean cell reads as False with
``valid(col)`` False; an empty string cell reads as ``""``.
"""
from __future__ import annotations

import math
import os
from typing import Any, Iterable, Iterator, Mapping

import numpy as np

from ._native import core as _core

COLUMNS: tuple[str, ...] = tuple(_core.CSV_COLUMNS)
CROSSING = "frame.pedestrian.is_crossing"
CROSSING_ALIAS: str = _core.CSV_CROSSING_ALIAS

_FLOAT_SHAPES = {
    "camera.transform": (6,),
    "pedestrian.spawn_point": (6,),
    "frame.pedestrian.transform": (6,),
    "frame.pedestrian.velocity": (3,),
    "frame.pedestrian.pose.world": (26, 6),
    "frame.pedestrian.pose.component": (26, 6),
    "frame.pedestrian.pose.relative": (26, 6),
    "frame.pedestrian.pose.camera": (26, 2),
}
_INTS = ("camera.idx", "camera.width", "camera.height", "pedestrian.idx", "frame.idx",
         "world.frame")
_BOOLS = (CROSSING, "frame.pedestrian.pose.in_frame", "frame.pedestrian.pose.in_segmentation")
_STRINGS = ("id", "world.map", "pedestrian.model", "pedestrian.age", "pedestrian.gender",
            "camera.recording", "camera.semantic_segmentation")


def _canonical(name: str) -> str:
    return CROSSING if name == CROSSING_ALIAS else name


def _check_name(name: Any) -> str:
    if not isinstance(name, str) or _canonical(name) not in COLUMNS:
        raise ValueError(f"unknown column {name!r}; allowed: {', '.join(COLUMNS)}, "
                         f"{CROSSING_ALIAS}")
    return _canonical(name)


class CsvTable:
    """The parsed columns of one data.csv.

    Dict-like over column names (``table[name]``, ``name in table``, ``keys()``, ``items()``,
    iteration), while ``len(table)`` is the number of rows, as for a DataFrame.
    """

    def __init__(self, raw: dict):
        self.path: str = raw["path"]
        self.columns: tuple[str, ...] = tuple(raw["columns"])
        #: file name of the crossing column, "" if it was not read
        self.crossing_column: str = raw["crossing_column"]
        #: 1-based line of each row in the file (the header is line 1)
        self.lines: np.ndarray = raw["line"]
        self._rows: int = raw["rows"]
        self._data: dict[str, np.ndarray] = dict(raw["data"])
        self._valid: dict[str, np.ndarray] = dict(raw["valid"])
        self._strings: dict[str, tuple[list, np.ndarray]] = dict(raw["strings"])
        self._objects: dict[str, np.ndarray] = {}

    def __len__(self) -> int:
        return self._rows

    def __contains__(self, name: object) -> bool:
        return isinstance(name, str) and _canonical(name) in self.columns

    def __iter__(self) -> Iterator[str]:
        return iter(self.columns)

    def keys(self) -> tuple[str, ...]:
        return self.columns

    def items(self) -> Iterator[tuple[str, np.ndarray]]:
        return ((name, self[name]) for name in self.columns)

    def values(self) -> Iterator[np.ndarray]:
        return (self[name] for name in self.columns)

    def get(self, name: str, default: Any = None) -> Any:
        return self[name] if name in self else default

    def __getitem__(self, name: str) -> np.ndarray:
        key = self._column(name)
        if key in self._data:
            return self._data[key]
        if key not in self._objects:
            self._objects[key] = self.categories(key)[self._strings[key][1]]
        return self._objects[key]

    def valid(self, name: str) -> np.ndarray:
        """(N,) bool: False where a boolean column's cell was empty."""
        key = self._column(name)
        if key not in self._valid:
            raise ValueError(f"valid() is defined for the boolean columns {', '.join(_BOOLS)}; "
                             f"got {name!r}")
        return self._valid[key]

    def codes(self, name: str) -> np.ndarray:
        """(N,) int32 dictionary codes of a string column (categories in first-seen order)."""
        return self._string(name)[1]

    def categories(self, name: str) -> np.ndarray:
        """The distinct values of a string column in first-seen order, as an object array."""
        values = self._string(name)[0]
        out = np.empty(len(values), dtype=object)
        out[:] = values
        return out

    def _column(self, name: str) -> str:
        key = _canonical(name) if isinstance(name, str) else name
        if key not in self.columns:
            raise KeyError(f"{name!r}: not read from {self.path} (read: {', '.join(self.columns)})")
        return key

    def _string(self, name: str) -> tuple[list, np.ndarray]:
        key = self._column(name)
        if key not in self._strings:
            raise ValueError(f"{name!r} is not a string column; string columns: "
                             f"{', '.join(_STRINGS)}")
        return self._strings[key]

    def __repr__(self) -> str:
        return f"CsvTable({self.path!r}, rows={self._rows}, columns={len(self.columns)})"


def read_csv(path: str | os.PathLike, columns: Iterable[str] | None = None,
             threads: int | None = None, *, check_duplicates: bool = True) -> CsvTable:
    """Parse a CARLA-BSP data.csv into a :class:`CsvTable`.

    columns: names to parse (default: all 24); others are skipped quickly. Every requested
        column must be in the file. With ``check_duplicates`` the key columns (id,
        camera.idx, pedestrian.idx, frame.idx) are read too and a repeated key is an error.
    threads: parser threads (default: ``bsp_fast.num_threads()``); the result does not
        depend on it.

    Raises FileNotFoundError, ValueError for an unknown column name, and
    ``bsp_fast.CsvParseError`` naming file, line and column for a malformed file.
    """
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"no such file: {path}")
    if isinstance(columns, str):
        raise TypeError("columns must be a list of names, not a single string")
    names = [] if columns is None else [_check_name(c) for c in columns]
    if columns is not None and not names:
        raise ValueError("columns is empty; pass None to read all columns")
    if threads is None:
        threads = 0
    elif not isinstance(threads, int) or threads < 1:
        raise ValueError(f"threads must be None or a positive int, got {threads!r}")
    return CsvTable(_core.read_pose_csv(path, names, threads, bool(check_duplicates)))


def _is_missing(v: Any) -> bool:
    """None, NaN, pandas.NA or NaT: pandas writes these as an empty cell."""
    if v is None:
        return True
    if isinstance(v, float):
        return math.isnan(v)
    return type(v).__name__ in ("NAType", "NaTType")


def _string_column(values: Any, rows: int) -> tuple[list[str], np.ndarray]:
    arr = np.asarray(values, dtype=object).reshape(-1)
    index: dict[str, int] = {}
    codes = np.empty(len(arr), dtype=np.int32)
    for i, v in enumerate(arr):
        codes[i] = index.setdefault("" if _is_missing(v) else str(v), len(index))
    return list(index), codes


def _bool_column(name: str, values: Any, mask: Any) -> tuple[np.ndarray, np.ndarray]:
    arr = np.asarray(values)
    if arr.dtype == object:
        ok = np.array([not _is_missing(v) for v in arr], dtype=bool)
        val = np.array([bool(v) if k else False for v, k in zip(arr, ok)], dtype=bool)
    elif arr.dtype.kind == "f":
        ok = ~np.isnan(arr)
        val = np.where(ok, arr, 0) != 0
    elif arr.dtype.kind in "biu":
        ok = np.ones(arr.shape, dtype=bool)
        val = arr != 0
    else:
        raise ValueError(f"{name}: expected bool, float (NaN = empty) or object values, "
                         f"got dtype {arr.dtype}")
    if mask is not None:
        ok = ok & np.asarray(mask, dtype=bool)
    return val.astype(np.uint8), ok.astype(np.uint8)


def _float_column(name: str, values: Any, rows: int) -> np.ndarray:
    arr = np.asarray(values)
    if arr.dtype == object:  # e.g. a pandas column of Python lists
        arr = np.array(arr.tolist(), dtype=np.float32)
    arr = np.ascontiguousarray(arr, dtype=np.float32)
    want = (rows,) + _FLOAT_SHAPES[name]
    if arr.shape != want:
        raise ValueError(f"{name}: expected shape {want}, got {arr.shape}")
    return arr


def _int_column(name: str, values: Any) -> np.ndarray:
    arr = np.asarray(values)
    if arr.dtype.kind == "f":
        if not np.all(np.isfinite(arr)) or np.any(arr != np.round(arr)):
            raise ValueError(f"{name}: expected integers, got non-integral or missing values")
    elif arr.dtype.kind not in "biu":
        raise ValueError(f"{name}: expected integers, got dtype {arr.dtype}")
    return np.ascontiguousarray(arr, dtype=np.int64)


def write_csv(path: str | os.PathLike, table: CsvTable | Mapping[str, Any], *,
              valid: Mapping[str, Any] | None = None, threads: int | None = None) -> None:
    """Write all 24 columns exactly as pandas ``to_csv(index=False)`` did for the recorder.

    table: a :class:`CsvTable` holding all 24 columns, or a mapping of column name (either
        crossing name) to array-like with the shapes of the module docstring. Float arrays
        are stored as float32 and printed as Python prints the float32 value widened to
        float (``1.100000023841858``). Boolean columns may be given as bool arrays, as
        float arrays where NaN means an empty cell, or as object arrays with None/NaN for
        empty cells. String columns are array-likes of str (None/NaN = empty).
    valid: optional {boolean column: (N,) bool mask}; False writes an empty cell. For a
        CsvTable, its own ``valid()`` masks are used unless overridden here.
    threads: formatting threads (default: ``bsp_fast.num_threads()``); the output does not
        depend on it. The file appears atomically (temporary name, then rename).
    """
    path = os.fspath(path)
    if threads is None:
        threads = 0
    elif not isinstance(threads, int) or threads < 1:
        raise ValueError(f"threads must be None or a positive int, got {threads!r}")
    masks = {_check_name(k): v for k, v in (valid or {}).items()}
    if isinstance(table, CsvTable):
        given = {name: table[name] for name in table.columns if name not in _STRINGS}
        for name in _BOOLS:
            if name in table and name not in masks:
                masks[name] = table.valid(name)
        strings = {name: table._string(name) for name in _STRINGS if name in table}
    else:
        given = {_check_name(k): v for k, v in table.items()}
        strings = {}
    missing = [c for c in COLUMNS if c not in given and c not in strings]
    if missing:
        raise ValueError(f"write_csv needs all 24 columns; missing: {', '.join(missing)}")
    rows = len(np.asarray(given["frame.idx"]))
    cols: dict[str, Any] = {}
    for name in COLUMNS:
        if name in _FLOAT_SHAPES:
            cols[name] = _float_column(name, given[name], rows)
        elif name in _INTS:
            cols[name] = _int_column(name, given[name])
        elif name in _BOOLS:
            cols[name] = _bool_column(name, given[name], masks.get(name))
        else:
            cols[name] = strings[name] if name in strings else _string_column(given[name], rows)
    for name, col in cols.items():
        n = len(col[1]) if isinstance(col, tuple) else len(col)
        if n != rows:
            raise ValueError(f"{name}: {n} rows, but frame.idx has {rows}")
    _core.write_pose_csv(path, cols, rows, threads)
