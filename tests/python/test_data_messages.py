"""What the data path tells a user: a dataset's clip file reused or converted again (once
per run; a plain .h5 is not compared), a .h5 converted with other options named option by
option, pose estimation refused on a poses-only dataset, the cache's size said, listed and
pruned, and bsp-eval finding the run's dataset folder from its config."""
from __future__ import annotations

import os
import re
import shutil
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _console_scripts() -> dict:
    """[project.scripts] of pyproject.toml: {name: "module:function"}."""
    text = (ROOT / "pyproject.toml").read_text()
    block = text.split("[project.scripts]\n", 1)[1].split("\n[", 1)[0]
    return dict(re.findall(r'^(bsp-[\w-]+) = "([\w.:]+)"', block, re.M))



def _uuid(k: int) -> str:
    return f"{k:08x}-0000-4000-8000-000000000000-0"


@pytest.fixture(scope="module")
def small_ds(tmp_path_factory):
    from bsp_testdata import recording, write_dataset

    rows = []
    for k in range(8):
        rows += recording(_uuid(k), range(36), crossing_from=18 if k % 2 else None, seed=k)
    return write_dataset(tmp_path_factory.mktemp("src") / "ds", rows)


@pytest.fixture()
def ds(small_ds, tmp_path):
    return shutil.copytree(small_ds, tmp_path / "ds")


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_reusing_is_said_once_per_run_and_rightly_for_a_plain_h5(ds, capsys):
    from bsp_fast.data import BSPDataModule

    BSPDataModule(ds, clip_length=12).prepare_data()
    capsys.readouterr()
    dm = BSPDataModule(ds, clip_length=12)
    # bsp-train: prepare_data, setup, then Lightning's fit and test call prepare_data again
    dm.prepare_data()
    dm.setup("fit")
    dm.prepare_data()
    dm.setup("test")
    dm.prepare_data()
    err = capsys.readouterr().err
    assert err == (f"bsp_fast.data: reusing {dm.h5_path} (same conversion options and "
                   "data.csv)\n")
    plain = BSPDataModule(h5_path=dm.h5_path, clip_length=12)
    plain.prepare_data()
    plain.setup("fit")
    plain.prepare_data()
    err = capsys.readouterr().err
    assert err == (f"bsp_fast.data: using {dm.h5_path} (no dataset directory given: not "
                   "compared with a data.csv)\n")
    assert "data.csv)" not in err.replace("a data.csv)", "")


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_a_plain_h5_that_differs_names_the_options(ds, tmp_path):
    import bsp_fast as bf
    from bsp_fast.data import BSPDataModule

    h5 = tmp_path / "mine.h5"
    bf.convert(ds, h5, clip_length=12, clip_offset=6, media=False)
    with pytest.raises(ValueError) as e:
        BSPDataModule(h5_path=h5, clip_length=12, clip_offset=4).setup()
    msg = str(e.value)
    assert msg.startswith(f"{h5} was converted with other options: --clip-offset 4 vs 6 in "
                          "the file. Use the file's values"), msg
    with pytest.raises(ValueError, match=r"--clip-length 16 vs 12 in the file, --clip-offset "
                                         r"4 vs 6 in the file\. "):
        BSPDataModule(h5_path=h5, clip_length=16, clip_offset=4).setup()
    BSPDataModule(h5_path=h5, clip_length=12, clip_offset=6).setup()  # the file's values


def test_describe_difference_names_each_option():
    from bsp_fast.data.cache import describe_difference

    assert describe_difference({"clip_offset": 30, "balance": False, "fov": 90.0},
                               {"clip_offset": 4, "balance": True, "fov": 90.0}) == \
        "--balance on vs off in the file, --clip-offset 4 vs 30 in the file"
    assert describe_difference({"media": True}, {"media": False}) == \
        "media (off: --no-media) off vs on in the file"


@pytest.fixture(scope="module")
def poses_only(tmp_path_factory):
    from bsp_fast.synth import generate

    out = tmp_path_factory.mktemp("po") / "ds"
    generate(out, "sample", clips=3, frames=40, size="160x96", seed=3, workers=1,
             poses_only=True, progress=False)
    return out


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_pose_estimation_on_a_poses_only_dataset_says_so(poses_only, tmp_path, capsys):
    from bsp_fast.data import BSPDataModule
    from bsp_fast.training.train import main

    with pytest.raises(ValueError) as e:
        BSPDataModule(poses_only, task="pose_estimation", clip_length=8).prepare_data()
    msg = str(e.value)
    assert msg.startswith(f"{poses_only} was generated with --poses-only (its config.yaml "
                          "says poses_only: true)"), msg
    assert "pose estimation needs the media" in msg and "mp4" not in msg
    assert not list((poses_only / "bsp_fast-cache").glob("*.h5"))  # nothing converted
    code = main(["pose_estimation", "pose_cnn", "--data", str(poses_only), "--clip-length",
                 "8", "--epochs", "1", "--out", str(tmp_path / "run"), "--quiet"])
    err = capsys.readouterr().err
    assert code == 1 and "--poses-only" in err and "cannot open" not in err, err
    # the pose tasks are still fine on it
    BSPDataModule(poses_only, task="lifting", clip_length=8, verbose=False).prepare_data()


# ------------------------------------------------------------------ 7: the cache
@pytest.mark.filterwarnings("ignore::UserWarning")
def test_cache_size_is_said_listed_and_pruned_least_recently_used(ds, capsys):
    import time

    from bsp_fast.data import BSPDataModule
    from bsp_fast.data import cache as C
    from bsp_fast.data.cache_cli import main

    folder = ds / "bsp_fast-cache"
    dms = []
    for k, offset in enumerate((12, 6, 4)):
        dm = BSPDataModule(ds, clip_length=12, clip_offset=offset)
        dm.prepare_data()
        err = capsys.readouterr().err
        n, size = C.cache_usage(folder)
        assert n == k + 1 and size == sum(d.h5_path.stat().st_size for d in dms + [dm])
        # said before converting (what the cache holds) and after (what it now holds)
        assert f"first use of these options; cache {folder}: {k} file(s)" in err, err
        assert (f"added {C.format_bytes(dm.h5_path.stat().st_size)} to the cache {folder}: "
                f"{k + 1} file(s), {C.format_bytes(size)} (bsp-cache ls / bsp-cache prune "
                f"{ds})") in err, err
        dms.append(dm)
    # last use: the o12 file is used again now, so o6 is the least recently used
    for j, dm in enumerate(dms):
        past = time.time() - 3600 * (10 - j)
        os.utime(dm.h5_path, (past, past))
    BSPDataModule(ds, clip_length=12, clip_offset=12).prepare_data()
    assert "reusing" in capsys.readouterr().err
    order = [e["path"] for e in C.cache_entries(folder)]
    assert order == [dms[1].h5_path, dms[2].h5_path, dms[0].h5_path]
    assert main(["ls", str(ds)]) == 0
    out = capsys.readouterr().out.splitlines()
    total = sum(e["bytes"] for e in C.cache_entries(folder))
    assert out[0] == f"{folder}: 3 file(s), {C.format_bytes(total)}"
    assert [line.split()[4] for line in out[1:]] == [p.name for p in order]
    assert "offset 6" in out[1] and "label last" in out[1]
    assert main(["where", str(ds)]) == 0 and capsys.readouterr().out.strip() == str(folder)
    # prune to the size of the newest two: the least recently used one goes
    keep = dms[0].h5_path.stat().st_size + dms[2].h5_path.stat().st_size
    assert main(["prune", str(ds), "--max-size", str(keep), "--dry-run"]) == 0
    assert "would remove " + dms[1].h5_path.name in capsys.readouterr().out
    assert dms[1].h5_path.exists()
    assert main(["prune", str(ds), "--max-size", str(keep)]) == 0
    assert capsys.readouterr().out.startswith("removed " + dms[1].h5_path.name)
    assert sorted(p.name for p in folder.glob("*.h5")) == sorted(
        [dms[0].h5_path.name, dms[2].h5_path.name])
    assert main(["prune", str(ds), "--keep", "1"]) == 0
    assert [p.name for p in folder.glob("*.h5")] == [dms[0].h5_path.name]
    with pytest.raises(SystemExit) as exc:  # no limit given: refuses to guess
        main(["prune", str(ds)])
    assert exc.value.code == 2
    assert "--max-size SIZE, --keep N or --all" in capsys.readouterr().err
    assert main(["prune", str(ds), "--all"]) == 0 and not list(folder.glob("*.h5"))
    assert main(["ls", str(ds / "nope")]) == 1  # a missing input, as for every command
    assert main(["prune", str(ds), "--max-size", "lots"]) == 2
    assert "e.g. 500M" in capsys.readouterr().err
    assert C.parse_bytes("1.5G") == 1_500_000_000 and C.parse_bytes("500M") == 500_000_000
    assert C.format_bytes(158_000_000) == "158 MB" and C.format_bytes(1_500) == "1.5 kB"
    assert "bsp-cache" in _console_scripts()


@pytest.mark.filterwarnings("ignore::UserWarning")
@pytest.mark.filterwarnings("ignore::DeprecationWarning")
def test_eval_reads_the_runs_dataset_folder_from_its_config(ds, tmp_path, capsys,
                                                           monkeypatch):
    pytest.importorskip("lightning")
    from bsp_fast.training.evaluate import main as eval_main
    from bsp_fast.training.train import main as train_main

    assert ds == tmp_path / "ds"  # the module's small dataset, copied for this test
    run = tmp_path / "run"
    monkeypatch.chdir(tmp_path)  # trained with --data ds (relative), scored from elsewhere
    assert train_main(["classification", "lstm", "--data", "ds", "--clip-length", "12",
                       "--epochs", "1", "--batch-size", "8", "--threads", "1", "--hp",
                       "hidden_size=8", "--hp", "num_layers=1", "--out", str(run),
                       "--quiet"]) == 0
    capsys.readouterr()
    (tmp_path / "elsewhere").mkdir()
    monkeypatch.chdir(tmp_path / "elsewhere")
    assert eval_main([str(run)]) == 0
    printed = capsys.readouterr()
    assert "no dataset directory given" not in printed.err
    assert "reusing" in printed.err and "same conversion options and data.csv" in printed.err
    assert "test metrics" in printed.out

    # the run's file no longer matches the folder's data.csv: converted again, not scored
    csv = Path(ds) / "data.csv"
    lines = csv.read_text().splitlines(keepends=True)
    csv.write_text("".join(lines[:-12]))  # the last recording loses its last rows
    assert eval_main([str(run)]) == 0
    err = capsys.readouterr().err
    assert "converting again" in err and "no dataset directory given" not in err
