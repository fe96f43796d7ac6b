"""The cost columns of the reproduced tables: parameters and forward FLOPs per clip of a
row's model (``bsp_fast.models.cost``, counted on a few test clips of the run's own HDF5
file) and its training time (``metrics.json``: wall seconds of ``fit``, and process CPU
seconds where the run recorded them; "≥" where a run's record covers only the last
process of a resumed run)."""
from __future__ import annotations

from pathlib import Path

from ..training.runs import read_run

__all__ = ["COST_HEADER", "run_cost", "cost_cells"]

COST_HEADER = ["params", "MFLOPs/clip", "fit min (wall; CPU)"]


def run_cost(run_dir) -> dict:
    """``{"parameters", "flops_per_clip"}`` of a finished run's best checkpoint (empty when
    its data file is gone)."""
    from ..data import ClipDataset
    from ..models.cost import flops_per_clip, parameter_count
    from ..training.module import load_module
    from ..training.tasks import get_task

    run_dir = Path(run_dir)
    if not (run_dir / "checkpoints" / "best.ckpt").is_file():
        return {}
    cfg = read_run(run_dir)["config"]
    h5 = (cfg.get("resolved") or {}).get("h5")
    if not h5 or not Path(h5).is_file():
        return {}
    module = load_module(run_dir / "checkpoints" / "best.ckpt")
    net = module.net
    options = get_task(cfg["task"]).dataset_options(cfg)
    # train-split settings the data module applies (box jitter, augmentation) are not test
    # clips' and box_jitter is no ClipDataset keyword: counted on plain test clips
    for key in ("box_jitter", "augment"):
        options.pop(key, None)
    ds = ClipDataset(h5, "test", cfg["task"], **options)
    batch = ds[:min(4, len(ds))]
    return {"parameters": parameter_count(net), "flops_per_clip": flops_per_clip(net, batch)}


def cost_cells(run_dirs: list, seconds: list, cost: dict | None = None) -> list:
    """The three cost cells of a row: from its first run's model (``cost``: its
    :func:`run_cost`, already measured), and the mean training time over its runs
    (``seconds``: their ``metrics.json`` seconds)."""
    run_dirs = [d for d in run_dirs if d]
    if cost is None:
        cost = run_cost(run_dirs[0]) if run_dirs else {}
    params = f"{cost['parameters']:,}" if cost else "–"
    flops = f"{cost['flops_per_clip'] / 1e6:,.1f}" if cost else "–"
    fits = [s["fit"] for s in seconds if s and s.get("fit") is not None]
    cpus = [s["fit_cpu"] for s in seconds if s and s.get("fit_cpu") is not None]
    if not fits:
        return [params, flops, "–"]
    t = f"{sum(fits) / len(fits) / 60:.1f}"
    if len(cpus) == len(fits):
        t += f"; {sum(cpus) / len(cpus) / 60:.1f}"
    # a run resumed before fit seconds were carried over resumes recorded its last
    # process's only: the row's mean is a lower bound
    if any(s and s.get("partial") for s in seconds):
        t = "≥ " + t
    return [params, flops, t]
