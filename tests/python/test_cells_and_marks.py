"""Marks a reviewer accepts (#37, items 1-2; #56): the tables' cells and findings from the
seed, recording and interaction variance components, on synthetic per-seed, per-recording
sums with known answers; the rules (5 seeds, 10 recordings), Holm-Bonferroni over a
table's family, the equivalence margin of an effect's size, the probability of
improvement, per-clip metrics; and an independent recomputation of two cells and two
marks from the raw values (numpy and scipy only) against what the table prints."""
from __future__ import annotations

import json
import re

import numpy as np
import pytest
from scipy import stats

from bsp_fast import reproduction as R
from bsp_fast.metrics import hierarchical as H
from bsp_fast.metrics import uncertainty as U
from bsp_fast.reproduction import evidence as E
from bsp_fast.reporting.reproduced import format_table, status_text

LIFT = ["poseformer", "lstm", "baseline_3d", "lstm_relative_rot"]


def _write(tmp_path, tab, per_row: dict, initial_offset: float = 50.0, clips=None) -> dict:
    """``res`` of :func:`R.run_table` with seeds, made of files: ``per_row[row]`` is a
    (seeds, recordings) array of per-joint values; each (seed, recording) counts 10-59
    joints (drawn once, the same for every row). The trivial baseline is the row plus
    ``initial_offset``. ``clips``: per row, per seed, per recording ``[[score, label]]``."""
    shapes = {np.shape(v) for v in per_row.values()}
    assert len(shapes) == 1
    S, n = shapes.pop()
    den = np.random.default_rng(5).integers(10, 60, (S, n)).astype(float)
    recs = [f"video{i}/0_{i}" for i in range(n)]
    metrics = [m for m in tab["metrics"] if m != "normaliser_fallback"]
    res = {"table": tab["table"], "budget": "quick", "seeds": list(range(S)), "results": {}}
    for row, values in per_row.items():
        seeds = {}
        for s in range(S):
            v = np.asarray(values[s], float)
            sec = {"recordings": recs, "metrics": {m: {"num": (v * den[s]).tolist(),
                                                       "den": den[s].tolist()}
                                                   for m in metrics}}
            off = np.broadcast_to(np.asarray(initial_offset, float), (S, n))[s]
            ini = {"recordings": recs,
                   "metrics": {m: {"num": ((v + off) * den[s]).tolist(),
                                   "den": den[s].tolist()} for m in metrics}}
            if clips is not None:
                sec["clips"] = clips[row][s]
            path = tmp_path / f"{row}-{s}.json"
            path.write_text(json.dumps({"test": sec, "initial": ini, "empty": {}}))
            value = float((v * den[s]).sum() / den[s].sum())
            first = float(((v + off) * den[s]).sum() / den[s].sum())
            seeds[str(s)] = {"metrics": {m: value for m in metrics},
                             "initial": {m: first for m in metrics},
                             "per_recording": str(path), "epochs": 1, "best_epoch": 1}
        res["results"][row] = {"seeds": seeds, "source": "test"}
    return E.summarise(tab, res)


def _compare(a="lstm", b="poseformer", relation=">", text="a worse than b"):
    return {"kind": "compare", "metric": "mpjpe_mm", "a": a, "b": b, "relation": relation,
            "text": text}


def _lifting(findings):
    return dict(R.load_table("lifting"), findings=findings)


def _base(S=5, n=20, seed=0, spread=0.5):
    """(S, n) values: recordings 60-120 mm apart, seeds ``spread`` mm apart."""
    rng = np.random.default_rng(seed)
    return rng.uniform(60, 120, n)[None, :] + rng.normal(0, spread, (S, 1))


def _jit(values, seed=6, sd=0.5):
    """``values`` plus seed x recording noise: rows of one table share their seed numbers
    and are paired on them, so a row that is another plus a constant differs from it by
    exactly that constant, a difference with no variance (inconclusive by rule)."""
    return values + np.random.default_rng(seed).normal(0, sd, np.shape(values))


# ---------------------------------------------------------------------- known answers
def test_two_identical_rows_are_inconclusive(tmp_path):
    base = _base()
    tab = _lifting([_compare()])
    f = E.evaluate_findings(tab, _write(tmp_path, tab, {"lstm": base, "poseformer": base}))[0]
    # no variation of the difference at either level: no p (never p 0 or 1 from an SE of
    # 0), inconclusive by the stated rule
    assert f["difference"] == 0.0 and np.isnan(f["p"][0]) and f["status"] == "inconclusive"
    assert f["rule"] == H.ZERO_SE and f["p_improvement"][0]["value"] == 0.5  # all ties


def test_seeds_that_disagree_wildly_are_inconclusive(tmp_path):
    rng = np.random.default_rng(1)
    rec = 100 + rng.normal(0, 0.2, 20)  # recordings barely differ
    a = rec + np.array([[-20.0], [0.0], [25.0], [-10.0], [10.0]])
    b = rec + 3.0 + np.array([[30.0], [-25.0], [0.0], [20.0], [-15.0]])
    tab = _lifting([_compare("lstm", "poseformer")])
    f = E.evaluate_findings(tab, _write(tmp_path, tab, {"lstm": b, "poseformer": a}))[0]
    assert f["status"] == "inconclusive" and f["rule"] is None
    assert f["interval"][0] < 0 < f["interval"][1] and f["p_holm"][0] > 0.5
    # the seeds held fixed (recordings only, what the tables printed before): decided
    rows = [(x * 30).sum(0) for x in (b, a)]
    old = U.paired_interval([(rows[0], np.full(20, 150.0)), (rows[1], np.full(20, 150.0))],
                            lambda v: v[0] - v[1])
    assert U.mark(old) == "reproduced"


def test_a_large_constant_shift_is_reproduced_and_its_opposite_is_not(tmp_path):
    base = _base()
    tab = _lifting([_compare("lstm", "poseformer", ">", "lstm worse"),
                    _compare("lstm", "poseformer", "<", "lstm better")])
    res = _write(tmp_path, tab, {"lstm": _jit(base + 10.0), "poseformer": base})
    worse, better = E.evaluate_findings(tab, res)
    assert worse["difference"] == pytest.approx(10.0, abs=0.1)
    assert (worse["status"], better["status"]) == ("reproduced", "not reproduced")
    assert (worse["marks"], better["marks"]) == (["reproduced"], ["not reproduced"])
    # every seed of lstm is worse than every seed of poseformer (lower is better)
    assert worse["p_improvement"][0]["value"] == 0.0
    assert status_text(worse).startswith("reproduced (p ")


def test_three_seeds_are_inconclusive_by_rule(tmp_path):
    base = _base(S=3)
    tab = _lifting([_compare()])
    f = E.evaluate_findings(tab, _write(tmp_path, tab, {"lstm": _jit(base + 30),
                                                        "poseformer": base}))[0]
    assert f["p_holm"][0] < 0.05  # decided by the interval, inconclusive by the rule
    assert f["status"] == "inconclusive" and f["marks"] == ["inconclusive"]
    assert f["rule"] == "fewer than 5 seeds (lstm: 3, poseformer: 3)"
    assert "rule: fewer than 5 seeds" in status_text(f)


def test_eight_recordings_are_inconclusive_by_rule(tmp_path):
    base = _base(n=8)
    tab = _lifting([_compare()])
    f = E.evaluate_findings(tab, _write(tmp_path, tab, {"lstm": _jit(base + 30),
                                                        "poseformer": base}))[0]
    assert f["p_holm"][0] < 0.05 and f["recordings"] == 8
    assert (f["status"], f["rule"]) == ("inconclusive", "fewer than 10 test recordings (8)")


def test_a_row_and_its_trivial_baseline_share_their_seeds(tmp_path):
    # seeds 30 mm apart, each seed's trivial baseline 50 mm (± 1 mm) above it: paired by
    # seed (the same runs), the loss is -50 within about a millimetre
    base = _base(spread=30.0)
    tab = _lifting([{"kind": "beats_initial", "metric": "mpjpe_mm", "rows": ["lstm"],
                     "text": "beats its baseline"}])
    jitter = 50.0 + np.random.default_rng(9).normal(0, 1.0, base.shape)
    f = E.evaluate_findings(tab, _write(tmp_path, tab, {"lstm": base}, jitter))[0]
    assert -51.5 < f["interval"][0] < f["difference"] < f["interval"][1] < -48.5
    assert f["p"][0] < 1e-6 and f["status"] == "reproduced"
    assert f["p_improvement"][0]["value"] > 0.5
    # unpaired, as two rows with their own seeds, the seeds' 30 mm would swamp it
    num, den = base * 20.0, np.full(base.shape, 20.0)
    for method in ("t", "vc"):
        apart = H.two_level([(num, den), (num + jitter * den, den)], lambda v: v[0] - v[1],
                            method=method)
        assert apart.high - apart.low > 40, method
    # exactly 50 mm above on every seed and recording: no variance, no p, inconclusive
    f = E.evaluate_findings(tab, _write(tmp_path, tab, {"lstm": base}))[0]
    assert f["interval"] == pytest.approx([-50.0, -50.0]) and np.isnan(f["p"][0])
    assert (f["status"], f["rule"]) == ("inconclusive", H.ZERO_SE)


def test_the_seeds_only_interval_is_the_t_interval_over_seeds():
    # recordings fixed, one row: mean ± t(S - 1) x s / sqrt(S), up to the bootstrap's
    # Monte Carlo error
    v = np.array([[10.0], [12.0], [15.0], [11.0], [17.0]]) + np.zeros((1, 6))
    iv = H.two_level([(v * 3.0, np.full(v.shape, 3.0))], levels="seeds")
    low, high = stats.t.interval(0.95, 4, loc=13.0, scale=np.std(v[:, 0], ddof=1) / np.sqrt(5))
    assert iv.value == pytest.approx(13.0) and iv.df == 4
    half = (high - low) / 2  # 3.62; the bootstrap's standard error within 3 % of s / sqrt(S)
    assert (iv.high - iv.low) / 2 == pytest.approx(half, rel=0.03)
    assert (iv.low + iv.high) / 2 == pytest.approx(13.0)
    with pytest.raises(ValueError, match="levels must be one of"):
        H.two_level([(v, v)], levels="recordings")


def test_holm_by_hand():
    # sorted 0.005, 0.01, 0.03, 0.04 -> x4, x3, x2, x1 = 0.02, 0.03, 0.06, 0.04; running
    # maximum: 0.02, 0.03, 0.06, 0.06
    assert U.holm([0.01, 0.04, 0.03, 0.005]) == pytest.approx([0.03, 0.06, 0.06, 0.02])
    out = U.holm([0.5, float("nan"), 0.4])  # NaN: not tested, not counted (m = 2)
    assert out[0] == pytest.approx(0.8) and np.isnan(out[1]) and out[2] == pytest.approx(0.8)
    assert U.holm([0.6, 0.7]) == [1.0, 1.0]  # capped at 1
    with pytest.raises(ValueError, match=r"p-values must lie in \[0, 1\]"):
        U.holm([1.5])
    assert U.decide(-2.0, 0.01, -1) == "reproduced" and U.decide(-2.0, 0.01, 1) == "not reproduced"
    assert U.decide(-2.0, 0.05, -1) == "inconclusive"  # not below the level


def test_holm_over_the_table_family_turns_marginal_findings_inconclusive(tmp_path):
    # two comparisons with raw p ~ 0.04 and one clear one: each marginal one alone is
    # decided; in the family of three Holm multiplies the smaller marginal p by 2
    base = _base(spread=0.0)
    # rows of one seed numbers are paired on them: the differences vary by seed only
    # (t with 4 df at p 0.035)
    off = np.array([[-3.9], [2.6], [1.3], [-2.08], [2.08]])
    rows = {"poseformer": base, "lstm": base + 4.0 + off, "baseline_3d": base + 4.0 + off,
            "lstm_relative_rot": base + 40 + np.random.default_rng(8).normal(0, 1, base.shape)}
    one = _lifting([_compare("lstm", "poseformer", ">", "m1")])
    alone = E.evaluate_findings(one, _write(tmp_path, one, rows))[0]
    tab = _lifting([_compare("lstm", "poseformer", ">", "m1"),
                    _compare("baseline_3d", "poseformer", ">", "m2"),
                    _compare("lstm_relative_rot", "poseformer", ">", "clear")])
    found = E.evaluate_findings(tab, _write(tmp_path, tab, rows))
    p = [f["p"][0] for f in found]
    assert 0.025 < alone["p"][0] == p[0] == p[1] < 0.05 and p[2] < 0.001
    assert alone["status"] == "reproduced" and alone["p_holm"] == alone["p"]
    # by hand: sorted p2 < p0 = p1: 3 x p2, then 2 x p0, then max(2 x p0, p1)
    assert [f["p_holm"][0] for f in found] == pytest.approx([2 * p[0], 2 * p[0], 3 * p[2]])
    assert [f["status"] for f in found] == ["inconclusive", "inconclusive", "reproduced"]
    text = format_table(tab, _write(tmp_path, tab, rows), found)
    assert "Holm's family: this table file's 3 confirmatory comparisons at budget quick" in text
    # an exploratory finding (added after results were seen) is a family of its own
    # (m2 here: m1 and the clear one are then a family of two, 2 x p2 and max(2 x p2, p0))
    tab["findings"][1] = dict(tab["findings"][1], exploratory=True)
    found = E.evaluate_findings(tab, _write(tmp_path, tab, rows))
    assert [f["p_holm"][0] for f in found] == pytest.approx([p[0], p[0], 2 * p[2]])
    assert [f["status"] for f in found] == ["reproduced", "reproduced", "reproduced"]


def test_equivalence_margin_in_and_out(tmp_path):
    iv = U.Interval(0.1, 0.08, 0.12, 20)
    assert U.equivalence(iv, 0.10, 0.05) == "agrees"
    assert U.equivalence(iv, 0.10, 0.01) == "undetermined"  # overlaps, not inside
    assert U.equivalence(iv, 0.30, 0.05) == "differs"
    with pytest.raises(ValueError, match="margin must be a number >= 0"):
        U.equivalence(iv, 0.1, -1)
    ae = R.load_table("autoencoder")
    clean = np.random.default_rng(3).uniform(0.8, 1.0, 20)[None, :] + np.zeros((5, 1))
    noise = np.random.default_rng(4).normal(0, 0.005, clean.shape)

    def size(loss, **extra):
        tab = dict(ae, findings=[dict(ae["findings"][1], **extra)])
        res = _write(tmp_path, tab, {"clean": clean, "noisy": clean - loss + noise})
        return E.evaluate_findings(tab, res)[0]

    f = size(0.1)  # report: about 10 p.p.; default margin half of it
    assert f["status"] == "reproduced" and f["size"] == {
        "report": 0.10, "equivalence_margin": 0.05, "verdict": "agrees"}
    assert "size agrees with the report's 10.0 p.p. ± 5.0 (interval inside)" in f["ours"]
    assert size(0.3)["size"]["verdict"] == "differs"
    assert size(0.3, equivalence_margin=0.25)["size"]["verdict"] == "agrees"
    with pytest.raises(ValueError, match="'tolerance' is now 'equivalence_margin'"):
        size(0.1, tolerance=0.2)
    with pytest.raises(ValueError, match="autoencoder.yaml: finding 'noise .*"
                                         "equivalence_margin must be a number >= 0"):
        size(0.1, equivalence_margin="wide")


def test_probability_of_improvement_in_a_finding_by_hand(tmp_path):
    # per-seed values (one per seed: every recording the same) a: 1..5 mm, b: 3 mm each;
    # lower is better: a beats b on seeds 1, 2, ties on 3: (2 + 0.5) / 5 per b seed
    a = np.arange(1.0, 6.0)[:, None] + np.zeros((1, 12))
    b = np.full((5, 12), 3.0)
    tab = _lifting([_compare("lstm", "poseformer")])
    f = E.evaluate_findings(tab, _write(tmp_path, tab, {"lstm": a, "poseformer": b}))[0]
    assert f["p_improvement"][0]["value"] == pytest.approx(0.5)
    res = _write(tmp_path, tab, {"lstm": a, "poseformer": b})
    assert "P(a beats b)" in format_table(tab, res, E.evaluate_findings(tab, res))


def test_a_per_clip_metric_is_resampled_from_its_recordings_clips(tmp_path):
    from bsp_fast.metrics.ranking import auroc

    def by_hand(scores, labels):  # the Mann-Whitney U over positives x negatives
        pos, neg = scores[labels == 1], scores[labels == 0]
        return stats.mannwhitneyu(pos, neg).statistic / (len(pos) * len(neg))

    # two recordings: one perfectly ranked, one inverted; clips [score, label, tte] as
    # test_per_recording.json keeps them
    clips = [[[0.9, 1, 40], [0.1, 0, 50]], [[0.2, 1, 30], [0.8, 0, 45]]]
    full = H.Clips([[(np.array([0.9, 0.1]), np.array([1, 0])),
                     (np.array([0.2, 0.8]), np.array([1, 0]))]], auroc)
    # all four clips: positives 0.9, 0.2 against negatives 0.1, 0.8: 3 of 4 pairs ranked
    assert full.values(np.ones((1, 2)))[0, 0] == pytest.approx(0.75) == \
        by_hand(np.array([0.9, 0.1, 0.2, 0.8]), np.array([1, 0, 1, 0]))
    # the first recording drawn twice (its clips twice), then the second three times
    assert full.values(np.array([[2.0, 0.0], [0.0, 3.0]]))[:, 0] == pytest.approx([1.0, 0.0])
    tab = {"table": "t", "task": "classification", "rows": [{"name": "a"}], "findings": [],
           "metrics": {"auroc": {"better": "higher", "format": ".3f"}}}
    res = {"table": "t", "budget": "quick", "seeds": [0, 1], "results": {"a": {
        "source": "test", "seeds": {}}}}
    for s in range(2):
        path = tmp_path / f"clips-{s}.json"
        sec = {"recordings": ["v/0", "v/1"], "metrics": {}, "clips": clips}
        path.write_text(json.dumps({"test": sec, "initial": sec, "empty": {}}))
        res["results"]["a"]["seeds"][str(s)] = {"metrics": {"auroc": 0.75},
                                                "initial": {}, "per_recording": str(path)}
    E.summarise(tab, res)
    # jackknife over two recordings (1 without the second, 0 without the first): a wide
    # interval, inside [0, 1] without cutting (Clopper-Pearson at the effective size)
    low, high = res["results"]["a"]["interval"]["auroc"]
    assert high == 1.0 and 0.0 <= low < 0.5
    bad = dict(sec, clips=[[[0.9]], []])
    (tmp_path / "clips-0.json").write_text(json.dumps({"test": bad, "empty": {}}))
    with pytest.raises(ValueError, match=r"clips-0.json: recording 'v/0': each clip must be "
                                         r"\[score, label, ...\]"):
        E.summarise(tab, res)


# ---------------------------------------------------------------------- recomputation
def _independent(rows, fn, log=False):
    """The variance-components interval and p, written out with loops (numpy and scipy
    only): each seed's ratio linearised on each recording (``v + R (num - v den) / D``),
    the statistic's terms ``W`` the rows' terms times fn's coefficients (fn is linear; the
    rows share their seed numbers, so they are paired on seeds), the two-way ANOVA mean
    squares of ``W`` (seeds x recordings), ``V = (MS_seed + MS_rec - MS_int) / (S R)``
    (the seed part left out when MS_seed < MS_int), Satterthwaite's df (no more than the df
    of a mean square carrying half of the variance or more); ``log``: the t
    interval of the log (a cell in mm)."""
    S, n = rows[0][0].shape
    zero = fn([0.0] * len(rows))
    coef = [fn([1.0 if j == i else 0.0 for j in range(len(rows))]) - zero
            for i in range(len(rows))]
    W = np.zeros((S, n))
    for c, (num, den) in zip(coef, rows):
        for s in range(S):
            D = den[s].sum()
            v = num[s].sum() / D
            for r in range(n):
                W[s, r] += c * (v + n * (num[s, r] - v * den[s, r]) / D)
    value = fn([np.mean(num.sum(1) / den.sum(1)) for num, den in rows])
    grand, rm, cm = W.mean(), W.mean(1), W.mean(0)
    ms_s = n * sum((x - grand) ** 2 for x in rm) / (S - 1)
    ms_r = S * sum((x - grand) ** 2 for x in cm) / (n - 1)
    ms_i = sum((W[s, r] - rm[s] - cm[r] + grand) ** 2 for s in range(S)
               for r in range(n)) / ((S - 1) * (n - 1))
    terms = [(1, ms_r, n - 1)]
    if ms_s > ms_i:
        terms += [(1, ms_s, S - 1), (-1, ms_i, (S - 1) * (n - 1))]
    total = sum(c * m for c, m, _ in terms)
    df = total ** 2 / sum((c * m) ** 2 / d for c, m, d in terms)
    # a mean square carrying at least half of the variance bounds the df by its own
    df = min([df] + [d for c, m, d in terms if c * m >= 0.5 * total])
    se = np.sqrt(total / (S * n))
    q = stats.t.ppf(0.975, df)
    if log:
        f = np.exp(q * se / value)
        return value, value / f, value * f, 2 * stats.t.sf(abs(value) / se, df)
    return value, value - q * se, value + q * se, 2 * stats.t.sf(abs(value) / se, df)


def test_two_cells_and_two_marks_recomputed_independently(tmp_path):
    rng = np.random.default_rng(11)
    rec = rng.uniform(70, 110, 16)
    rows = {"poseformer": rec + rng.normal(0, 2.0, (6, 1)) + rng.normal(0, 1.0, (6, 16)),
            "lstm": rec + 10.0 + rng.normal(0, 2.0, (6, 1)) + rng.normal(0, 1.0, (6, 16)),
            "baseline_3d": rec + 10.5 + rng.normal(0, 2.0, (6, 1))
            + rng.normal(0, 1.0, (6, 16))}
    tab = _lifting([_compare("lstm", "poseformer", ">", "first"),
                    _compare("baseline_3d", "lstm", ">", "second")])
    res = _write(tmp_path, tab, rows)
    text = format_table(tab, res, E.evaluate_findings(tab, res))
    # the raw sums as saved, read back without the code under test
    raw = {}
    for row in rows:
        secs = [json.loads(open(s["per_recording"]).read())["test"]["metrics"]["mpjpe_mm"]
                for s in res["results"][row]["seeds"].values()]
        raw[row] = (np.array([s["num"] for s in secs]), np.array([s["den"] for s in secs]))
    for row in ("poseformer", "lstm"):  # the cells: mean ± std [interval]
        value, low, high, _ = _independent([raw[row]], lambda v: v[0], log=True)
        per_seed = raw[row][0].sum(1) / raw[row][1].sum(1)
        cell = re.search(rf"^\| {row} \| [^|]+ \| ([\d.]+) ± ([\d.]+) \[([\d.]+), ([\d.]+)\]",
                         text, re.M).groups()
        assert float(cell[0]) == pytest.approx(value, abs=0.006)
        assert float(cell[1]) == pytest.approx(np.std(per_seed, ddof=1), abs=0.006)
        assert float(cell[2]) == pytest.approx(low, abs=0.006)  # printed to 2 decimals
        assert float(cell[3]) == pytest.approx(high, abs=0.006)
        assert high - value > value - low  # on the log: longer above than below
    # the two marks: t tests of the two differences, Holm over the family of two by hand
    diff = lambda v: v[0] - v[1]  # noqa: E731
    first = _independent([raw["lstm"], raw["poseformer"]], diff)
    second = _independent([raw["baseline_3d"], raw["lstm"]], diff)
    small, large = sorted([first[3], second[3]])  # Holm, m = 2: 2 x smaller, then larger
    holm = {small: min(1.0, 2 * small), large: min(1.0, max(2 * small, large))}
    marks = []
    for name, (value, low, high, praw) in (("first", first), ("second", second)):
        line = next(ln for ln in text.splitlines() if ln.startswith(f"| {name} |"))
        got = re.search(r"([-+]?[\d.]+) \[([-+]?[\d.]+), ([-+]?[\d.]+)\]", line).groups()
        assert float(got[0]) == pytest.approx(value, abs=0.006)
        assert float(got[1]) == pytest.approx(low, abs=0.006)
        assert float(got[2]) == pytest.approx(high, abs=0.006)
        # lower is better: "a worse than b" is a − b above 0
        want = "inconclusive" if holm[praw] >= 0.05 else (
            "reproduced" if value > 0 else "not reproduced")
        assert line.split("|")[-2].strip().startswith(want + " (p ")
        printed = re.search(r"\(p (< )?([\d.]+)\)", line).groups()
        if printed[0]:  # "< 0.001"
            assert holm[praw] < 0.002
        else:
            assert float(printed[1]) == pytest.approx(holm[praw], abs=0.0006)
        marks.append(want)
    assert marks == ["reproduced", "inconclusive"]  # 10 mm apart is decided, 0.5 mm is not


def test_cell_intervals_respect_what_the_metric_can_take_without_clipping():
    assert E.support("f1") == (0.0, 1.0) and E.support("pck_0.05") == (0.0, 1.0)
    assert E.support("mpjpe_mm") == (0.0, np.inf) == E.support("mpjve_mm")  # mm per frame
    assert E.support("loss") is None  # no stated bound
    # F1 0.95, SE 0.04, 20 df: the symmetric t interval would reach 1.03; Clopper-Pearson
    # at the effective sample size (Korn & Graubard) stays below 1 and is longer below
    low, high = H.bounded_interval(0.95, 0.04, 20, (0.0, 1.0))
    assert 0.75 < low < 0.95 < high < 1.0 and 0.95 - low > high - 0.95
    # a large effective sample: the symmetric t interval
    low, high = H.bounded_interval(0.5, 0.01, 1e6, (0.0, 1.0))
    assert (low, high) == pytest.approx((0.5 - 1.96 * 0.01, 0.5 + 1.96 * 0.01), abs=2e-4)
    # 19 of 19 recordings perfect, no variance: a bound from the counts, 0.025^(1/19)
    assert H.bounded_interval(1.0, 0.0, np.inf, (0.0, 1.0), 19) == (
        pytest.approx(0.025 ** (1 / 19)), 1.0)
    low, high = H.bounded_interval(4.0, 2.0, 10, (0.0, np.inf))  # mm: on the log
    assert 0 < low < 4.0 < high and low * high == pytest.approx(16.0)
    assert H.bounded_interval(4.0, 2.0, 10) == pytest.approx(
        (4 - stats.t.ppf(0.975, 10) * 2, 4 + stats.t.ppf(0.975, 10) * 2))


def test_the_seed_rule_binds_each_comparison_of_an_ordering(tmp_path):
    """An ordering with one row under-seeded (PoseFormer, 3 of 5 seeds): a comparison of
    two rows with all their seeds that goes decisively the wrong way makes the finding not
    reproduced; where every comparison names the under-seeded row, it stays inconclusive
    by rule."""
    base = _base()

    def order(rows):
        tab = _lifting([{"kind": "order", "metric": "mpjpe_mm", "rows": rows, "text": "o"}])
        res = _write(tmp_path, tab, {"poseformer": base - 30, "lstm": _jit(base + 30),
                                     "baseline_3d": base})
        for s in ("3", "4"):
            del res["results"]["poseformer"]["seeds"][s]
        return E.evaluate_findings(tab, E.summarise(tab, res))[0]

    f = order(["poseformer", "lstm", "baseline_3d"])  # lstm < baseline_3d is false
    assert f["status"] == "not reproduced" and f["rule"] is None
    assert "(inconclusive by rule)" in f["ours"] and "(not reproduced)" in f["ours"]
    f = order(["lstm", "poseformer", "baseline_3d"])  # both comparisons name PoseFormer
    assert f["status"] == "inconclusive"
    assert f["rule"] == "fewer than 5 seeds (poseformer: 3)"


def test_a_row_whose_seeds_trained_in_different_precisions_is_named(tmp_path):
    """--precision auto decides per machine: seeds added later elsewhere can differ from a
    row's first ones. The table says which rows and seeds; rows that agree are not named."""
    a = np.arange(1.0, 6.0)[:, None] + np.zeros((1, 12))
    tab = _lifting([_compare("lstm", "poseformer")])
    res = _write(tmp_path, tab, {"lstm": a, "poseformer": a + 1})
    for s, v in res["results"]["lstm"]["seeds"].items():
        v["precision"] = "bf16-mixed" if int(s) < 3 else "32"
    for v in res["results"]["poseformer"]["seeds"].values():
        v["precision"] = "bf16-mixed"
    text = format_table(tab, res, E.evaluate_findings(tab, res))
    line = [ln for ln in text.splitlines() if ln.startswith("Precision:")]
    assert len(line) == 1
    assert line[0].endswith("lstm (32: seeds 3, 4; bf16-mixed: seeds 0, 1, 2).")
    assert "poseformer" not in line[0]
    for v in res["results"]["lstm"]["seeds"].values():
        v["precision"] = "bf16-mixed"
    assert "Precision:" not in format_table(tab, res, E.evaluate_findings(tab, res))


def test_labels_add_up():
    """#56, item 4: 'not recorded' only where a mixed run has no hash; a fails finding
    names the answer it compares with, which is not the table's trivial column."""
    from bsp_fast.reporting.reproduced import protocol_lines, table_header

    prot = {"table_file": "x.yaml", "hash": "a" * 64, "hashed": "h", "utc": "now",
            "code": {"commit": "b" * 40}, "mixed": {"r/seed-1": {"hash": "c" * 64,
                                                                "options": {}}}}
    line = [x for x in protocol_lines({}, {"protocol": prot}) if "Mixed" in x][0]
    assert "cccccccccccc" in line and "not recorded" not in line
    prot["mixed"]["r/seed-2"] = {"hash": None, "options": {}}
    line = [x for x in protocol_lines({}, {"protocol": prot}) if "Mixed" in x][0]
    assert "cccccccccccc, none (" in line and "('none': not recorded)" in line
    tab = R.load_table("classification")
    assert "trivial F1 (majority class)" in table_header(tab, "epochs")[0]
    fails = next(f for f in tab["findings"] if f["kind"] == "fails")
    assert E._pieces(tab, fails)[0][0].endswith("(always-crossing answer +0.05)")
