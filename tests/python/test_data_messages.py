"""Issue 28, the rough edges a new user meets: one test (at least) per item."""
from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PYTHON = str(ROOT / "python")


def _console_scripts() -> dict:
    """[project.scripts] of pyproject.toml: {name: "module:function"}."""
    text = (ROOT / "pyproject.toml").read_text()
    block = text.split("[project.scripts]\n", 1)[1].split("\n[", 1)[0]
    return dict(re.findall(r'^(bsp-[\w-]+) = "([\w.:]+)"', block, re.M))


def _env(**extra) -> dict:
    return dict(os.environ, PYTHONPATH=os.pathsep.join([PYTHON] + sys.path), **extra)


# ------------------------------------------------------------------ 13: torchmetrics style
def test_single_metric_classes_and_collection_match_hand_counts():
    import torch
    from torchmetrics import Metric, MetricCollection

    from bsp_fast.metrics import (BinaryAccuracy, BinaryF1Score, BinaryPrecision,
                                  BinaryRecall, ClassificationMetrics,
                                  classification_collection)

    # batch 1 (labels): tp 2, fp 1, fn 1, tn 1; batch 2 (logits, threshold 0 -> 1, 0, 1
    # against 1, 1, 0): tp 1, fn 1, fp 1. In all: tp 3, fp 2, fn 2, tn 1 (by hand).
    batches = [(torch.tensor([1, 1, 0, 0, 1]), torch.tensor([1, 0, 0, 1, 1])),
               (torch.tensor([0.9, -2.0, 3.0]), torch.tensor([1, 1, 0]))]
    want_first = {"precision": 2 / 3, "recall": 2 / 3}
    singles = {"f1": BinaryF1Score(), "precision": BinaryPrecision(),
               "recall": BinaryRecall(), "accuracy": BinaryAccuracy()}
    coll = classification_collection(prefix="val/")
    both = ClassificationMetrics()
    assert isinstance(coll, MetricCollection)
    for m in singles.values():
        assert isinstance(m, Metric)
    for k, (p, t) in enumerate(batches):
        for m in list(singles.values()) + [coll, both]:
            m.update(p, t)
        if k == 0:
            assert float(singles["precision"].compute()) == pytest.approx(want_first["precision"])
            assert float(singles["recall"].compute()) == pytest.approx(want_first["recall"])
    want = {"f1": 6 / (6 + 2 + 2), "precision": 3 / 5, "recall": 3 / 5, "accuracy": 4 / 8}
    for name, m in singles.items():
        value = m.compute()
        assert value.ndim == 0 and value.dtype == torch.float64
        assert float(value) == pytest.approx(want[name]), name
    got = coll.compute()
    assert sorted(got) == ["val/accuracy", "val/f1", "val/precision", "val/recall"]
    for name in want:
        assert float(got[f"val/{name}"]) == pytest.approx(want[name])
        assert float(both.compute()[name]) == pytest.approx(want[name])
    # one set of confusion counts for the four (torchmetrics' compute groups)
    assert len(coll.compute_groups) == 1
    assert singles["f1"].confusion_matrix().tolist() == [[1, 2], [2, 3]]


# ------------------------------------------------------------------ 15: make demo
@pytest.mark.skipif(shutil.which("make") is None, reason="needs make")
def test_make_demo_prints_the_commands_a_user_types():
    scripts = _console_scripts()
    # -o install: do not install; PY=true: run nothing, only the echoed commands print
    r = subprocess.run(["make", "--no-print-directory", "-o", "install", "demo", "PY=true"],
                       cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    assert len(lines) == 5, r.stdout
    for line in lines:
        assert line.startswith("$ "), line
        assert "$(" not in line and "-m bsp_fast" not in line and "build/.python" not in line
        prog = line.split()[1]
        assert prog in scripts or line.startswith("$ python tools/"), line
    assert lines[0] == "$ bsp-synth demo-out/dataset --preset sample --force"
    assert lines[-1] == "$ bsp-eval --table demo-out/runs/lifting-lstm"


# ------------------------------------------------------------------ 2: optional extras
def _without(modules, code: str, cwd=ROOT) -> subprocess.CompletedProcess:
    """Runs python ``code`` with ``modules`` unimportable (as if their extra were not
    installed)."""
    hide = "import sys\n" + "".join(f"sys.modules[{m!r}] = None\n" for m in modules)
    return subprocess.run([sys.executable, "-c", hide + code], cwd=cwd, env=_env(),
                          capture_output=True, text=True, timeout=300)


def test_bsp_preview_without_the_preview_extra_names_it(tmp_path):
    r = _without(["cv2"], "from bsp_fast.__main__ import main\n"
                 f"sys.exit(main(['preview', 'clips', {str(tmp_path / 'c.h5')!r}, "
                 f"'--out', {str(tmp_path / 'x.png')!r}]))")
    assert r.returncode == 1, r.stderr
    assert "Traceback" not in r.stderr
    assert r.stderr.startswith("bsp-preview: bsp-preview needs cv2 (opencv-python-headless), "
                               "which is not installed. Install the 'preview' extra: "
                               "pip install 'bsp_fast[preview]'"), r.stderr
    # the API raises the same ImportError; matplotlib (3D views) names the same extra
    r = _without(["matplotlib"], "from bsp_fast.preview.plot3d import SkeletonFigure\n"
                 "import numpy as np\n"
                 "try:\n    SkeletonFigure([('a', (0, 0))], -np.ones(3), np.ones(3))\n"
                 "except ImportError as e:\n    print(e)\n")
    assert "needs matplotlib" in r.stdout and "pip install 'bsp_fast[preview]'" in r.stdout, \
        r.stdout + r.stderr


def test_scheduler_dask_without_the_distributed_extra_names_it(tmp_path):
    r = _without(["distributed", "dask"], "from bsp_fast.__main__ import main\n"
                 f"sys.exit(main(['synth', {str(tmp_path / 'ds')!r}, '--clips', '1', "
                 "'--scheduler', 'dask', '--quiet']))")
    assert r.returncode == 1 and "Traceback" not in r.stderr, r.stderr
    assert "pip install 'bsp_fast[distributed]'" in r.stderr
    assert not (tmp_path / "ds").exists()


def test_bsp_train_without_jsonargparse_names_the_torch_extra():
    r = _without(["jsonargparse"], "from bsp_fast.__main__ import main\n"
                 "sys.exit(main(['train', '--help']))")
    assert r.returncode == 1 and "Traceback" not in r.stderr, r.stderr
    assert r.stderr.startswith("bsp-train: bsp-train needs jsonargparse, which is not "
                               "installed. Install the 'torch' extra: pip install "
                               "'bsp_fast[torch]'"), r.stderr


def test_logger_without_the_loggers_extra_names_it(tmp_path):
    from bsp_fast._extras import install_hint, require_any

    with pytest.raises(ImportError, match=r"pip install 'bsp_fast\[loggers\]'"):
        require_any(["no_such_module_bsp"], "x", extra="loggers")
    with pytest.raises(ValueError, match="no extra provides 'numpyz'"):
        install_hint("numpyz", "x")
    for kind in ("wandb", "tensorboard"):
        code = (f"import bsp_fast.training.train as t, bsp_fast.training.config as C\n"
                f"cfg = C.defaults() | {{'logger': {kind!r}, 'out': 'r', "
                "'accelerator': 'cpu'}\n"
                "try:\n    t.make_trainer(cfg, __import__('pathlib').Path('r'), '32')\n"
                "except C.ConfigError as e:\n    print('ConfigError:', e)\n")
        r = _without(["wandb", "tensorboard", "tensorboardX"], code, cwd=tmp_path)
        assert (f"ConfigError: --logger {kind} needs {kind}, which is not installed. "
                "Install the 'loggers' extra: pip install 'bsp_fast[loggers]'") in r.stdout, \
            r.stdout + r.stderr[-2000:]
    assert "loggers = [" in (ROOT / "pyproject.toml").read_text()


# ------------------------------------------------------------------ data module messages
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
    assert main(["prune", str(ds)]) == 2  # no limit given: refuses to guess
    assert "--max-size SIZE, --keep N or --all" in capsys.readouterr().err
    assert main(["prune", str(ds), "--all"]) == 0 and not list(folder.glob("*.h5"))
    assert main(["ls", str(ds / "nope")]) == 2
    assert main(["prune", str(ds), "--max-size", "lots"]) == 2
    assert "e.g. 500M" in capsys.readouterr().err
    assert C.parse_bytes("1.5G") == 1_500_000_000 and C.parse_bytes("500M") == 500_000_000
    assert C.format_bytes(158_000_000) == "158 MB" and C.format_bytes(1_500) == "1.5 kB"
    assert "bsp-cache" in _console_scripts()


# ------------------------------------------------------------------ 6: generated data checks clean
def _normalise(text: str) -> str:
    """Output with its time values (``0.21 s``) masked."""
    return re.sub(r"\b\d+\.\d+ s\b", "#.## s", text)


@pytest.fixture(scope="module")
def sample_ds(tmp_path_factory):
    """The documented sample, made as the README makes it: ``bsp-synth sample-ds``."""
    root = tmp_path_factory.mktemp("readme")
    r = subprocess.run([sys.executable, "-m", "bsp_fast", "synth", "sample-ds", "--quiet",
                        "--workers", "2"], cwd=root, env=_env(), capture_output=True,
                       text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    return root


def test_documented_sample_output_blocks_match_their_commands(sample_ds):
    """The output blocks shown for the documented sample (the README had one; issue 54
    moved it to docs/check.md) are what their commands print now."""
    runnable = {"$ bsp-check sample-ds": ["check", "sample-ds"]}
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    # every output block of the README is regenerated here: a new one needs its command
    assert set(re.findall(r"```\n(\$ [^\n]*)\n", readme)) <= set(runnable)
    page = (ROOT / "docs" / "check.md").read_text(encoding="utf-8")
    blocks = [(cmd, shown) for cmd, shown in re.findall(r"```\n(\$ [^\n]*)\n(.*?)```", page,
                                                         re.S) if cmd in runnable]
    assert [cmd for cmd, _ in blocks] == list(runnable), [cmd for cmd, _ in blocks]
    for cmd, shown in blocks:
        r = subprocess.run([sys.executable, "-m", "bsp_fast", *runnable[cmd]], cwd=sample_ds,
                           env=_env(), capture_output=True, text=True, timeout=600)
        assert _normalise(r.stdout) == _normalise(shown), (cmd, r.stdout)
        assert r.returncode == 0


def test_generated_samples_check_clean(sample_ds, tmp_path, capsys):
    from bsp_fast.check import check_dataset
    from bsp_fast.check.cli import main
    from bsp_fast.synth import generate

    rep = check_dataset(sample_ds / "sample-ds")
    assert rep["findings"] == [] and rep["clean"]
    # seed 4: clip 8 has no row (its walker never enters the view): no media for it, and
    # the occlusion warnings of other clips pass without --strict
    s = generate(tmp_path / "s4", "sample", seed=4, clips=9, frames=60, size="320x120",
                 workers=2, progress=False)
    assert s["clips"] == 9 and s["recordings"] == 8
    rep = check_dataset(tmp_path / "s4")
    assert [f for f in rep["findings"] if f["kind"] == "unreferenced_media"] == []
    assert rep["counts"]["error"] == 0
    media = sorted(p.name for p in (tmp_path / "s4" / "clips").iterdir())
    assert len(media) == 2 * 8 and not any(p.startswith(s["ids"][8][:36]) for p in media)
    assert main([str(tmp_path / "s4"), "--quiet"]) == 0
    capsys.readouterr()


def test_warnings_pass_unless_strict(sample_ds, tmp_path, capsys):
    from bsp_fast.check.cli import main

    ds = tmp_path / "ds"
    shutil.copytree(sample_ds / "sample-ds", ds)
    (ds / "clips" / "stray-0.mp4").write_bytes(b"x")  # a warning: unreferenced media
    assert main([str(ds), "--quiet"]) == 0
    assert capsys.readouterr().out == ("Result: no errors, 1 warning(s) (--strict fails on "
                                       "warnings)\n")
    assert main([str(ds), "--quiet", "--strict"]) == 1
    (ds / "clips" / sorted(p.name for p in (ds / "clips").glob("*.apng"))[0]).unlink()
    assert main([str(ds), "--quiet"]) == 1  # an error fails either way
    assert capsys.readouterr().out.endswith("Result: 2 problem(s) found\n")


def test_synth_says_which_clips_have_no_recording(tmp_path):
    r = subprocess.run([sys.executable, "-m", "bsp_fast", "synth", str(tmp_path / "s4"),
                        "--seed", "4", "--clips", "9", "--frames", "60", "--size", "320x120",
                        "--workers", "1"], env=_env(), capture_output=True, text=True,
                       timeout=600)
    assert r.returncode == 0, r.stderr
    assert ("8 recordings: in 1 clip(s) the walker never enters the view (no rows, no media "
            "files)") in r.stdout.splitlines()


# ------------------------------------------------------------------ 1: tables as package data
def _wheel_packages() -> dict:
    """pyproject's tool.scikit-build wheel.packages as {wheel path: source folder}."""
    tomllib = pytest.importorskip("tomllib")
    skb = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["scikit-build"]
    packages = skb["wheel"]["packages"]
    if isinstance(packages, list):  # a list keeps each folder's name
        return {Path(p).name: p for p in packages}
    return dict(packages)


def test_installed_layout_finds_the_tables_outside_the_source_tree(tmp_path):
    """The package as the wheel lays it out (from pyproject's mapping), run from another
    directory: bsp-reproduce finds its tables there, not in a source checkout."""
    site = tmp_path / "site"
    for dest, src in _wheel_packages().items():
        shutil.copytree(ROOT / src, site / dest, dirs_exist_ok=True,
                        ignore=shutil.ignore_patterns("__pycache__"))
    elsewhere = tmp_path / "somewhere" / "else"
    elsewhere.mkdir(parents=True)
    env = dict(os.environ, PYTHONPATH=str(site))  # _core: the installed one (extend_path)
    code = ("from bsp_fast.reproduction import load_table, TABLES\n"
            "for t in TABLES:\n    print(load_table(t)['path'])\n")
    r = subprocess.run([sys.executable, "-c", code], cwd=elsewhere, env=env,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    from bsp_fast.reproduction import TABLES

    assert r.stdout.split() == [str(site / "bsp_fast" / "experiments" / f"{t}.yaml")
                                for t in TABLES]
    for t in TABLES:  # the shipped copy is the source of truth's
        assert (site / "bsp_fast" / "experiments" / f"{t}.yaml").read_bytes() == \
            (ROOT / "experiments" / f"{t}.yaml").read_bytes()
    # and the command runs there (--dry-run: the per-row configs of the smoke budget)
    (tmp_path / "ds").mkdir(exist_ok=True)
    r = subprocess.run([sys.executable, "-m", "bsp_fast", "reproduce", "autoencoder", "--data",
                        str(tmp_path / "ds"), "--budget", "smoke", "--dry-run", "--out", "runs"],
                       cwd=elsewhere, env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "bsp-train --config runs/autoencoder-smoke/configs/" in r.stdout
    assert (elsewhere / "runs" / "autoencoder-smoke" / "configs").is_dir()


def test_reproduce_reads_a_users_own_table_file(tmp_path, capsys):
    from bsp_fast.reproduction import main

    mine = tmp_path / "mine.yaml"
    text = (ROOT / "experiments" / "autoencoder.yaml").read_text()
    mine.write_text(text.replace("table: autoencoder", "table: my_autoencoder", 1))
    assert "table: my_autoencoder" in mine.read_text()
    out = tmp_path / "runs"
    (tmp_path / "ds").mkdir()
    assert main([str(mine), "--data", str(tmp_path / "ds"), "--budget", "smoke",
                 "--dry-run", "--out", str(out)]) == 0
    assert (out / "my_autoencoder-smoke" / "configs").is_dir()
    assert "bsp-train --config" in capsys.readouterr().out
    with pytest.raises(SystemExit) as e:  # one TABLE: a name or a path
        main(["autoencoder", str(mine), "--data", "x"])
    assert e.value.code == 2
    with pytest.raises(SystemExit):
        main(["--data", "x"])
    assert "the following arguments are required: TABLE" in capsys.readouterr().err
    assert main([str(tmp_path / "nope.yaml"), "--data", "x", "--dry-run"]) == 2
    assert "nope.yaml: no such table file" in capsys.readouterr().err
