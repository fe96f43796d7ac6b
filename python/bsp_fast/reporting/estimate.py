"""``bsp-reproduce TABLE --estimate``'s text: the estimate of
:func:`bsp_fast.reproduction.estimate.estimate_table` (each row's CPU minutes per seed
here and on an AVX2-only core, the table's total) as a markdown table and its verdict
against the CPU budget."""
from __future__ import annotations

__all__ = ["format_estimate"]


def _min(s) -> str:
    return "–" if s is None else f"{s / 60:,.1f}"


def format_estimate(est: dict) -> str:
    """The estimate as a markdown table and its verdict against the budget."""
    cpu = est["cpu"]
    kind = ("AVX512" + (" with native bf16 (AVX512-BF16/AMX)" if cpu["bf16"] else
                        ", no native bf16") if cpu["avx512"] else "AVX2-only")
    lines = [f"### Estimate: {est['table']} ({est['budget']} budget, {est['seeds']} seeds a "
             f"row unless capped)", "",
             f"Probe on {cpu['model']} ({kind}); CPU seconds of this process "
             "(time.process_time). AVX2 column: x the measured float32 ratio of an "
             "AVX2-only core (docs/performance.md); bf16 rows are not translated.", "",
             "| row | model | precision | batch | updates (cap) | epochs | CPU s/update | "
             "CPU s/val batch | val / test batches | CPU min/seed here | x AVX2 | "
             "CPU min/seed AVX2 | seeds | CPU min AVX2 |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, r in est["rows"].items():
        if "reads" in r:
            lines.append(f"| {name} | (reads {r['reads']}'s run) | | | | | | | | 0 | | 0 | "
                         f"{r['seeds']} | 0 |")
            continue
        f = "–" if r["avx2_factor"] is None else f"{r['avx2_factor']:.2f}"
        lines.append(
            f"| {name} | {r['model']} | {r['precision']} | {r['batch_size']} | "
            f"{r['updates']:,} | {r['epochs']} | {r['step_s']:.3f} | {r['eval_s']:.3f} | "
            f"{r['val_batches']} / {r['test_batches']} | {_min(r['per_seed_s'])} | {f} | "
            f"{_min(r['per_seed_avx2_s'])} | {r['seeds']} | {_min(r['total_avx2_s'])} |")
    hours = est["budget_s"] / 3600
    for name, r in est["rows"].items():
        if r.get("note"):
            lines.append(f"| {name} | {r['note']} | | | | | | | | | | | | |")
    for name, why in est.get("moved", {}).items():
        lines.append(f"| {name} | moved to the full budget (GPU): {why} | | | | | | | | | | "
                     "| | |")
    lines.append("")
    if est.get("test_scale", 1) != 1:
        lines.append(f"Test passes on the registered test set, {est['test_scale']:g} x the "
                     "data's own test split.")
    lines.append(f"Total here: {est['total_s'] / 3600:.2f} CPU h.")
    if est["total_avx2_s"] is None:
        lines.append(f"Total on an AVX2-only core: not estimated: rows "
                     f"{', '.join(est['bf16_rows'])} train in bf16, which such a core runs "
                     f"5-17x slower than float32 (move them to the full budget or pin "
                     f"precision \"32\"). Budget: {hours:g} CPU h.")
    else:
        verdict = "fits" if est["fits"] else "does NOT fit"
        lines.append(f"Total on an AVX2-only core: {est['total_avx2_s'] / 3600:.2f} CPU h "
                     f"against the budget of {hours:g} CPU h: {verdict}.")
    if est["cheap"]:
        lines.append(f"Under 5 CPU min per seed (AVX2): {', '.join(est['cheap'])} (10 seeds by "
                     "the rule of issue #57).")
    lines.append(f"Upper bounds: the budget's cap of updates; early stopping may end a run "
                 f"sooner. Each run counts {est['startup_s']:g} CPU s of start-up, checkpoints and "
                 "figures.")
    return "\n".join(lines)
