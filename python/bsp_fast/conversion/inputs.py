"""The dataset's inputs as bsp-convert sees them: where data.csv is, the FOV of its
config.yaml, and which output paths would overwrite an input (issue 15: a downloaded
dataset is untrusted input)."""
from __future__ import annotations

import math
from pathlib import Path

from ..atomic import DATASET_FILES, check_outputs
from .errors import BadDataset

__all__ = ["dataset_csv", "dataset_config", "dataset_fov", "poses_only",
           "refuse_inputs_as_output"]


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


def dataset_config(root) -> dict:
    """The dataset's config.yaml beside data.csv (bsp-synth writes one) as a mapping; {}
    when there is none. BadDataset when the file is not YAML or its top level not a
    mapping."""
    cfg = Path(root) / "config.yaml"
    if not cfg.is_file():
        return {}
    import yaml

    try:
        doc = yaml.safe_load(cfg.read_text(encoding="utf-8"))
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        raise BadDataset(f"{cfg}: not a readable YAML file: {exc}") from None
    if doc is None:
        return {}
    if not isinstance(doc, dict):
        raise BadDataset(f"{cfg}: expected a mapping (key: value lines) at the top level, "
                         f"found a {type(doc).__name__}")
    return doc


def poses_only(root) -> bool:
    """Whether config.yaml says the dataset was generated without media (``bsp-synth
    --poses-only``: data.csv and no MP4/APNG files)."""
    return dataset_config(root).get("poses_only") is True


def dataset_fov(root: Path):
    """FOV from the dataset's config.yaml, if it gives one; BadDataset when the file is not
    YAML, its top level not a mapping, or its FOV not a number in (0, 180)."""
    doc = dataset_config(root)
    cfg = Path(root) / "config.yaml"
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
    """:class:`~bsp_fast.atomic.OutputOverlapError` (a ValueError) when `out` is (or
    resolves, through symlinks, to) one of the dataset's inputs: data.csv, config.yaml, or
    a media or CSV file inside the dataset directory (the rule of
    :func:`bsp_fast.atomic.check_outputs`)."""
    check_outputs(inputs=[("the dataset's input", csv),
                          ("the dataset's input", root / "config.yaml")],
                  outputs=[("output", out)],
                  read_dirs=[("the dataset", root, DATASET_FILES)])
