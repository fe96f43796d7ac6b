"""Every command answers at once: ``--help`` and argument or input errors come before
PyTorch or Lightning is imported, in one line, with a "did you mean" for names; and the
new user's frictions of the front-door issue, each run as the user ran it."""
import json
import subprocess
import sys
from pathlib import Path

import h5py
import pytest

from bsp_fast.command_line import did_you_mean

COMMANDS = {"bsp-synth": "bsp_fast.synth.cli", "bsp-convert": "bsp_fast.conversion.cli",
            "bsp-train": "bsp_fast.training.train", "bsp-eval": "bsp_fast.training.evaluate",
            "bsp-predict": "bsp_fast.training.predict",
            "bsp-reproduce": "bsp_fast.reproduction.cli", "bsp-preview": "bsp_fast.preview.cli",
            "bsp-check": "bsp_fast.check.cli", "bsp-cache": "bsp_fast.data.cache_cli",
            "bsp-interop": "bsp_fast.interop.cli"}

# runs a command's main() in a fresh interpreter, then says which heavy modules it imported
_PROBE = """
import json, sys
from {module} import main
try:
    code = main({argv!r})
except SystemExit as exc:
    code = exc.code
print(json.dumps({{"code": code, "heavy": sorted(m for m in ("torch", "lightning",
      "torchmetrics") if m in sys.modules)}}))
"""


def _probe(module, argv, cwd=None):
    out = subprocess.run([sys.executable, "-c", _PROBE.format(module=module, argv=list(argv))],
                         capture_output=True, text=True, cwd=cwd, timeout=120)
    result = json.loads(out.stdout.strip().splitlines()[-1])
    return result["code"], result["heavy"], out.stderr


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_help_imports_neither_torch_nor_lightning(command):
    code, heavy, _ = _probe(COMMANDS[command], ["--help"])
    assert code == 0 and heavy == [], (command, heavy)


def _one_line_error(err: str) -> str:
    lines = [x for x in err.splitlines() if x.strip()]
    assert len(lines) == 1, err
    return lines[0]


@pytest.mark.parametrize("command,argv,code,expect", [
    ("bsp-train", ["lifitng", "lstm"], 2, "did you mean 'lifting'?"),
    ("bsp-train", ["lifting", "lstn", "--data", "x.h5"], 2, "did you mean 'lstm'?"),
    ("bsp-train", ["lifting", "lstm", "--data", "x.h5", "--epohcs", "3"], 2,
     "did you mean '--epochs'?"),
    ("bsp-train", ["lifting", "lstm", "--data", "x.h5", "--hp", "hiden_size=8"], 2,
     "did you mean 'hidden_size'?"),
    ("bsp-train", ["lifting", "lstm", "--data", "/nope.h5"], 1, "/nope.h5: no such dataset"),
    ("bsp-eval", ["/nope"], 1, "/nope: no such run directory or checkpoint"),
    ("bsp-eval", ["/nope", "--splt", "val"], 2, "did you mean '--split'?"),
    ("bsp-predict", ["/nope", "--out", "p.h5"], 1, "/nope: no such run directory"),
    ("bsp-reproduce", ["clasification", "--data", "x"], 2, "did you mean 'classification'?"),
    ("bsp-reproduce", ["classification", "--data", "/nope"], 1, "--data /nope: no such"),
    ("bsp-reproduce", ["classification", "--data", ".", "--set", "epohcs=1"], 2,
     "did you mean 'epochs'?"),
    ("bsp-interop", ["imprt"], 2, "did you mean 'import'?"),
    ("bsp-interop", ["export", "coco", "../nope.h5", "out.json"], 1,
     "../nope.h5: no such file or folder"),
])
def test_argument_errors_are_one_line_before_torch(tmp_path, command, argv, code, expect):
    got, heavy, err = _probe(COMMANDS[command], argv, cwd=tmp_path)
    line = _one_line_error(err)
    assert got == code and expect in line and heavy == [], (got, heavy, err)


# every command, one error class each: the same exit code (docs/architecture.md, "Exit codes")
MISSING_INPUT = {"bsp-synth": ["out", "--config", "/nope.yaml"],
                 "bsp-convert": ["/nope", "o.h5"],
                 "bsp-train": ["lifting", "lstm", "--data", "/nope.h5"],
                 "bsp-eval": ["/nope"], "bsp-predict": ["/nope", "--out", "p.h5"],
                 "bsp-reproduce": ["classification", "--data", "/nope"],
                 "bsp-preview": ["clips", "/nope.h5", "--out", "x.png"],
                 "bsp-check": ["/nope"], "bsp-cache": ["where", "/nope"],
                 "bsp-interop": ["export", "coco", "/nope.h5", "o.json"]}


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_every_command_a_missing_input_is_1_and_a_bad_option_2(tmp_path, command):
    assert sorted(MISSING_INPUT) == sorted(COMMANDS)
    got, heavy, err = _probe(COMMANDS[command], MISSING_INPUT[command], cwd=tmp_path)
    line = _one_line_error(err)
    assert (got, heavy) == (1, []) and line.startswith(f"{command}: ") and "/nope" in line, err
    got, heavy, err = _probe(COMMANDS[command], [*MISSING_INPUT[command], "--no-such-option"],
                             cwd=tmp_path)
    line = _one_line_error(err)
    assert (got, heavy) == (2, []) and f"(see {command} --help)" in line, err


# an existing output, each command's own (bsp-eval, bsp-predict and bsp-reproduce write
# theirs only after a run is found: their FileExistsError is the ladder's case below)
EXISTING_OUTPUT = {"bsp-synth": ["out"], "bsp-convert": ["ds", "o.h5", "--no-media"],
                   "bsp-train": ["lifting", "lstm", "--data", "c.h5", "--out", "out"],
                   "bsp-preview": ["clips", "c.h5", "--out", "o.png"],
                   "bsp-check": ["ds", "--fix", "out"],
                   "bsp-interop": ["export", "coco", "c.h5", "o.json"]}


def test_an_existing_output_is_3_for_every_command_that_names_one(tmp_path):
    from bsp_testdata import recording, write_dataset
    from bsp_fast.data.testing import write_clip_file

    write_clip_file(tmp_path / "c.h5", clips=(4, 2, 2), clip_length=4, seed=1)
    write_dataset(tmp_path / "ds", recording("r0", range(20), crossing_from=10))
    (tmp_path / "out").mkdir()
    for name in ("o.h5", "o.png", "o.json"):
        (tmp_path / name).write_bytes(b"")
    for command, argv in EXISTING_OUTPUT.items():
        got, heavy, err = _probe(COMMANDS[command], argv, cwd=tmp_path)
        line = _one_line_error(err)
        assert (got, heavy) == (3, []) and "exists" in line, (command, err)


def test_every_command_goes_through_the_one_ladder():
    """Each command's main() hands its work to command_line.run_command."""
    import ast
    import importlib

    for command, module in COMMANDS.items():
        source = Path(importlib.import_module(module).__file__).read_text()
        main = next(n for n in ast.parse(source).body
                    if isinstance(n, ast.FunctionDef) and n.name == "main")
        calls = {c.func.id for c in ast.walk(main)
                 if isinstance(c, ast.Call) and isinstance(c.func, ast.Name)}
        assert "run_command" in calls, command


def test_the_ladder_maps_each_error_class_to_its_code(capsys):
    import bsp_fast
    from bsp_fast.atomic import OutputOverlapError
    from bsp_fast.command_line import EXIT, BadInput, exit_code
    from bsp_fast.conversion import BadDataset

    cases = [(ValueError("bad value"), EXIT["usage"]), (OutputOverlapError("o"), EXIT["usage"]),
             (FileNotFoundError("/nope: no such file"), EXIT["failure"]),
             (OSError("disk full"), EXIT["failure"]), (ImportError("no cv2"), EXIT["failure"]),
             (BadInput("x.h5: no group"), EXIT["failure"]),
             (BadDataset("config.yaml"), EXIT["failure"]),
             (bsp_fast.VideoDecodeError("a.mp4: broken"), EXIT["failure"]),
             (FileExistsError("out exists"), EXIT["exists"]),
             (KeyboardInterrupt(), EXIT["interrupted"])]
    for exc, code in cases:
        assert exit_code("bsp-x", exc) == code, exc
        line = _one_line_error(capsys.readouterr().err)
        assert line.startswith("bsp-x: "), line
    stopped = KeyboardInterrupt("terminated; no output written")
    stopped.code = 143
    assert exit_code("bsp-x", stopped) == 143
    assert capsys.readouterr().err == "bsp-x: terminated; no output written\n"
    exit_code("bsp-x", bsp_fast.VideoDecodeError("a.mp4: broken"))
    assert capsys.readouterr().err == "bsp-x: VideoDecodeError: a.mp4: broken\n"
    exit_code("bsp-x", KeyboardInterrupt("no output written"))
    assert capsys.readouterr().err == "bsp-x: interrupted; no output written\n"
    assert exit_code("bsp-x", RuntimeError("a bug")) is None  # re-raised by run_command


def test_output_equal_to_its_input_is_refused_before_torch(tmp_path):
    (tmp_path / "x.h5").write_bytes(b"")
    got, heavy, err = _probe(COMMANDS["bsp-train"],
                             ["lifting", "lstm", "--data", "x.h5", "--out", "x.h5"], tmp_path)
    assert got == 2 and heavy == [] and "refusing" in _one_line_error(err)


def test_did_you_mean_only_for_close_names():
    assert did_you_mean("lifitng", ["lifting", "autoencoder"]) == " (did you mean 'lifting'?)"
    assert did_you_mean("zzz", ["lifting", "autoencoder"]) == ""


def test_model_list_without_torch_is_the_registry():
    from bsp_fast import models
    from bsp_fast.models.catalogue import catalogue

    for task in models.TASKS:
        assert list(catalogue()[task]) == list(models.available(task))
        for name, entry in catalogue()[task].items():
            assert entry.description == models.available(task)[name]
            assert entry.hparams == models.hparams_of(task, name), (task, name)


# ---------------------------------------------------------------------- the frictions
def _run(*argv, cwd):
    return subprocess.run(list(argv), capture_output=True, text=True, cwd=cwd, timeout=600)


@pytest.fixture(scope="module")
def poses_only(tmp_path_factory):
    root = tmp_path_factory.mktemp("front_door")
    r = _run("bsp-synth", "s", "--clips", "6", "--frames", "40", "--size", "96x64",
             "--poses-only", "--quiet", "--seed", "5", cwd=root)
    assert r.returncode == 0, r.stderr
    return root


def test_a_poses_only_dataset_converts_without_a_flag(poses_only):
    r = _run("bsp-convert", "s", "s.h5", "--verify", cwd=poses_only)
    assert r.returncode == 0, r.stderr
    assert "media: none (the dataset's config.yaml says poses_only: true)" in r.stdout
    with h5py.File(poses_only / "s.h5") as f:
        assert json.loads(f.attrs["settings_json"])["media"] is False
    r = _run("bsp-convert", "s", "m.h5", "--crop-size", "32", "--force", cwd=poses_only)
    assert r.returncode == 0  # media options alone do not ask for media it has not
    from bsp_fast import convert

    with pytest.raises(ValueError, match="poses_only: true.*--no-media"):
        convert(poses_only / "s", poses_only / "x.h5", media=True)


def test_missing_media_names_both_ways_out(tmp_path):
    r = _run("bsp-synth", "m", "--clips", "4", "--frames", "60", "--size", "96x64",
             "--quiet", "--seed", "5", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    for video in (tmp_path / "m" / "clips").glob("*.mp4"):
        video.unlink()
    r = _run("bsp-convert", "m", "m.h5", "--clip-length", "8", cwd=tmp_path)
    line = _one_line_error(r.stderr)
    assert r.returncode == 1 and "--no-media" in line and "--skip-bad-media" in line


def test_few_updates_per_epoch_are_said():
    from bsp_fast.training.train import few_updates

    note = few_updates({"batch_size": 256, "epochs": 5, "max_steps": 0}, 40)
    assert "1 update(s) per epoch, 5 in all" in note and "--batch-size (e.g. 4)" in note
    assert few_updates({"batch_size": 8, "epochs": 5, "max_steps": 0}, 40) is None
    assert few_updates({"batch_size": 256, "epochs": 5, "max_steps": 100}, 40) is None


def test_help_texts_say_what_options_are(tmp_path):
    help_predict = _run("bsp-predict", "--help", cwd=tmp_path).stdout
    assert "(default: None)" not in help_predict and "where to train" not in help_predict
    assert "(default: the run's) (default" not in help_predict
    help_interop = _run("bsp-interop", "export", "coco", "--help", cwd=tmp_path).stdout
    assert "output, with --results" in " ".join(help_interop.split())
    help_import = _run("bsp-interop", "import", "coco", "--help", cwd=tmp_path).stdout
    assert "input: a COCO-style JSON" in " ".join(help_import.split())
    help_reproduce = _run("bsp-reproduce", "--help", cwd=tmp_path).stdout
    # one option set: bsp-train's options only through --set, one way to name a table
    assert "--table" not in help_reproduce
    for flag in ("--epochs", "--batch-size", "--lr", "--precision", "--workers", "--noise"):
        assert flag not in help_reproduce, flag


def test_write_images_without_opencv_is_one_line(tmp_path):
    from bsp_fast.data.testing import write_clip_file

    write_clip_file(tmp_path / "c.h5", clips=(4, 2, 2), clip_length=4, seed=1)
    code = ("import sys; sys.modules['cv2'] = None\n"
            "from bsp_fast.interop.cli import main\n"
            "sys.exit(main(['export', 'coco', 'c.h5', 'o.json', '--write-images', 'img']))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       cwd=tmp_path, timeout=120)
    line = _one_line_error(r.stderr)
    assert r.returncode == 1 and "pip install 'bsp_fast[preview]'" in line
    assert not (tmp_path / "o.json").exists()


def test_eval_output_explains_or_hides_the_normaliser_fallback():
    from bsp_fast._plain_progress import readable

    assert readable({"mpjpe_mm": 3.0, "normaliser_fallback": 0.0}) == {"mpjpe_mm": 3.0}
    assert readable({"val/normaliser_fallback": 0.5}) == {"val/normaliser_fallback": 0.5}


def test_classification_predictions_carry_no_pixel_units():
    from bsp_fast.training.tasks import get_task

    assert get_task("classification").prediction_units is None
    assert get_task("lifting").prediction_units == "metres"


def test_bench_cli_latency_smoke(capsys):
    """benchmarks/bench_cli_latency.py, its --help rows once."""
    import importlib.util

    path = Path(__file__).resolve().parents[2] / "benchmarks" / "bench_cli_latency.py"
    spec = importlib.util.spec_from_file_location("bench_cli_latency", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    result = bench.run(1, "help")
    assert [r["exit"] for r in result["rows"]["help"]] == [0] * len(bench.HELP)
    text = bench.table(result)
    assert text.count("| help |") == len(bench.HELP) and "median of 1" in text
