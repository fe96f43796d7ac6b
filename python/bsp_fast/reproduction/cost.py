"""The cost of a row's model in a reproduced table: parameters and forward FLOPs per clip
(``bsp_fast.models.cost``, counted on a few test clips of the run's own HDF5 file),
measured once per row by the runner; the table's cost columns render it with the row's
training time (:func:`bsp_fast.reporting.reproduced.cost_cells`)."""
from __future__ import annotations

from pathlib import Path

from ..training.runs import read_run

__all__ = ["run_cost"]


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
