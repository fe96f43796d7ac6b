"""bsp-convert without media parses the three pose columns only while it writes the clips
(issue 59: the table never holds them). Same file as the path that reads them up front
(--verify needs them for every row, so it still does), and the same error for a
malformed pose cell, wherever it is: in a clip, or in a row no clip uses."""
from __future__ import annotations

import csv
import io

import h5py
import numpy as np
import pytest

import bsp_fast as bf
from bsp_fast import conversion as cv
from bsp_testdata import COLUMNS, recording, write_dataset

pytestmark = pytest.mark.filterwarnings("ignore::UserWarning")  # tiny datasets: empty splits

U1 = "094b9fe1-babe-48d5-bd17-3ba3185690c5-0"
U2 = "1a2b3c4d-babe-48d5-bd17-3ba3185690c5-0"
WORLD = "frame.pedestrian.pose.world"


def dataset(root, columns=None, newline="\n"):
    # Two recordings of 25 rows: clips of 10 leave 5 rows of each in no clip.
    rows = recording(U1, range(25), crossing_from=12) + recording(U2, range(25), seed=4)
    return write_dataset(root, rows, **({"columns": columns} if columns else {}), newline=newline)


def datasets(path) -> dict:
    out = {}
    with h5py.File(path, "r") as f:
        f.visititems(lambda k, v: out.__setitem__(k, v[()]) if isinstance(v, h5py.Dataset) else None)
    return out


def convert(ds, out, **kw):
    return cv.convert(ds, out, clip_length=10, val_frac=0.3, test_frac=0.3, media=False,
                      force=True, **kw)


@pytest.mark.parametrize("threads", [1, 2])
@pytest.mark.parametrize("layout", ["plain", "reversed+crlf"])
def test_same_file_as_reading_the_poses_up_front(tmp_path, threads, layout):
    cols = dict(columns=COLUMNS[::-1], newline="\r\n") if layout != "plain" else {}
    ds = dataset(tmp_path / "ds", **cols)
    deferred = datasets(convert(ds, tmp_path / "d.h5", threads=threads)["output"])
    upfront = datasets(convert(ds, tmp_path / "u.h5", threads=threads, verify=True)["output"])
    assert deferred.keys() == upfront.keys() and len(deferred) > 20
    for k in upfront:
        a, b = deferred[k], upfront[k]
        assert a.dtype == b.dtype and a.shape == b.shape, k
        if a.dtype.kind == "O":  # strings
            assert a.tolist() == b.tolist(), k
        else:
            assert a.tobytes() == b.tobytes(), k  # bit for bit, NaNs included


def rewrite_cell(path, column, line, value):
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    rows[line - 1][rows[0].index(column)] = value
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerows(rows)
    path.write_text(buf.getvalue())


@pytest.mark.parametrize("line", [4, 25, 51])  # in a clip; no clip (row 24 of U1); last row
@pytest.mark.parametrize("value", ["[[1.0, 2.0]]", "[" + ", ".join(["[1.5, x, 0, 0, 0, 0]"] * 26) + "]"])
def test_a_malformed_pose_cell_fails_as_when_read_up_front(tmp_path, line, value):
    ds = dataset(tmp_path / "ds")
    rewrite_cell(ds / "data.csv", WORLD, line, value)
    with pytest.raises(bf.CsvParseError) as upfront:
        convert(ds, tmp_path / "u.h5", verify=True)
    assert f"line {line}, column '{WORLD}'" in str(upfront.value)
    with pytest.raises(bf.CsvParseError) as deferred:
        convert(ds, tmp_path / "d.h5")
    assert str(deferred.value) == str(upfront.value)
    assert not list(tmp_path.glob("*.h5")) and not list(tmp_path.glob(".*.h5*"))


def test_the_first_bad_row_is_named_and_comes_before_other_errors(tmp_path):
    ds = dataset(tmp_path / "ds")
    rewrite_cell(ds / "data.csv", WORLD, 40, "[]")
    rewrite_cell(ds / "data.csv", "frame.pedestrian.pose.relative", 9, "[0]")
    with pytest.raises(bf.CsvParseError, match="line 9, column 'frame.pedestrian.pose.relative'"):
        convert(ds, tmp_path / "d.h5")
    # A bad clip option is reported after the data error, as when the poses were read first.
    with pytest.raises(bf.CsvParseError, match="line 9"):
        cv.convert(ds, tmp_path / "e.h5", clip_length=10, media=False, val_frac=0.3,
                   test_frac=0.3, threads=1, clip_offset=10)
