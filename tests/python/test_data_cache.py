"""BSPDataModule's conversion cache: keyed by the options, checked against data.csv, and
it says whether it converts or reuses."""
import shutil

import h5py
import pytest

from bsp_fast.data import BSPDataModule
from bsp_testdata import recording, write_dataset

pytestmark = pytest.mark.filterwarnings("ignore::UserWarning")


def _uuid(k: int) -> str:
    return f"{k:08x}-0000-4000-8000-000000000000-0"


@pytest.fixture(scope="module")
def source(tmp_path_factory):
    rows = []
    for k in range(8):  # crossing from frame 18 in every other recording
        rows += recording(_uuid(k), range(36), crossing_from=18 if k % 2 else None, seed=k)
    return write_dataset(tmp_path_factory.mktemp("src") / "ds", rows)


@pytest.fixture()
def ds(source, tmp_path):
    return shutil.copytree(source, tmp_path / "ds")


def _prepare(dm, capsys):
    dm.prepare_data()
    return capsys.readouterr().err


def test_every_output_option_has_its_own_file(ds, capsys):
    base = dict(clip_length=12, batch_size=4)
    first = BSPDataModule(ds, **base)
    assert "converting" in _prepare(first, capsys) and first.reused is False
    assert first.h5_path.parent == ds / "bsp_fast-cache"
    again = BSPDataModule(ds, **base)
    assert "reusing" in _prepare(again, capsys) and again.reused is True
    assert again.h5_path == first.h5_path
    paths = {first.h5_path}
    for change in ({"convert_options": {"label": "any:0.5"}},
                   {"convert_options": {"seed": 7}},
                   {"convert_options": {"val_frac": 0.3}},
                   {"convert_options": {"fov": 70.0}},
                   {"clip_offset": 6}):
        dm = BSPDataModule(ds, **base, **change)
        assert "converting" in _prepare(dm, capsys), change
        assert dm.h5_path not in paths, change
        paths.add(dm.h5_path)
        with h5py.File(dm.h5_path) as f:  # the file was converted with the new option
            want = "any:0.5" if "label" in change.get("convert_options", {}) else "last"
            assert f.attrs["label_rule"].startswith(want)
    # options that do not change the output share the file
    same = BSPDataModule(ds, **base, num_workers=0, noise=3.0)
    assert "reusing" in _prepare(same, capsys)


def test_a_changed_data_csv_is_converted_again(ds, capsys):
    dm = BSPDataModule(ds, clip_length=12)
    _prepare(dm, capsys)
    rows0 = dm.conversion_report["rows"]
    csv = ds / "data.csv"
    lines = csv.read_text().splitlines(keepends=True)
    csv.write_text("".join(lines[:-36]))  # the last recording is gone
    dm2 = BSPDataModule(ds, clip_length=12)
    err = _prepare(dm2, capsys)
    assert "converting again" in err and "changed size" in err
    assert dm2.h5_path == dm.h5_path and dm2.conversion_report["rows"] == rows0 - 36
    # same size, other content: the CRC tells (the file is older than data.csv)
    text = csv.read_text()
    csv.write_text(text.replace("walker.pedestrian.0001", "walker.pedestrian.0002", 1))
    err = _prepare(BSPDataModule(ds, clip_length=12), capsys)
    assert "CRC-32 differs" in err
    # touched but unchanged: one CRC scan, no conversion
    csv.write_text(csv.read_text())
    err = _prepare(BSPDataModule(ds, clip_length=12), capsys)
    assert "reusing" in err


def test_explicit_h5_path_is_checked_not_replaced(ds, tmp_path, capsys):
    out = tmp_path / "mine.h5"
    _prepare(BSPDataModule(ds, out, clip_length=12), capsys)
    mtime = out.stat().st_mtime_ns
    with pytest.raises(ValueError, match=r"converted with other options: --label any:0.5 vs "
                                         r"last in the file; delete it"):
        BSPDataModule(ds, out, clip_length=12, convert_options={"label": "any:0.5"}).prepare_data()
    assert out.stat().st_mtime_ns == mtime


def test_cache_dir_and_the_read_only_fallback(ds, tmp_path, monkeypatch, capsys):
    from bsp_fast.data import cache as C

    dm = BSPDataModule(ds, clip_length=12, cache_dir=tmp_path / "c")
    _prepare(dm, capsys)
    assert dm.h5_path.parent == tmp_path / "c" and dm.h5_path.is_file()
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    monkeypatch.setattr(C.os, "access", lambda p, mode: False)  # a read-only dataset
    folder = C.default_cache_dir(ds)
    assert folder.parent == tmp_path / "xdg" / "bsp_fast" and folder.name.startswith("ds-")
    quiet = BSPDataModule(ds, clip_length=12, verbose=False)
    assert _prepare(quiet, capsys) == "" and quiet.h5_path.parent == folder
