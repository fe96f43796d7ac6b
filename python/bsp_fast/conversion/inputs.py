"""The dataset's inputs as bsp-convert sees them: where data.csv is, the FOV of its
config.yaml, and which output paths would overwrite an input (issue 15: a downloaded
dataset is untrusted input)."""
from __future__ import annotations

import math
import os
from pathlib import Path

from .errors import BadDataset

__all__ = ["dataset_csv", "dataset_fov", "refuse_inputs_as_output"]


def dataset_csv(dataset) -> tuple[Path, Path]:
    """(dataset folder, its data.csv) from either; FileNotFoundError naming the path."""
    p = Path(dataset)
    if p.is_dir():
        csv = p / "data.csv"
        if not csv.is_file():
            raise FileNotFoundError(f"{p}: not a CARLA-BSP dataset (no data.csv inside)")
        return p, csv
    if p.is_file():
        return p.parent, p
    raise FileNotFoundError(f"{p}: no such dataset directory or data.csv file")


def dataset_fov(root: Path):
    """FOV from a bsp-synth config.yaml beside data.csv, if there is one; BadDataset when
    the file is not YAML, its top level not a mapping, or its FOV not a number in (0, 180)."""
    cfg = root / "config.yaml"
    if not cfg.is_file():
        return None
    import yaml

    try:
        doc = yaml.safe_load(cfg.read_text(encoding="utf-8"))
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        raise BadDataset(f"{cfg}: not a readable YAML file: {exc}") from None
    if doc is None:
        return None
    if not isinstance(doc, dict):
        raise BadDataset(f"{cfg}: expected a mapping (key: value lines) at the top level, "
                         f"found a {type(doc).__name__}")
    for key in ("fov", "camera_fov"):
        if key in doc:
            v = doc[key]
            if (not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v)
                    or not 0 < v < 180):
                raise BadDataset(f"{cfg}: {key} must be a number of degrees in (0, 180), "
                                 f"got {v!r}")
            return float(v)
    return None


def refuse_inputs_as_output(root: Path, csv: Path, out: Path) -> None:
    """ValueError when `out` is (or resolves, through symlinks, to) one of the dataset's
    inputs: data.csv, config.yaml, or a media or CSV file inside the dataset directory."""
    real = Path(os.path.realpath(out))
    for inp in (csv, root / "config.yaml"):
        if real == Path(os.path.realpath(inp)) or (
                out.exists() and inp.exists() and os.path.samefile(out, inp)):
            raise ValueError(f"output {out} is the dataset's input {inp}; refusing to "
                             "overwrite it (choose another output path)")
    inside = Path(os.path.realpath(root)) in real.parents
    if inside and real.suffix.lower() in (".csv", ".mp4", ".apng", ".png", ".yaml"):
        raise ValueError(f"output {out} would replace the dataset's {real.suffix} file "
                         f"{real}; refusing to overwrite an input (choose another output path)")
