"""The words and numbers of a finding as the tables print them: the ``ours`` and
``report`` cells of a one-run table (:mod:`bsp_fast.reproduction.findings` decides the
direction), and of a table with seeds, each comparison's difference with its intervals,
the size against the report's and the baseline a ``fails`` finding compares with
(:mod:`bsp_fast.reproduction.evidence` computes and marks them). The texts are kept in
results.json and the published tables, so they are rendered when the finding is made.
"""
from __future__ import annotations

from ..metrics.uncertainty import AGREES, DIFFERS, UNDETERMINED
from .values import format_value

__all__ = ["point_text", "report_drop_text", "difference_label", "threshold_label",
           "fails_baseline", "fails_label", "seeds_text"]


def _sign(tab, metric) -> int:
    return {"higher": 1, "lower": -1}.get(tab["metrics"][metric].get("better"), 0)


def _pp(tab, metric) -> str:
    """The unit of a difference of fractions shown in %: percentage points."""
    return " p.p." if tab["metrics"][metric].get("format") == "pct" else ""


def point_text(tab: dict, f: dict, v: dict, initial: dict, baseline: str) -> str:
    """One finding's cell on one run per row: ``v[row]`` the metric of each row it names,
    ``initial[row]`` the value it compares with where it needs one, ``baseline`` that
    value's name (a ``fails`` finding)."""
    m, k = f["metric"], f["kind"]
    sign, pp = _sign(tab, m), _pp(tab, m)
    fm = lambda x: format_value(tab, m, x)  # noqa: E731
    if k == "order":
        rs = f["rows"]
        text = rs[0] + " " + fm(v[rs[0]])
        for a, b in zip(rs, rs[1:]):
            op = "<" if v[a] < v[b] else (">" if v[a] > v[b] else "=")
            text += f" {op} {b} {fm(v[b])}"
        return text
    if k == "compare":
        return f"{f['a']} {fm(v[f['a']])} vs {f['b']} {fm(v[f['b']])}"
    if k == "drop":
        drop = sign * (v[f["base"]] - v[f["other"]])
        return f"{fm(v[f['base']])} -> {fm(v[f['other']])} (loss {fm(drop)}{pp})"
    if k == "robuster":
        la = sign * (v[f["a"][0]] - v[f["a"][1]])
        lb = sign * (v[f["b"][0]] - v[f["b"][1]])
        return f"loss {fm(la)}{pp} vs {fm(lb)}{pp}"
    if k == "at_least":
        return f"{f['row']} {fm(v[f['row']])} (threshold {fm(f['value'])})"
    if k == "fails":
        r = f["row"]
        return f"{fm(v[r])} vs {baseline} {fm(initial[r])}"
    return "; ".join(f"{r} {fm(v[r])} vs {fm(initial[r])}" for r in f["rows"])


def report_drop_text(tab: dict, f: dict) -> str:
    """The report column of a ``drop`` finding that states only its size."""
    return f"loss about {format_value(tab, f['metric'], f['report'])}{_pp(tab, f['metric'])}"


# ---------------------------------------------------------------------- with seeds
def difference_label(a: str, b: str, offset: float = 0.0) -> str:
    """A comparison's label: the difference of two rows, with its offset (a margin)."""
    return f"{a} − {b}" + (f" {offset:+g}" if offset else "")


def threshold_label(tab: dict, f: dict) -> str:
    """An ``at_least`` finding's comparison: its row against the threshold."""
    return f"{f['row']} − {format_value(tab, f['metric'], f['value'])}"


def fails_baseline(tab: dict, f: dict) -> str:
    """The name of the answer a ``fails`` finding compares with: the always-crossing
    constant (``baseline: constant``, not the table's trivial column) or the trivial
    baseline the table's column shows."""
    if f.get("baseline") == "constant":
        return "always-crossing answer"
    return f"trivial baseline ({tab['trivial']})"


def fails_label(row: str, baseline: str, margin: float) -> str:
    """A ``fails`` finding's comparison: its row against the answer it must not beat."""
    return f"{row} − ({baseline} {margin:+g})"


def _num(tab, m, v) -> str:
    return format_value(tab, m, v, True)


def _size_text(tab: dict, f: dict, margin: float, verdict) -> str:
    m = f["metric"]
    size = f"{format_value(tab, m, f['report'])}{_pp(tab, m)} ± {format_value(tab, m, margin)}"
    return {AGREES: f"size agrees with the report's {size} (interval inside)",
            DIFFERS: f"size differs from the report's {size} (interval outside)",
            UNDETERMINED: f"size undetermined against the report's {size} "
                          "(interval not inside)",
            None: f"size not judged against the report's {size} (by rule)"}[verdict]


def seeds_text(tab: dict, f: dict, pieces: list, marks: list, *, size=None,
               baseline=None) -> str:
    """One finding's ``ours`` cell with seeds: each comparison (``pieces``: ``label``,
    ``test`` and ``seeds_only`` intervals, ``rule``) as its difference [interval] (seeds
    only [interval]), with its mark (``marks``) where there are several; ``size``:
    ``(margin, verdict)`` of a ``drop`` finding against the report's size; ``baseline``:
    ``(name, value)`` a ``fails`` finding compares with."""
    m = f["metric"]
    pp = _pp(tab, m)
    texts = []
    for q, mark in zip(pieces, marks):
        t, s = q["test"], q["seeds_only"]
        text = (f"{q['label']} {_num(tab, m, t.value)}{pp} [{_num(tab, m, t.low)}, "
                f"{_num(tab, m, t.high)}] (seeds only [{_num(tab, m, s.low)}, "
                f"{_num(tab, m, s.high)}])")
        texts.append(text + (f" ({mark}{' by rule' if q['rule'] else ''})"
                             if len(pieces) > 1 else ""))
    if size is not None:
        texts.append(_size_text(tab, f, *size))
    if baseline is not None:
        texts.append(f"{baseline[0]}: {_num(tab, m, baseline[1])}")
    return "; ".join(texts)
