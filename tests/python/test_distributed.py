"""bsp-convert and bsp-synth on a Dask LocalCluster (2 worker processes, 1 thread each):
the sharded conversion equals the one-process file value for value whatever the shard
count, fails with the same errors, survives a worker killed mid-task, leaves nothing
behind when interrupted; bsp-synth's Dask mode writes byte-identical files."""
import filecmp
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

distributed = pytest.importorskip("distributed")

import bsp_fast as bf  # noqa: E402
from bsp_fast import conversion as cv  # noqa: E402
from bsp_fast.conversion.sharded import shard_dir  # noqa: E402
from bsp_testdata import corrupt_apng_frame  # noqa: E402

OPTS = dict(clip_length=8, clip_offset=4, crop_size=24, val_frac=0.3, test_frac=0.3, seed=5)
SPLITS = ("train", "val", "test")
REPO = Path(__file__).resolve().parents[2]
# the tiny dataset has single-class splits (warned about); every split has media
pytestmark = pytest.mark.filterwarnings("ignore:bsp_fast.convert:UserWarning")


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    # the fault-injection spec lives in a file every worker reads, also one restarted
    # after a test killed its predecessor
    hook = tmp_path_factory.mktemp("hook") / "spec"
    old = os.environ.get("BSP_FAST_TEST_DASK_HOOK")
    os.environ["BSP_FAST_TEST_DASK_HOOK"] = f"@{hook}"
    try:
        with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                      dashboard_address=None) as cluster, \
                distributed.Client(cluster) as c:
            c.hook_file = hook
            yield c
    finally:
        if old is None:
            os.environ.pop("BSP_FAST_TEST_DASK_HOOK", None)
        else:
            os.environ["BSP_FAST_TEST_DASK_HOOK"] = old


@pytest.fixture(scope="module")
def ds(tmp_path_factory):
    from bsp_fast.synth import generate

    out = tmp_path_factory.mktemp("dask") / "ds"
    generate(out, "sample", clips=6, frames=90, size="256x96", seed=3, workers=1,
             progress=False)
    return out


@pytest.fixture(scope="module")
def single(ds, tmp_path_factory):
    out = tmp_path_factory.mktemp("single") / "clips.h5"
    cv.convert(ds, out, threads=2, **OPTS)
    return out


def read_all(path):
    """Every dataset's values and every group's attributes, by name."""
    out = {}

    def visit(name, obj):
        if isinstance(obj, h5py.Dataset):
            out[name] = obj.asstr()[...] if obj.dtype.kind == "O" else obj[...]
        else:
            out[name + "/@"] = {k: obj.attrs[k] for k in obj.attrs}

    with h5py.File(path, "r") as f:
        out["@"] = {k: f.attrs[k] for k in f.attrs}
        f.visititems(visit)
    return out


def assert_same(a_path, b_path):
    a, b = read_all(a_path), read_all(b_path)
    assert sorted(a) == sorted(b)
    for k in a:
        if k.endswith("@"):
            assert sorted(a[k]) == sorted(b[k]), k
            for name in a[k]:
                np.testing.assert_array_equal(a[k][name], b[k][name], err_msg=f"{k}{name}")
        else:
            assert a[k].dtype == b[k].dtype and a[k].shape == b[k].shape, k
            np.testing.assert_array_equal(a[k], b[k], err_msg=k)


def test_sharded_output_equals_one_process_for_1_2_and_5_shards(ds, single, client, tmp_path):
    with h5py.File(single) as f:
        assert min(f[f"{s}/clip_frames"].shape[0] for s in SPLITS) > 0  # media in every split
    for shards in (1, 2, 5):
        out = tmp_path / f"s{shards}" / "clips.h5"
        rep = cv.convert(ds, out, client=client, shards=shards, **OPTS)
        assert rep["shards"] == shards and rep["media"]["passes"] == 1
        assert sorted(p.name for p in shard_dir(out).iterdir()) == \
            [f"part-{k:05d}.h5" for k in range(shards)]
        with h5py.File(out) as f:
            assert f["train/projection_2d"].is_virtual and f["test/frames/rgb"].is_virtual
        assert_same(single, out)
        assert not [p for p in out.parent.iterdir() if p.name.startswith(".")]
    # relative sources: the file and its folder moved together still read
    moved = tmp_path / "elsewhere"
    shutil.move(str(tmp_path / "s2"), moved)
    assert_same(single, moved / "clips.h5")


def test_no_media_and_verify_sharded(ds, client, tmp_path):
    opts = dict(OPTS, media=False, verify=True)
    a = cv.convert(ds, tmp_path / "a.h5", **opts)
    b = cv.convert(ds, tmp_path / "b.h5", client=client, shards=3, **opts)
    assert_same(tmp_path / "a.h5", tmp_path / "b.h5")
    assert a["verify"] == b["verify"] and len(a["verify"]) == a["recordings"] > 0
    with h5py.File(tmp_path / "b.h5") as f:
        assert "frames" not in f["train"] and f.attrs["media"] == 0
    # the tiny dataset has single-class splits: --strict refuses, and leaves nothing
    with pytest.raises(cv.UnusableConversion, match="single class"):
        cv.convert(ds, tmp_path / "c.h5", client=client, strict=True, **opts)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.h5", "b.h5", "b.h5.shards"]


def test_loaders_read_the_virtual_file_unchanged(ds, single, client, tmp_path):
    pytest.importorskip("torch")
    from bsp_fast.data import ClipDataset

    out = tmp_path / "clips.h5"
    cv.convert(ds, out, client=client, shards=3, **OPTS)
    for task in ("classification", "pose_estimation"):
        a, b = ClipDataset(single, "train", task), ClipDataset(out, "train", task)
        assert len(a) == len(b) > 0
        for i in (0, len(a) - 1):
            x, y = a[i], b[i]
            for key in ("inputs", "targets"):
                np.testing.assert_array_equal(np.asarray(x[key]), np.asarray(y[key]))
    # OUT.h5 without its shards folder: HDF5 alone would read zeros; the loaders refuse
    from bsp_fast.data import MissingShardError

    os.replace(shard_dir(out), tmp_path / "moved")
    with pytest.raises(MissingShardError) as info:
        ClipDataset(out, "train", "classification")
    assert str(out) in str(info.value)
    assert str(shard_dir(out) / "part-00000.h5") in str(info.value)
    os.replace(tmp_path / "moved", shard_dir(out))
    assert len(ClipDataset(out, "train", "classification")) == len(a)


def first_video(path):
    with h5py.File(path) as f:
        vid = f["test/meta/video_id"].asstr()[0]
        frames = f["test/targets/frame_idx"][...][f["test/meta/video_id"].asstr()[...] == vid]
    return vid, int(frames.max())


def _error(fn):
    with pytest.raises(bf.Error) as info:
        fn()
    return type(info.value), str(info.value)


def test_bad_media_same_error_or_left_out_the_same(ds, single, client, tmp_path):
    copy = Path(shutil.copytree(ds, tmp_path / "copy"))
    vid, _ = first_video(single)
    (copy / f"{vid}.mp4").unlink()
    one = _error(lambda: cv.convert(copy, tmp_path / "a.h5", **OPTS))
    out = tmp_path / "b.h5"
    assert _error(lambda: cv.convert(copy, out, client=client, shards=2, **OPTS)) == one
    assert "No such file" in one[1] and not out.exists() and not shard_dir(out).exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]
    a = cv.convert(copy, tmp_path / "a.h5", skip_bad_media=True, **OPTS)
    b = cv.convert(copy, out, client=client, shards=2, skip_bad_media=True, **OPTS)
    assert a["media"]["bad"] == [tuple(x) for x in b["media"]["bad"]] and len(a["media"]["bad"]) == 1
    assert a["media"]["passes"] == b["media"]["passes"] == 1
    assert_same(tmp_path / "a.h5", out)


def test_file_damaged_mid_decode_same_error_or_second_pass(ds, single, client, tmp_path):
    copy = Path(shutil.copytree(ds, tmp_path / "copy"))
    vid, last = first_video(single)
    corrupt_apng_frame(copy / (vid[:-2] + "-1.apng"), last)
    one = _error(lambda: cv.convert(copy, tmp_path / "a.h5", **OPTS))
    assert one[0] is bf.ApngError
    assert _error(lambda: cv.convert(copy, tmp_path / "b.h5", client=client, shards=3,
                                     **OPTS)) == one
    a = cv.convert(copy, tmp_path / "a.h5", skip_bad_media=True, **OPTS)
    b = cv.convert(copy, tmp_path / "b.h5", client=client, shards=3, skip_bad_media=True, **OPTS)
    assert a["media"]["passes"] == b["media"]["passes"] == 2
    assert_same(tmp_path / "a.h5", tmp_path / "b.h5")


def _set_hook(client, value):
    if value is None:
        client.hook_file.unlink(missing_ok=True)
    else:
        client.hook_file.write_text(value)


def test_worker_killed_mid_task_is_retried(ds, single, client, tmp_path):
    marker = tmp_path / "killed"
    _set_hook(client, f"kill:shard:1:{marker}")
    try:
        out = tmp_path / "clips.h5"
        cv.convert(ds, out, client=client, shards=2, **OPTS)
    finally:
        _set_hook(client, None)
    assert marker.exists()  # shard 1's first attempt did end its worker process
    assert_same(single, out)
    client.wait_for_workers(2, timeout=60)


def test_cli_interrupted_leaves_no_output(ds, tmp_path):
    out = tmp_path / "clips.h5"
    sleeping = tmp_path.parent / f"{tmp_path.name}-sleeping"  # outside the output folder
    # the signal is sent once a shard task is sleeping (the hook's marker). The child gets
    # SIGINT's default disposition back: a test suite started as a background job (`make
    # test &` without job control) ignores SIGINT, the child inherits SIG_IGN and, like any
    # background job, bsp-convert then leaves Ctrl-C alone (it ran to its end)
    env = dict(os.environ, BSP_FAST_TEST_DASK_HOOK=f"sleep:shard:900:{sleeping}",
               PYTHONPATH=os.pathsep.join([str(REPO / "python"), os.environ.get("PYTHONPATH", "")]))
    p = subprocess.Popen([sys.executable, "-m", "bsp_fast", "convert", str(ds), str(out),
                          "--scheduler", "dask", "--shards", "2", "--crop-size", "24", "--quiet"],
                         env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    t0 = time.time()
    while not sleeping.exists() and time.time() - t0 < 240 and p.poll() is None:
        time.sleep(0.2)
    assert sleeping.exists(), "no shard task started within 240 s"
    time.sleep(0.5)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=120)
    assert p.returncode == 130, err[-2000:]
    assert "interrupted; no output written" in err
    assert list(tmp_path.iterdir()) == []


def test_cli_options(ds, tmp_path, capsys):
    assert cv.main([str(ds), str(tmp_path / "o.h5"), "--scheduler", "spark"]) == 2
    assert "scheduler must be 'threads', 'dask' or 'dask:ADDRESS', got 'spark'" in \
        capsys.readouterr().err
    assert cv.main([str(ds), str(tmp_path / "o.h5"), "--shards", "2"]) == 2
    assert "--shards needs --scheduler dask" in capsys.readouterr().err
    with pytest.raises(ValueError, match="shards must be a positive integer"):
        cv.convert(ds, tmp_path / "o.h5", shards=0)


def test_synth_on_dask_is_byte_identical(client, tmp_path):
    from bsp_fast.synth import generate

    # seed 11: every walker enters the view (seed 9's clips 0 and 2 have no rows, hence no
    # media files since issue 28)
    kw = dict(clips=3, frames=30, size="160x60", seed=11, progress=False)
    a = generate(tmp_path / "a", "sample", workers=1, **kw)
    marker = tmp_path / "killed"
    _set_hook(client, f"kill:clip:1:{marker}")
    try:
        b = generate(tmp_path / "b", "sample", client=client, **kw)
    finally:
        _set_hook(client, None)
    assert marker.exists() and a["ids"] == b["ids"]
    files = sorted(str(p.relative_to(tmp_path / "a")) for p in (tmp_path / "a").rglob("*")
                   if p.is_file())
    assert len(files) == 2 + 2 * 3
    assert files == sorted(str(p.relative_to(tmp_path / "b")) for p in (tmp_path / "b").rglob("*")
                           if p.is_file())
    match, mismatch, errors = filecmp.cmpfiles(tmp_path / "a", tmp_path / "b", files, shallow=False)
    assert mismatch == [] and errors == []
    client.wait_for_workers(2, timeout=60)


def test_refused_csv_is_the_same_error(client, tmp_path):
    sys.path.insert(0, str(Path(__file__).parent))
    from bsp_testdata import recording, write_dataset

    rows = recording("094b9fe1-babe-48d5-bd17-3ba3185690c5-0", range(20))
    for r in rows:
        r["camera.recording"] = "/etc/passwd"
    root = write_dataset(tmp_path / "ds", rows)
    one = _error(lambda: cv.convert(root, tmp_path / "a.h5"))
    assert "is absolute" in one[1]
    assert _error(lambda: cv.convert(root, tmp_path / "b.h5", client=client)) == one
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ds"]


def test_relative_paths_reach_the_workers_and_errors_read_the_same(ds, single, client, tmp_path,
                                                                    monkeypatch):
    shutil.copytree(ds, tmp_path / "rel")
    vid, _ = first_video(single)
    (tmp_path / "rel" / f"{vid}.mp4").unlink()
    monkeypatch.chdir(tmp_path)
    one = _error(lambda: cv.convert("rel", "a.h5", **OPTS))
    assert one[1].startswith(f"rel/{vid}.mp4: ")
    assert _error(lambda: cv.convert("rel", "b.h5", client=client, shards=2, **OPTS)) == one
    a = cv.convert("rel", "a.h5", skip_bad_media=True, **OPTS)
    b = cv.convert("rel", "b.h5", client=client, shards=2, skip_bad_media=True, **OPTS)
    assert a["media"]["bad"] == [tuple(x) for x in b["media"]["bad"]]
    assert_same(tmp_path / "a.h5", tmp_path / "b.h5")
