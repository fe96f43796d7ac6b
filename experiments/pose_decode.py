#!/usr/bin/env python3
"""Decoding ablation of pose_temporal on the same training (#38 item 4): each seed's best
checkpoint scored on the test split with the soft-argmax it was trained and tabled with,
again with DARK (Taylor refinement of the predicted distribution's peak,
``bsp_fast.models.pose_temporal.dark_decode``) and with the soft-argmax and a test-time
flip (``flip_test``: the mirrored crop decoded too, mapped back and averaged).

pose_temporal's loss is the soft-argmax's whatever ``decode`` is, so the ablation table's
``dark`` row (a training with ``hp: {decode: dark}``) would repeat these trainings step for
step and pick the same checkpoints; scoring the table's own checkpoints twice answers it
without training again. The decoding each run was tabled with (its ``hp``) must reproduce
its ``metrics.json`` (checked, printed). Per metric: the difference DARK - soft-argmax over
seeds and test recordings (the tables' two-level bootstrap, t method; the decodings are
the same runs, so seeds and recordings are drawn together), for DARK and for the flip
each against the soft-argmax.

    python experiments/pose_decode.py RUNS/pose_estimation-quick --row pose_temporal \\
        --out DIR

Writes ``DIR/pose_decode.json`` and ``.md`` (``pose_decode-ROW.*`` for another row than
pose_temporal), a seed at a time (``--resume`` keeps the seeds done).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

METRICS = ("pck_0.05", "pck_0.05_visible", "pck_0.05_occluded", "pck_0.05_hands",
           "pck_0.05_feet", "pckhn_0.1")
# each decoding: the model attributes it sets on the trained network
DECODES = {"soft_argmax": {"decode": "soft_argmax", "flip_test": False},
           "dark": {"decode": "dark", "flip_test": False},
           "flip": {"decode": "soft_argmax", "flip_test": True}}
LABELS = {"soft_argmax": "soft-argmax", "dark": "DARK", "flip": "soft-argmax + flip"}


class _SetDecode:
    """An observer of bsp-eval's scoring (evaluate(observers=...)): sets the decoding on
    the trained network before the first batch is scored."""

    def __init__(self, decode: str):
        self.decode = decode

    def start(self, spec, net) -> None:
        for key, value in DECODES[self.decode].items():
            setattr(net, key, value)

    def update(self, spec, net, output, batch) -> None:
        pass


def _own_decode(run: Path) -> str:
    """Which of DECODES the run's own hyper-parameters are (its config.yaml's ``hp``)."""
    import yaml

    cfg = yaml.safe_load((run / "config.yaml").read_text(encoding="utf-8")) or {}
    hp = cfg.get("hp") or {}
    want = {"decode": hp.get("decode", "soft_argmax"), "flip_test": bool(hp.get("flip_test"))}
    return next((d for d, v in DECODES.items() if v == want), "soft_argmax")


def score(run: Path, decode: str) -> dict:
    from bsp_fast.training.evaluate import evaluate

    t = time.process_time()
    res = evaluate(run, "test", observers=[_SetDecode(decode)])
    return {"metrics": res.metrics, "per_recording": res.per_recording,
            "cpu_s": round(time.process_time() - t, 1)}


def summarise(seeds: dict) -> list:
    """Per metric: each decoding's mean over seeds, and each other decoding minus the
    soft-argmax (two-level interval, p)."""
    import numpy as np

    from bsp_fast.metrics import hierarchical as H

    out = []
    for m in METRICS:
        rows = {}
        for decode in DECODES:
            per = [seeds[s].get(decode, {}).get("per_recording") for s in sorted(seeds)]
            if any(p is None or m not in p["metrics"] for p in per):
                continue
            rows[decode] = H.Ratios.from_sections(per, m)
        if "soft_argmax" not in rows or len(rows) < 2:
            continue
        entry = {"metric": m, "seeds": len(seeds)}
        for decode, r in rows.items():
            entry[decode] = float(np.mean(H.row_values(r.num, r.den)))
        for decode in rows:
            if decode == "soft_argmax":
                continue
            t = H.two_level([rows["soft_argmax"], rows[decode]], lambda v: v[1] - v[0],
                            seed_keys=["runs", "runs"])
            entry[f"{decode}_difference"] = {"value": t.value, "interval": [t.low, t.high],
                                             "p": t.p, "recordings": t.n}
        out.append(entry)
    return out


def render(doc: dict) -> str:
    shown = [d for d in DECODES if any(d in r for r in doc["summary"])]
    others = [d for d in shown if d != "soft_argmax"]
    lines = [f"{len(doc['seeds'])} seeds ({', '.join(doc['seeds'])}) of "
             f"`{doc['runs']}`, test split, the same checkpoints decoded "
             f"{len(shown)} ways (PCK in %; each difference against the soft-argmax [95 % "
             "interval over seeds and recordings, t method], two-sided p; the decoding "
             "the runs were trained and tabled with reproduces their metrics.json to "
             f"{doc['reproduced_max_abs']:.1e}).", "",
             "| metric | " + " | ".join(LABELS[d] for d in shown) + " | "
             + " | ".join(f"{LABELS[d]} − soft-argmax | p" for d in others) + " |",
             "|---" * (1 + len(shown) + 2 * len(others)) + "|"]
    for r in doc["summary"]:
        cells = [f"{100 * r[d]:.1f}" if d in r else "–" for d in shown]
        for d in others:
            t = r.get(f"{d}_difference")
            if t is None:
                cells += ["–", "–"]
                continue
            lo, hi = t["interval"]
            cells += [f"{100 * t['value']:+.2f} [{100 * lo:+.2f}, {100 * hi:+.2f}]",
                      f"{t['p']:.3f}"]
        lines.append(f"| {r['metric']} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    from bsp_fast.atomic import write_text
    from bsp_fast.reproduction.readme import portable, portable_command

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("runs", type=Path, help="a pose_estimation table's run folder")
    p.add_argument("--row", default="pose_temporal")
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--resume", action="store_true")
    a = p.parse_args(argv)
    runs = sorted((a.runs / a.row).glob("seed-*"))
    if not runs:
        sys.exit(f"pose_decode: no {a.runs / a.row}/seed-* run folders")
    a.out.mkdir(parents=True, exist_ok=True)
    stem = "pose_decode" if a.row == "pose_temporal" else f"pose_decode-{a.row}"
    path = a.out / f"{stem}.json"
    done = json.loads(path.read_text(encoding="utf-8"))["per_seed"] if (
        a.resume and path.is_file()) else {}
    worst = 0.0
    for run in runs:
        seed = run.name.split("-", 1)[1]
        have = done.setdefault(seed, {})
        for d in DECODES:
            if d not in have:
                have[d] = score(run, d)
        tabled = json.loads((run / "metrics.json").read_text(encoding="utf-8"))["test"]
        own = _own_decode(run)  # the decoding the run was tabled with
        worst = max([worst] + [abs(done[seed][own]["metrics"][m] - tabled[m])
                               for m in METRICS if m in tabled])
        doc = {"runs": f"{portable(a.runs)}/{a.row}", "seeds": sorted(done),
               "per_seed": done, "reproduced_max_abs": worst,
               "summary": summarise(done) if len(done) > 1 else [],
               "command": portable_command("experiments/pose_decode.py",
                                           sys.argv[1:] if argv is None else argv)}
        write_text(path, json.dumps(doc, indent=1))
        write_text(a.out / f"{stem}.md", render(doc))
        print(f"seed {seed}: " + ", ".join(
            f"{LABELS[d]} {done[seed][d]['metrics']['pck_0.05']:.4f}" for d in DECODES),
            flush=True)
    print(render(doc), end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
