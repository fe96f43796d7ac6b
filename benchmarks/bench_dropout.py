"""The CPU dropout mask (models/dropout.py) and PedestrianGraph's narrower-side GCN sum
against what they replace, side by side in one process (#36).

    PYTHONPATH=python python3 benchmarks/bench_dropout.py [--rounds 6] [--steps 10]
        [--models classification/pedestrian_graph ...] [--json out.jsonl]

Per model, the quick budget's training step (forward, backward, AdamW on one batch of
generated clips, one thread) in up to three variants built from the same seed:
``nn.Dropout`` (every ``models.dropout.Dropout`` swapped back for torch's, as a user's
model would have it), ``bsp`` (the models as shipped) and, for PedestrianGraph,
``nn.Dropout + permuted GCN`` (also the GCN's neighbour sum on the 64-channel side through
permuted copies, the layout before). Variants alternate round by round; the table gives the
median CPU seconds per step (``time.process_time``: steal on a shared machine does not
count) and the ratio to ``nn.Dropout``. First, the mask alone for one PedestrianGraph layer
at batch 64 (1.7 M values): ``bernoulli_`` as ``nn.Dropout`` draws it, and
:func:`keep_mask`.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time

#: (task/model, the quick budget's batch size, clip length)
MODELS = [("classification/pedestrian_graph", 64, 16), ("autoencoder/simple_transformer", 32, 30),
          ("lifting/baseline_3d", 64, 16)]


def _permuted_gcn(self, x, adjacency):
    """The GCN layer before: ``x W`` first, then the (J, J) sum through permuted copies."""
    xw = x @ self.weight
    B, L, J, C = xw.shape
    flat = xw.permute(2, 0, 1, 3).reshape(J, -1)
    return (adjacency @ flat).view(J, B, L, C).permute(1, 2, 0, 3) + self.bias


def _variant(net, name: str):
    """``net`` (a fresh model) turned into variant ``name``; returns its forward hook."""
    from torch import nn

    from bsp_fast.models.dropout import Dropout

    if name != "bsp":
        def back(module):
            for child_name, child in module.named_children():
                if type(child) is Dropout:
                    setattr(module, child_name, nn.Dropout(child.p, inplace=child.inplace))
                else:
                    back(child)
        back(net)
    if name.endswith("permuted GCN"):
        import types
        for conv in (net.conv1, net.conv2):
            conv.forward = types.MethodType(_permuted_gcn, conv)
    return net


def mask_alone(repeat: int = 20) -> dict:
    import torch

    from bsp_fast.models.dropout import keep_mask

    shape = (64, 16, 26, 64)
    out = {}
    for name, fn in (("bernoulli_", lambda: torch.empty(shape).bernoulli_(0.5)),
                     ("keep_mask", lambda: keep_mask(shape, 0.5))):
        fn()
        t = time.process_time()
        for _ in range(repeat):
            fn()
        out[name] = (time.process_time() - t) / repeat
    return out


def bench_model(name: str, batch: int, length: int, rounds: int, steps: int,
                folder: str) -> list:
    import torch

    from bsp_fast import models
    from bsp_fast.data import ClipDataset
    from bsp_fast.data.testing import write_clip_file

    task, model = name.split("/")
    h5 = os.path.join(folder, f"{task}-{length}.h5")
    if not os.path.exists(h5):
        write_clip_file(h5, clips=(batch, 4, 4), clip_length=length,
                        frames_per_recording=8 * length, seed=1, rotations=False)
    b = ClipDataset(h5, "train", task)[list(range(batch))]
    variants = ["nn.Dropout", "bsp"]
    if model == "pedestrian_graph":
        variants.insert(0, "nn.Dropout + permuted GCN")
    nets = {}
    for v in variants:
        torch.manual_seed(1)
        net = _variant(models.create(task, model), v).train()
        nets[v] = (net, net.configure_optimizers(lr=None)["optimizer"])  # always a dict
    cpu = {v: [] for v in variants}
    for _ in range(rounds):
        for v, (net, opt) in nets.items():
            for i in range(steps + 2):  # two warm-up steps per round
                if i == 2:
                    t = time.process_time()
                loss = net.loss(net.forward_batch(b), b)
                opt.zero_grad(set_to_none=True)
                loss.backward()
                opt.step()
            cpu[v].append((time.process_time() - t) / steps)
    med = {v: statistics.median_high(t) for v, t in cpu.items()}  # a measured round's time
    return [{"model": name, "batch": batch, "variant": v, "step_cpu_s": med[v],
             "min_step_cpu_s": min(cpu[v]), "vs_nn_dropout": med["nn.Dropout"] / med[v],
             "rounds": rounds, "steps": steps} for v in variants]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--rounds", type=int, default=6)
    p.add_argument("--steps", type=int, default=10)
    p.add_argument("--models", nargs="+", default=[m[0] for m in MODELS])
    p.add_argument("--json", help="append one JSON line per (model, variant) to this file")
    args = p.parse_args(argv)
    import torch

    from bsp_fast.training.precision import cpu_summary

    torch.set_num_threads(1)
    load = os.getloadavg()[0]
    print(f"CPU: {cpu_summary()}; load average {load:.2f}; one thread; torch "
          f"{torch.__version__}", flush=True)
    m = mask_alone()
    print(f"mask of 1.7 M values, p 0.5: bernoulli_ {m['bernoulli_'] * 1e3:.1f} ms CPU, "
          f"keep_mask {m['keep_mask'] * 1e3:.1f} ms CPU "
          f"(x{m['bernoulli_'] / m['keep_mask']:.1f})", flush=True)
    print("| model | batch | variant | CPU ms per step (median) | min | vs nn.Dropout |\n"
          "|---|---|---|---|---|---|")
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench_dropout_") as tmp:
        for name, batch, length in MODELS:
            if name not in args.models:
                continue
            for r in bench_model(name, batch, length, args.rounds, args.steps, tmp):
                r["load"] = load
                rows.append(r)
                print(f"| {name} | {batch} | {r['variant']} | {r['step_cpu_s'] * 1e3:.1f} | "
                      f"{r['min_step_cpu_s'] * 1e3:.1f} | x{r['vs_nn_dropout']:.2f} |",
                      flush=True)
    print(f"load average at the end {os.getloadavg()[0]:.2f}")
    if args.json:
        with open(args.json, "a", encoding="utf-8") as f:
            for r in rows:
                f.write(json.dumps(dict(r, cpu=cpu_summary(), mask_ms=m)) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
