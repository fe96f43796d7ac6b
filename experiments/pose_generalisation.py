#!/usr/bin/env python3
"""Does a pose row fit its training clips better than unseen ones? (#38: is the training set
what keeps pose_temporal below 85 %?)

Each seed's best checkpoint of a pose_estimation table row is scored, with the table's
protocol (mask-box crops, no augmentation, no jitter, every joint), on the clips it was
trained on (the ``train`` split), on the validation clips and on the test clips. The
train and val scores come from files whose ``test`` split links to the run's ``train`` or
``val`` split (HDF5 external links in a temporary folder, nothing copied); the test
scores are the run's own ``test_per_recording.json``. Per metric: each split's mean over seeds, and the gap train -
val with a two-level interval (seeds drawn once for both, as they are the same runs; each
split's recordings drawn on their own, as the splits share none; t method, as the tables).

    python experiments/pose_generalisation.py RUNS/pose_estimation-quick \\
        --rows pose_temporal pose_temporal_w32 --out DIR [--resume]

Writes ``DIR/pose_generalisation.json`` and ``.md`` after every seed (``--resume`` keeps
the seeds scored). The rule the result is read by is stated in docs/findings.md.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

METRICS = ("pck_0.05", "pck_0.05_visible", "pck_0.05_hands", "pck_0.05_feet", "pckhn_0.1")
SPLITS = ("train", "val", "test")


def split_as_test(h5, split: str, path) -> Path:
    """A file whose ``train``/``val`` link to ``h5``'s and whose ``test`` links to its
    ``split``, so that an evaluation of the test split scores ``split``'s clips."""
    import h5py

    from bsp_fast.atomic import publish

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp")
    with h5py.File(h5, "r") as f, h5py.File(tmp, "w") as g:
        for key in f.attrs:
            g.attrs.create(key, f.attrs[key], dtype=f.attrs.get_id(key).dtype)
        for name, target in (("train", "/train"), ("val", "/val"), ("test", f"/{split}")):
            g[name] = h5py.ExternalLink(str(Path(h5).resolve()), target)
    publish(tmp, path, force=True)
    return path


def _run_h5(run: Path) -> Path:
    import yaml

    cfg = yaml.safe_load((run / "config.yaml").read_text(encoding="utf-8")) or {}
    h5 = (cfg.get("resolved") or {}).get("h5") or cfg.get("data")
    if not h5 or Path(h5).suffix not in (".h5", ".hdf5") or not Path(h5).is_file():
        raise SystemExit(f"pose_generalisation: {run}/config.yaml names no converted HDF5 "
                         f"file that exists (got {h5!r})")
    return Path(h5)


def score(run: Path, linked: dict) -> dict:
    """``{split: {"metrics", "per_recording", "cpu_s"}}`` of one run."""
    from bsp_fast.training.evaluate import evaluate

    out = {}
    for split in ("train", "val"):
        t = time.process_time()
        res = evaluate(run, "test", data=linked[split])
        out[split] = {"metrics": res.metrics, "per_recording": res.per_recording,
                      "clips": res.clips, "cpu_s": round(time.process_time() - t, 1)}
    saved = json.loads((run / "test_per_recording.json").read_text(encoding="utf-8"))
    tested = json.loads((run / "metrics.json").read_text(encoding="utf-8"))["test"]
    out["test"] = {"metrics": tested, "per_recording": saved["test"], "clips": None,
                   "cpu_s": 0.0}
    return out


def summarise(seeds: dict) -> list:
    """Per metric and row: each split's mean over seeds, per-seed values, and the gap
    train - val (two-level interval: the same seeds, independent recordings)."""
    import numpy as np

    from bsp_fast.metrics import hierarchical as H

    out = []
    for m in METRICS:
        names = sorted(seeds)
        if not all(m in seeds[s][sp]["per_recording"]["metrics"] for s in names
                   for sp in SPLITS):
            continue
        rows = {sp: H.Ratios.from_sections([seeds[s][sp]["per_recording"] for s in names], m)
                for sp in SPLITS}
        entry = {"metric": m, "seeds": names}
        for sp, r in rows.items():
            values = H.row_values(r.num, r.den)
            entry[sp] = float(np.mean(values))
            entry[f"{sp}_per_seed"] = [float(v) for v in values]
            entry[f"{sp}_recordings"] = int(r.num.shape[1])
        t = H.two_level([rows["train"], rows["val"]], lambda v: v[0] - v[1],
                        groups=["train", "val"], seed_keys=["runs", "runs"])
        entry["gap"] = {"value": t.value, "interval": [t.low, t.high], "p": t.p}
        out.append(entry)
    return out


def render(doc: dict) -> str:
    lines = []
    for row, part in doc["rows"].items():
        lines += [f"**{row}**: {len(part['seeds'])} seeds ({', '.join(part['seeds'])}) of "
                  f"`{doc['runs']}/{row}`, best checkpoints, the table's scoring (PCK in %; "
                  "the gap's 95 % interval over seeds and recordings, t method).", "",
                  "| metric | train | val | test | train − val [95 %] | train − val per seed |",
                  "|---|---|---|---|---|---|"]
        for r in part["summary"]:
            lo, hi = r["gap"]["interval"]
            per = ", ".join(f"{100 * (a - b):+.1f}" for a, b in
                            zip(r["train_per_seed"], r["val_per_seed"]))
            lines.append(f"| {r['metric']} | {100 * r['train']:.1f} | {100 * r['val']:.1f} | "
                         f"{100 * r['test']:.1f} | {100 * r['gap']['value']:+.1f} "
                         f"[{100 * lo:+.1f}, {100 * hi:+.1f}] | {per} |")
        if part["summary"]:
            r = part["summary"][0]
            lines += ["", f"Recordings: train {r['train_recordings']}, val "
                      f"{r['val_recordings']}, test {r['test_recordings']}."]
        lines.append("")
    return "\n".join(lines)


def main(argv=None) -> int:
    from bsp_fast.atomic import write_text
    from bsp_fast.reproduction.readme import portable, portable_command

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("runs", type=Path, help="a pose_estimation table's run folder")
    p.add_argument("--rows", nargs="+", default=["pose_temporal"])
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--resume", action="store_true")
    a = p.parse_args(argv)
    a.out.mkdir(parents=True, exist_ok=True)
    path = a.out / "pose_generalisation.json"
    old = json.loads(path.read_text(encoding="utf-8")) if a.resume and path.is_file() else {}
    done = {row: v["per_seed"] for row, v in old.get("rows", {}).items()}
    doc = {}
    for row in a.rows:
        runs = sorted(r for r in (a.runs / row).glob("seed-*")
                      if (r / "metrics.json").is_file())
        if not runs:
            sys.exit(f"pose_generalisation: no finished {a.runs / row}/seed-* run folders")
        have = done.setdefault(row, {})
        for run in runs:
            seed = run.name.split("-", 1)[1]
            if seed not in have:  # the link files live only while the seed is scored
                h5 = _run_h5(run)
                with tempfile.TemporaryDirectory(prefix="pose_generalisation-") as tmp:
                    linked = {sp: split_as_test(h5, sp, Path(tmp) / f"{sp}-as-test.h5")
                              for sp in ("train", "val")}
                    have[seed] = score(run, linked)
            doc = {"runs": portable(a.runs),
                   "rows": {r: {"seeds": sorted(s), "per_seed": s,
                                "summary": summarise(s) if len(s) > 1 else []}
                            for r, s in done.items()},
                   "command": portable_command("experiments/pose_generalisation.py",
                                               sys.argv[1:] if argv is None else argv)}
            write_text(path, json.dumps(doc, indent=1))
            write_text(a.out / "pose_generalisation.md", render(doc))
            m = {sp: have[seed][sp]["metrics"]["pck_0.05"] for sp in SPLITS}
            print(f"{row} seed {seed}: PCK@0.05 train {m['train']:.4f}, val {m['val']:.4f}, "
                  f"test {m['test']:.4f}", flush=True)
    print(render(doc), end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
