"""Runs read back from a published table (``bsp-reproduce --with-published DIR``).

A table's run folder lives on the machine that trained it; a table whose rows take more
than one machine's session (the ablation's matched-updates rows, the pose table's long
rows) is finished on another machine. There, ``--with-published docs/results`` takes every
run of the wanted rows that has no run folder here from the published table
(``DIR/TABLE-BUDGET.json`` and its per-recording sums, :func:`.readme.load_published`):
its test metrics, seconds, precision, machine (where recorded) and per-recording sums,
exactly as published, and its protocol record (the hash and code it was trained under,
checked like any reused run's). Nothing is trained again for them and no run folder is made; results.json and
the printed table say which runs were read so. Runs trained here always win.

What a read-back run cannot give: its checkpoint (``--breakdown``, the noisy-box scores
of a pose table: published with the run where it had them), its validation curve
(``curves.png`` draws the rows trained here).
"""
from __future__ import annotations

from pathlib import Path

__all__ = ["restorable", "RESTORED_KEY"]

#: a seed's result and a ledger record carry this key: the published file it came from
RESTORED_KEY = "restored_from"


def restorable(tab: dict, budget: str, results_dir, data, split_seeds: bool,
               missing: list) -> dict:
    """``{name: (seed result, ledger record, the row's cost)}`` for the runs ``missing``
    here (names ``ROW/seed-S``) that the published table in ``results_dir`` holds.
    ValueError when the published table was made on other data (another folder name) or
    another split setting, or lacks the protocol record of a run it publishes."""
    from .readme import load_published, published_path

    path = published_path(results_dir, tab["table"], budget)
    if not path.is_file():
        raise ValueError(f"--with-published: {path} does not exist (no published "
                         f"{tab['table']} table at the {budget} budget)")
    doc = load_published(path)
    source = f"{path.name} (protocol {doc['protocol']['hash'][:12]})"
    if Path(str(doc.get("data"))).name != Path(data).name:  # published: a name, or relative
        raise ValueError(f"--with-published: {path} was trained on data {doc.get('data')!r}, "
                         f"this call's is {Path(data).name!r}: the runs would not be comparable")
    if bool(doc.get("split_seeds")) != bool(split_seeds):
        raise ValueError(f"--with-published: {path} was made with split_seeds="
                         f"{bool(doc.get('split_seeds'))}, this call with {bool(split_seeds)}")
    ledger = doc["protocol"].get("runs") or {}
    out = {}
    for name in missing:
        row, _, seed = name.partition("/seed-")
        one = doc["results"].get(row, {}).get("seeds", {}).get(seed)
        if not seed or one is None or doc["results"][row].get("source") == "initial":
            continue
        if not ledger.get(name):
            raise ValueError(f"--with-published: {path} has no protocol record of {name}")
        if one.get("per_recording") is None:
            raise ValueError(f"--with-published: {path}'s per-recording sums lack {name}")
        record = dict(ledger[name])
        record.setdefault(RESTORED_KEY, source)  # the first publication that carried it
        result = dict(one, run=None, **{RESTORED_KEY: record[RESTORED_KEY]})
        out[name] = (result, record, doc["results"][row].get("cost") or {})
    return out
