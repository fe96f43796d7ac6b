"""bsp_fast.read_csv / write_csv against hand-written CSVs and pandas (docs/dataset-format.md,
"2. data.csv")."""
from __future__ import annotations

import ast
import math

import numpy as np
import pandas as pd
import pytest

import bsp_fast
from bsp_fast.csvio import COLUMNS, CROSSING, CROSSING_ALIAS, CsvTable

SHAPES = {
    "camera.transform": (6,), "pedestrian.spawn_point": (6,), "frame.pedestrian.transform": (6,),
    "frame.pedestrian.velocity": (3,), "frame.pedestrian.pose.world": (26, 6),
    "frame.pedestrian.pose.component": (26, 6), "frame.pedestrian.pose.relative": (26, 6),
    "frame.pedestrian.pose.camera": (26, 2),
}
INTS = ("camera.idx", "camera.width", "camera.height", "pedestrian.idx", "frame.idx", "world.frame")
BOOLS = (CROSSING, "frame.pedestrian.pose.in_frame", "frame.pedestrian.pose.in_segmentation")
STRINGS = ("id", "world.map", "pedestrian.model", "pedestrian.age", "pedestrian.gender",
           "camera.recording", "camera.semantic_segmentation")


# ----------------------------------------------------------------- hand-written fixtures
def pylist(a) -> str:
    """Python's str() of a (nested) list of the float32 values in `a`, widened to float."""
    return str(np.asarray(a, dtype=np.float32).tolist())


def cells_of(frame: int, clip: str = "094b9fe1-babe-48d5-bd17-3ba3185690c5-0", crossing="True",
             in_seg="True", pose_camera=None) -> dict:
    """One valid row as {column: cell text}; numbers depend on frame."""
    b = np.float32(frame)
    ramp = lambda n: b + np.float32(0.1) * np.arange(n, dtype=np.float32)  # noqa: E731
    cam = ramp(52).reshape(26, 2) if pose_camera is None else pose_camera
    return {
        "id": clip, "world.map": "/Game/Carla/Maps/Town04", "camera.idx": "0",
        "camera.transform": '"[10.5, 20.25, 1.100000023841858, -8.130000114440918, 90.0, 0.0]"',
        "camera.width": "1600", "camera.height": "600", "pedestrian.idx": "0",
        "pedestrian.model": "walker.pedestrian.0001", "pedestrian.age": "adult",
        "pedestrian.gender": "female", "pedestrian.spawn_point": f'"{pylist(ramp(6))}"',
        "frame.idx": str(frame), "camera.recording": f"clips/{clip}-0.mp4",
        "camera.semantic_segmentation": f"clips/{clip}-1.apng", "world.frame": str(1000 + frame),
        "frame.pedestrian.transform": f'"{pylist(ramp(6) + 1)}"',
        "frame.pedestrian.velocity": f'"{pylist(ramp(3) + 2)}"',
        "frame.pedestrian.pose.world": f'"{pylist(ramp(156).reshape(26, 6) + 3)}"',
        "frame.pedestrian.pose.component": f'"{pylist(ramp(156).reshape(26, 6) + 4)}"',
        "frame.pedestrian.pose.relative": f'"{pylist(ramp(156).reshape(26, 6) + 5)}"',
        CROSSING: crossing, "frame.pedestrian.pose.camera": f'"{pylist(cam)}"',
        "frame.pedestrian.pose.in_frame": "False", "frame.pedestrian.pose.in_segmentation": in_seg,
    }


def write_text(path, rows: list[dict], columns=COLUMNS, eol="\n", rename=None) -> str:
    rename = rename or {}
    lines = [",".join(rename.get(c, c) for c in columns)]
    lines += [",".join(r[c] for c in columns) for r in rows]
    path.write_bytes((eol.join(lines) + eol).encode())
    return str(path)


# ----------------------------------------------------------------- reading
def test_reads_values_shapes_and_dtypes(tmp_path):
    p = write_text(tmp_path / "data.csv", [cells_of(3), cells_of(4)])
    t = bsp_fast.read_csv(p)
    assert isinstance(t, CsvTable) and len(t) == 2 and t.path == p
    assert t.columns == COLUMNS
    for name, shape in SHAPES.items():
        assert t[name].shape == (2,) + shape and t[name].dtype == np.float32, name
    for name in INTS:
        assert t[name].dtype == np.int64 and t[name].shape == (2,)
    for name in BOOLS:
        assert t[name].dtype == bool and t.valid(name).dtype == bool
    np.testing.assert_array_equal(t["camera.transform"][0],
                                  np.float32([10.5, 20.25, 1.1, -8.13, 90.0, 0.0]))
    ramp = np.float32(4) + np.float32(0.1) * np.arange(156, dtype=np.float32)
    np.testing.assert_array_equal(t["frame.pedestrian.pose.world"][1], ramp.reshape(26, 6) + 3)
    np.testing.assert_array_equal(t["frame.idx"], [3, 4])
    np.testing.assert_array_equal(t["world.frame"], [1003, 1004])
    np.testing.assert_array_equal(t.lines, [2, 3])
    assert t["id"].dtype == object and list(t["pedestrian.age"]) == ["adult", "adult"]
    np.testing.assert_array_equal(t.codes("id"), [0, 0])
    assert list(t.categories("camera.recording")) == [
        "clips/094b9fe1-babe-48d5-bd17-3ba3185690c5-0-0.mp4"]


def test_gaps_nan_joints_inf_and_empty_bools(tmp_path):
    cam = np.arange(52, dtype=np.float32).reshape(26, 2)
    cam[3] = np.nan  # a joint behind the camera: [nan, nan]
    cam[4, 0] = np.inf
    cam[5, 1] = -np.inf
    rows = [cells_of(0), cells_of(7, in_seg="", crossing=""), cells_of(8, pose_camera=cam)]
    assert "[nan, nan]" in rows[2]["frame.pedestrian.pose.camera"]
    t = bsp_fast.read_csv(write_text(tmp_path / "gaps.csv", rows))
    np.testing.assert_array_equal(t["frame.idx"], [0, 7, 8])
    np.testing.assert_array_equal(t["frame.pedestrian.pose.camera"][2], cam)
    np.testing.assert_array_equal(t.valid("frame.pedestrian.pose.in_segmentation"),
                                  [True, False, True])
    np.testing.assert_array_equal(t[CROSSING], [True, False, True])
    np.testing.assert_array_equal(t.valid(CROSSING), [True, False, True])
    with pytest.raises(ValueError, match="boolean columns"):
        t.valid("frame.idx")


@pytest.mark.parametrize("name", [CROSSING, CROSSING_ALIAS])
def test_both_crossing_column_names(tmp_path, name):
    p = write_text(tmp_path / "c.csv", [cells_of(1, crossing="False"), cells_of(2)],
                   rename={CROSSING: name})
    t = bsp_fast.read_csv(p)
    assert t.crossing_column == name
    np.testing.assert_array_equal(t[CROSSING], [False, True])
    np.testing.assert_array_equal(t[CROSSING_ALIAS], [False, True])
    assert CROSSING in t and CROSSING in t.columns
    only = bsp_fast.read_csv(p, columns=[CROSSING_ALIAS], check_duplicates=False)
    assert only.columns == (CROSSING,)


def test_reordered_columns_crlf_extra_column(tmp_path):
    rows = [cells_of(5), cells_of(6)]
    for r in rows:
        r["notes"] = '"free, text"'
    order = list(reversed(COLUMNS)) + ["notes"]
    p = write_text(tmp_path / "r.csv", rows, columns=order, eol="\r\n")
    ref = bsp_fast.read_csv(write_text(tmp_path / "plain.csv", [cells_of(5), cells_of(6)]))
    t = bsp_fast.read_csv(p)
    assert t.columns == COLUMNS
    for name in COLUMNS:
        np.testing.assert_array_equal(t[name], ref[name])


def test_column_selection(tmp_path):
    p = write_text(tmp_path / "s.csv", [cells_of(1), cells_of(2)])
    t = bsp_fast.read_csv(p, columns=["frame.pedestrian.pose.world"], check_duplicates=False)
    assert t.columns == ("frame.pedestrian.pose.world",)
    with pytest.raises(KeyError, match="not read"):
        t["frame.idx"]
    t = bsp_fast.read_csv(p, columns=["frame.pedestrian.pose.world"])  # + the key columns
    assert set(t.columns) == {"id", "camera.idx", "pedestrian.idx", "frame.idx",
                              "frame.pedestrian.pose.world"}
    with pytest.raises(ValueError, match="unknown column 'nope'; allowed: id, world.map"):
        bsp_fast.read_csv(p, columns=["nope"])
    with pytest.raises(ValueError, match="threads"):
        bsp_fast.read_csv(p, threads=0)
    with pytest.raises(FileNotFoundError):
        bsp_fast.read_csv(tmp_path / "missing.csv")


def test_threads_give_identical_tables(tmp_path):
    rows = [cells_of(f, clip=f"clip-{f // 40}") for f in range(400)]
    p = write_text(tmp_path / "t.csv", rows)
    one, two = bsp_fast.read_csv(p, threads=1), bsp_fast.read_csv(p, threads=2)
    for name in COLUMNS:
        np.testing.assert_array_equal(one[name], two[name])
    for name in STRINGS:
        np.testing.assert_array_equal(one.codes(name), two.codes(name))
        np.testing.assert_array_equal(one.categories(name), two.categories(name))
    assert list(one.categories("id")) == [f"clip-{k}" for k in range(10)]  # first-seen order


# ----------------------------------------------------------------- errors
def error_text(path, **kw) -> str:
    with pytest.raises(bsp_fast.CsvParseError) as info:
        bsp_fast.read_csv(path, **kw)
    return str(info.value)


def test_error_missing_column(tmp_path):
    p = write_text(tmp_path / "m.csv", [cells_of(1)], columns=COLUMNS[:-1])
    assert error_text(p) == (f"{p}, line 1 (header): missing required column "
                             "'frame.pedestrian.pose.in_segmentation'")


def test_error_wrong_list_length(tmp_path):
    rows = [cells_of(1), cells_of(2)]
    rows[1]["frame.pedestrian.pose.world"] = f'"{pylist(np.zeros((25, 6)))}"'
    p = write_text(tmp_path / "l.csv", rows)
    assert error_text(p) == (f"{p}, line 3, column 'frame.pedestrian.pose.world': "
                             "expected 26 x 6 numbers, got 25 lists")
    rows[1] = cells_of(2)
    rows[1]["frame.pedestrian.velocity"] = '"[1.0, 2.0, 3.0, 4.0]"'
    p = write_text(tmp_path / "v.csv", rows)
    assert error_text(p) == (f"{p}, line 3, column 'frame.pedestrian.velocity': "
                             "expected 3 numbers, got 4 numbers")


def test_error_bad_number(tmp_path):
    row = cells_of(1)
    row["frame.pedestrian.pose.relative"] = row["frame.pedestrian.pose.relative"].replace(
        "[[6.0,", "[[6.0.1,", 1)
    p = write_text(tmp_path / "n.csv", [row])
    assert error_text(p) == (f"{p}, line 2, column 'frame.pedestrian.pose.relative': "
                             "expected a number in list 1 at item 1, found '6.0.1'")


def test_error_truncated_last_line(tmp_path):
    p = write_text(tmp_path / "t.csv", [cells_of(1), cells_of(2)])
    data = open(p, "rb").read()
    open(p, "wb").write(data[:-200])
    msg = error_text(p)
    assert msg.startswith(f"{p}, line 3, column 'frame.pedestrian.pose.camera': "
                          "expected a closing '\"' before the end of the line")
    assert msg.endswith("(the last line has no line end: is the file truncated?)")


def test_error_duplicate_key(tmp_path):
    p = write_text(tmp_path / "d.csv", [cells_of(1), cells_of(2), cells_of(1)])
    assert error_text(p) == (
        f"{p}, line 4, columns (id, camera.idx, pedestrian.idx, frame.idx): duplicate key "
        "('094b9fe1-babe-48d5-bd17-3ba3185690c5-0', 0, 0, 1): expected each key once, found it "
        "on line 2 and line 4")
    assert len(bsp_fast.read_csv(p, check_duplicates=False)) == 3


def test_error_wrong_cell_count_and_bad_values(tmp_path):
    p = tmp_path / "w.csv"
    write_text(p, [cells_of(1)])
    p.write_text(p.read_text().rstrip("\n") + ",extra\n")
    assert error_text(p) == (f"{p}, line 2, column 'frame.pedestrian.pose.in_segmentation': "
                             "expected 24 cells, found 25 (extra text after the last column: "
                             "'extra')")
    row = cells_of(1)
    row["frame.idx"] = "seven"
    p = write_text(tmp_path / "i.csv", [row])
    assert error_text(p) == f"{p}, line 2, column 'frame.idx': expected an integer, found 'seven'"
    row = cells_of(1)
    row["frame.pedestrian.pose.in_frame"] = "maybe"
    p = write_text(tmp_path / "b.csv", [row])
    assert error_text(p) == (f"{p}, line 2, column 'frame.pedestrian.pose.in_frame': expected "
                             "True, False or an empty cell, found 'maybe'")


def test_error_string_not_utf8(tmp_path):
    p = write_text(tmp_path / "u.csv", [cells_of(1), cells_of(2)])
    data = open(p, "rb").read()
    open(p, "wb").write(data.replace(b"walker.pedestrian.0001", b"walker\xff", 1))
    assert error_text(p) == (f"{p}, line 2, column 'pedestrian.model': value 'walker\\xff' is "
                             "not valid UTF-8")
    # Only the columns that are read are decoded.
    assert len(bsp_fast.read_csv(p, columns=["frame.idx"], check_duplicates=False)) == 2


# ----------------------------------------------------------------- writing
SPECIAL = np.float32([0.0, -0.0, 1e-05, 1e-4, 1e16, 1.1, -8.13, 90.0, np.nan, np.inf, -np.inf,
                      1e-40, 3.4e38, 123456789.0])


def random_columns(rows: int, seed: int = 0) -> dict:
    rng = np.random.default_rng(seed)
    cols: dict = {}
    for name, shape in SHAPES.items():
        a = (rng.standard_normal((rows,) + shape) * 10.0 ** rng.integers(-6, 7, (rows,) + shape))
        a = a.astype(np.float32)
        a.reshape(-1)[: len(SPECIAL)] = SPECIAL
        cols[name] = a
    for name in INTS:
        cols[name] = rng.integers(0, 2000, rows).astype(np.int64)
    cols["frame.idx"] = np.arange(rows, dtype=np.int64) * 2  # gaps
    for name in BOOLS:
        cols[name] = rng.random(rows) < 0.5
    seg = np.where(rng.random(rows) < 0.3, np.nan, rng.random(rows) < 0.5)
    cols["frame.pedestrian.pose.in_segmentation"] = seg
    ids = np.array(["clip-a", 'odd, "quoted" id', "clip-b"], dtype=object)
    cols["id"] = ids[np.arange(rows) % 3]
    for name in STRINGS[1:]:
        cols[name] = np.array([f"{name}-{k % 4}" for k in range(rows)], dtype=object)
    cols["camera.idx"] = np.zeros(rows, np.int64)
    cols["pedestrian.idx"] = np.zeros(rows, np.int64)
    return cols


def pandas_frame(cols: dict) -> pd.DataFrame:
    """The recorder's DataFrame: Python lists of floats, True/False/None, ints, str."""
    data = {}
    for name in COLUMNS:
        v = cols[name]
        if name in SHAPES:
            data[name] = pd.Series(list(np.asarray(v, np.float32).tolist()), dtype=object)
        elif name in BOOLS:
            data[name] = pd.Series([None if x is None or x is pd.NA or (
                                        isinstance(x, float) and math.isnan(x)) else bool(x)
                                    for x in np.asarray(v, dtype=object)], dtype=object)
        else:
            data[name] = list(v)
    return pd.DataFrame(data)


def test_write_matches_pandas_byte_for_byte(tmp_path):
    cols = random_columns(60)
    ours = tmp_path / "ours.csv"
    bsp_fast.write_csv(ours, cols)
    theirs = pandas_frame(cols).to_csv(index=False)
    assert ours.read_bytes() == theirs.encode()
    assert "1e-05" in theirs and '""quoted""' in theirs and ",nan," not in theirs
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ours.csv"]  # no temp file left


def test_read_back_matches_pandas_literal_eval(tmp_path):
    cols = random_columns(40, seed=1)
    p = tmp_path / "d.csv"
    pandas_frame(cols).to_csv(p, index=False)
    t = bsp_fast.read_csv(p)
    df = pd.read_csv(p, keep_default_na=False)
    env = {"nan": math.nan, "inf": math.inf}
    for name in SHAPES:
        ref = np.array([eval(compile(ast.parse(s, mode="eval"), "<cell>", "eval"), env)
                        for s in df[name]], dtype=np.float32)
        np.testing.assert_array_equal(t[name], ref)
    for name in INTS:
        np.testing.assert_array_equal(t[name], df[name].to_numpy())
    for name in STRINGS:
        assert list(t[name]) == list(df[name])
    for name in BOOLS:
        text = df[name].astype(str).to_numpy()
        np.testing.assert_array_equal(t.valid(name), text != "")
        np.testing.assert_array_equal(t[name], text == "True")
    # And a table read back writes the same bytes again, with 1 or 2 threads.
    for threads in (1, 2):
        bsp_fast.write_csv(tmp_path / "again.csv", t, threads=threads)
        assert (tmp_path / "again.csv").read_bytes() == p.read_bytes()


def test_write_nullable_pandas_columns_like_pandas(tmp_path):
    cols = random_columns(5)
    seg = pd.array([True, None, False, None, True], dtype="boolean")
    model = pd.array(["m1", None, "m1", "m,2", "m,2"], dtype="string")
    cols["frame.pedestrian.pose.in_segmentation"] = seg
    cols["pedestrian.model"] = model
    p = tmp_path / "n.csv"
    bsp_fast.write_csv(p, cols)
    frame = pandas_frame(cols)
    frame["frame.pedestrian.pose.in_segmentation"] = seg  # pandas writes pd.NA as ""
    frame["pedestrian.model"] = model
    assert p.read_bytes() == frame.to_csv(index=False).encode()
    t = bsp_fast.read_csv(p)
    np.testing.assert_array_equal(t.valid("frame.pedestrian.pose.in_segmentation"),
                                  [True, False, True, False, True])
    assert list(t["pedestrian.model"]) == ["m1", "", "m1", "m,2", "m,2"]


def test_write_bool_forms_and_validation(tmp_path):
    cols = random_columns(5)
    cols["frame.pedestrian.pose.in_frame"] = np.array([1.0, 0.0, np.nan, 1.0, 0.0])
    cols[CROSSING_ALIAS] = cols.pop(CROSSING)
    p = tmp_path / "b.csv"
    bsp_fast.write_csv(p, cols, valid={CROSSING: [True, False, True, True, True]})
    t = bsp_fast.read_csv(p)
    np.testing.assert_array_equal(t.valid("frame.pedestrian.pose.in_frame"),
                                  [True, True, False, True, True])
    np.testing.assert_array_equal(t["frame.pedestrian.pose.in_frame"],
                                  [True, False, False, True, False])
    assert not t.valid(CROSSING)[1]
    bad = dict(cols)
    del bad["world.map"]
    with pytest.raises(ValueError, match="missing: world.map"):
        bsp_fast.write_csv(p, bad)
    bad = dict(cols, **{"frame.pedestrian.pose.world": np.zeros((5, 25, 6))})
    with pytest.raises(ValueError, match=r"expected shape \(5, 26, 6\)"):
        bsp_fast.write_csv(p, bad)
    bad = dict(cols, **{"frame.idx": np.array([0.0, 1.5, 2, 3, 4])})
    with pytest.raises(ValueError, match="frame.idx: expected integers"):
        bsp_fast.write_csv(p, bad)
    partial = bsp_fast.read_csv(p, columns=["frame.idx"], check_duplicates=False)
    with pytest.raises(ValueError, match="needs all 24 columns"):
        bsp_fast.write_csv(p, partial)
