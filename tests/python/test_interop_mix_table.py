"""MixedDataModule.from_config by table name, and the clip-length checks."""
import pytest

pytest.importorskip("torch")

from bsp_fast.data.mixed import MixedDataModule, mix_dirs, mix_table  # noqa: E402
from bsp_fast.data.testing import write_clip_file  # noqa: E402

NAMES = ("jaad", "carla_bsp", "amass")


def _files(root, length):
    out = {}
    for k, name in enumerate(NAMES):
        write_clip_file(root / f"{name}.h5", clips=(8, 2, 2), clip_length=length, seed=k)
        out[name] = root / f"{name}.h5"
    return out


def test_table_name_finds_the_installed_yaml(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # not the source tree: found through the package's location
    path = mix_table("autoencoder")
    assert path.name == "autoencoder.yaml" and path.parent.name == "mix"
    files = _files(tmp_path, 30)
    dm = MixedDataModule.from_config("autoencoder", files, batch_size=4, seed=1)
    assert [s["name"] for s in dm.sources] == list(NAMES)
    assert [s["share"] for s in dm.sources] == [0.1, 0.4, 0.5]
    with pytest.raises(FileNotFoundError, match=r"no mixing table 'nope'.*autoencoder"):
        mix_table("nope")


def test_own_tables_by_name_through_bsp_experiments(tmp_path, monkeypatch):
    (tmp_path / "mine" / "mix").mkdir(parents=True)
    (tmp_path / "mine" / "mix" / "half.yaml").write_text(
        "task: autoencoder\nclip_length: 8\nsources:\n"
        "  - {name: jaad, share: 0.5}\n  - {name: amass, share: 0.5}\n")
    monkeypatch.setenv("BSP_EXPERIMENTS", str(tmp_path / "mine"))
    assert mix_dirs()[0] == tmp_path / "mine" / "mix"
    files = _files(tmp_path, 8)
    dm = MixedDataModule.from_config("half", files, batch_size=4, seed=1)
    assert [s["name"] for s in dm.sources] == ["jaad", "amass"]


def test_clip_lengths_are_checked_against_the_table_and_each_other(tmp_path):
    files = _files(tmp_path, 8)
    with pytest.raises(ValueError, match=r"clip_length 30, but source 'jaad' .* has 8.*"
                                         r"--clip-length 30"):
        MixedDataModule.from_config("autoencoder", files)
    write_clip_file(tmp_path / "other.h5", clips=(8, 2, 2), clip_length=4)
    table = tmp_path / "t.yaml"
    table.write_text("task: autoencoder\nsources:\n  - {name: jaad, share: 0.5}\n"
                     "  - {name: amass, share: 0.5}\n")
    with pytest.raises(ValueError, match="different clip lengths"):
        MixedDataModule.from_config(table, {"jaad": files["jaad"],
                                            "amass": tmp_path / "other.h5"})


def test_the_documented_snippet_runs_verbatim(tmp_path, monkeypatch, capsys):
    """docs/interop.md's mixed-training block, exactly as printed, on three small clip
    files named as it names them (30 frames, the table's clip length)."""
    import re
    from pathlib import Path

    from bsp_fast.data.testing import write_clip_file

    page = (Path(__file__).resolve().parents[2] / "docs" / "interop.md").read_text()
    section = page.split("## Mixed training", 1)[1]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    monkeypatch.chdir(tmp_path)
    for k, name in enumerate(("jaad.h5", "carla.h5", "amass.h5")):
        write_clip_file(tmp_path / name, clips=(48, 16, 16), clip_length=30, seed=k)
    exec(compile(code, "docs/interop.md", "exec"), {"__name__": "__snippet__"})
    assert "tensor(" in capsys.readouterr().out  # the val loss it prints
