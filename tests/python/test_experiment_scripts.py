"""Smoke versions of the scripts in experiments/ (the long runs live there, not here)."""
import importlib.util
import json
from pathlib import Path

import pytest

pytest.importorskip("torch")

ROOT = Path(__file__).resolve().parents[2]


def _load(name):
    spec = importlib.util.spec_from_file_location(name, ROOT / "experiments" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def clips(tmp_path_factory):
    import warnings

    from bsp_fast import convert
    from bsp_fast.synth import generate

    root = tmp_path_factory.mktemp("ns")
    generate(root / "ds", "sample", clips=6, frames=60, size="320x120", seed=1,
             poses_only=True, workers=1, progress=False)
    with warnings.catch_warnings():  # a single-class split is fine here
        warnings.simplefilter("ignore", UserWarning)
        convert(root / "ds", root / "c.h5", clip_length=10, media=False, val_frac=0.3,
                test_frac=0.3)
    return root / "c.h5"


def test_normaliser_stats_smoke(clips, tmp_path):
    ns = _load("normaliser_stats")
    assert ns.main([str(clips), "--out", str(tmp_path), "--mjp", "0", "0.5", "0.95",
                    "--sigma", "0", "5"]) == 0
    info = json.loads((tmp_path / "normaliser_stats.json").read_text())
    rows = {(r["sigma"], r["mjp"]): r for r in info["rows"]}
    assert len(rows) == 6 and "| 5 | 0.95 |" in (tmp_path / "normaliser_stats.md").read_text()
    # no missing joint: hips and neck are always there, the normaliser never falls back
    assert rows[(0.0, 0.0)]["fallback_share"] == 0.0
    assert rows[(0.0, 0.0)]["direct_noise_over_scale_median"] == 0.0
    # hips or neck dropped: the fallback share grows with MJP, towards 1 - (1 - p)^2
    shares = [rows[(5.0, m)]["fallback_share"] for m in (0.0, 0.5, 0.95)]
    assert shares[0] == 0.0 < shares[1] < shares[2]
    assert abs(shares[1] - 0.75) < 0.1 and shares[2] > 0.95
    # the noise is the same share of the direct scale whatever the MJP (same frames' sizes)
    assert rows[(5.0, 0.0)]["direct_noise_over_scale_median"] > 0
