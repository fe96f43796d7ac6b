#!/usr/bin/env python3
"""The power each confirmatory comparison is registered with (issue #57): the power table's
variance components (experiments/power_analysis.py, from each published table) at the
design a table file registers before its runs (``design:``: its seeds, a row's
``max_seeds`` cap, and its registered test set's size), beside the power at the published
sizes.

For a comparison, S is the fewest seeds among the rows it compares (runs are paired on
shared seed numbers; the finding's rows where the comparison names none) and R the test
recordings: the registered test set's ``recordings`` (its test split counted under the
table's conversion), else the published ones. Power: the normal approximation at Holm's
first level (0.05 / m), as the power table's. ``--write`` registers the result as ``design.power`` in the table file
(inside its protocol hash: written before any run of the design).

    python experiments/design_power.py [--write] [TABLE ...]
"""
from __future__ import annotations

import argparse
import importlib.util
import math
import sys
from pathlib import Path

from scipy import stats

HERE = Path(__file__).resolve().parent


def _power_module():
    spec = importlib.util.spec_from_file_location("power_analysis", HERE / "power_analysis.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def design_power(tab: dict, res: dict) -> dict:
    """``{"level", "comparisons", "findings": [{finding, comparison, effect, seeds,
    recordings, power_now, power}]}`` at the table file's registered design."""
    from bsp_fast.reproduction import evidence as E
    from bsp_fast.reproduction.estimate import moved_rows, registered_seeds, row_seed_counts
    from bsp_fast.reproduction.protocol import confirmatory
    from bsp_fast.reproduction.table_files import rows_of
    from bsp_fast.reproduction.test_sets import registered_test_set

    P = _power_module()
    seeds = registered_seeds(tab, "quick") or 5
    counts = row_seed_counts(tab, "quick", seeds)
    moved = moved_rows(tab, "quick")
    ts = registered_test_set(tab)
    scale = float(ts["scale"]) if ts else 1.0
    sums, have = E._Sums(res), set(res["results"])
    main = set(confirmatory(tab))
    done = {i: E._compute(tab, f, sums, have) for i, f in enumerate(tab["findings"])
            if i in main}
    m = sum(1 for c in done.values() for q in c.get("pieces", [])
            if q["test"].p == q["test"].p)
    level = P.ALPHA / max(m, 1)
    zl = stats.norm.ppf(1 - level / 2)
    out = []
    for i, c in done.items():
        f = tab["findings"][i]
        rows = [r for r in rows_of(f) if r in counts]
        for q in c.get("pieces", []):
            comp = q["test"].components
            if comp is None:
                continue
            # the rows the comparison names (an order's pair, a row against its trivial
            # baseline), else the finding's
            named = [r for r in q["label"].split(" ") if r in counts] or rows
            S = min((counts[r] for r in named), default=seeds)
            gone = sorted({r for r in named + rows_of(f) if r in moved})
            eff, why = P.effect(tab, f, q["label"])
            # the registered test set's recordings (its test split, counted under this
            # table's conversion), else scale x the published ones
            R = int(ts["recordings"]) if ts else comp["recordings"]

            def power(s, r):
                se = math.sqrt(comp["seed"] / s + comp["recording"] / r
                               + comp["interaction"] / (s * r))
                return float(stats.norm.cdf(eff / se - zl)) if se > 0 else 1.0

            out.append({"finding": f["text"], "comparison": q["label"],
                        "effect": round(eff, 4), "effect_from": why,
                        "seeds": S, "recordings": R,
                        "power_now": round(power(comp["seeds"], comp["recordings"]), 3),
                        "power": None if gone else round(power(S, R), 3),
                        **({"moved": gone} if gone else {})})
    return {"level": round(level, 5), "comparisons": m, "seeds": seeds,
            "test_scale": scale, "findings": out}


def markdown(name: str, p: dict) -> str:
    decided = sum(1 for f in p["findings"] if (f["power"] or 0) >= 0.8)
    lines = [f"#### {name}: {p['comparisons']} confirmatory comparisons at Holm level "
             f"{p['level']:g}; design {p['seeds']} seeds, test set x{p['test_scale']:g}: "
             f"{decided} of {len(p['findings'])} at 80 % power", "",
             "| finding | comparison | effect | S × R registered | power published | "
             "power registered |", "|---|---|---|---|---|---|"]
    for f in p["findings"]:
        lines.append(f"| {f['finding']} | {f['comparison']} | {f['effect']:g} | "
                     f"{f['seeds']} × {f['recordings']} | {100 * f['power_now']:.0f} % | "
                     + (f"{100 * f['power']:.0f} % |" if f["power"] is not None else
                        f"moved to full ({', '.join(f['moved'])}) |"))
    return "\n".join(lines)


def register(path: Path, block: dict) -> None:
    """Writes ``power:`` into the file's ``design:`` block (its last key; replaced when
    there), before the power table's block."""
    import yaml

    text = path.read_text(encoding="utf-8")
    begin, end = "  # design power: experiments/design_power.py\n", "  # end design power\n"
    if begin in text:
        text = text[:text.index(begin)] + text[text.index(end) + len(end):]
    anchor = "  # end design\n"
    if anchor not in text:
        raise SystemExit(f"{path}: no '# end design' line closing its design block")
    body = yaml.safe_dump({"power": block}, sort_keys=False, allow_unicode=True, width=4096)
    body = "".join("  " + ln + "\n" for ln in body.splitlines())
    text = text.replace(anchor, begin + body + end + anchor)
    path.write_text(text, encoding="utf-8")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("tables", nargs="*")
    p.add_argument("--results", type=Path, default=Path("docs/results"))
    p.add_argument("--experiments", type=Path, default=Path("experiments"))
    p.add_argument("--write", action="store_true")
    args = p.parse_args(argv)
    from bsp_fast.reproduction import readme as RM
    from bsp_fast.reproduction.table_files import load_table

    names = args.tables or sorted(q.stem for q in args.experiments.glob("*.yaml"))
    for name in names:
        path = args.experiments / f"{name}.yaml"
        tab = load_table(str(path))
        if not tab.get("design"):
            continue
        pub = RM.published_path(args.results, tab["table"], "quick")
        if not pub.is_file():
            print(f"#### {name}: no published table: no components\n")
            continue
        block = design_power(tab, RM.load_published(pub))
        print(markdown(name, block) + "\n")
        if args.write:
            register(path, block)
    return 0


if __name__ == "__main__":
    sys.exit(main())
