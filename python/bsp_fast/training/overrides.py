"""bsp-train's options (:data:`.config.OPTIONS`, one declaration) as the overrides of the
commands that read runs or tables: ``bsp-eval`` and ``bsp-predict`` take every option
declared ``scoring=True`` (how a saved run is scored: its input corruption, batches,
hardware), ``bsp-reproduce`` every option but the run's identity (for every row, like
``--set KEY=VALUE``). Help texts, types and messages are the options' own, so a new
bsp-train option reaches them with no other edit."""
from __future__ import annotations

import argparse

from . import config as C

__all__ = ["NOT_OVERRIDES", "add_overrides", "given_overrides"]


#: bsp-train options that name a run rather than change one: never overrides of the
#: commands that read runs or tables (they have their own --data, --out, --force, --seeds)
NOT_OVERRIDES = ("task", "model", "data", "out", "force", "resume", "quiet", "seed", "hp")


def _override_kwargs(o: C.Option) -> dict:
    kw = dict(default=argparse.SUPPRESS, dest=o.name)  # absent: the run's (no "default:")
    if o.kind == "flag":
        return dict(kw, action="store_const", const=True)
    if o.kind == "bool":
        return dict(kw, action=argparse.BooleanOptionalAction)
    if o.kind == "files":  # --mix-data a=X --mix-data b=Y: both, as bsp-train merges them
        kw["action"] = C.MergeItems
    return dict(kw, type=_argparse_type(o), metavar=o.metavar or
                ("|".join(o.choices) if o.choices else o.name.upper()))


def _argparse_type(o: C.Option):
    def convert(value):
        try:
            return o.convert(value)
        except C.ConfigError as exc:  # argparse prints its message: "argument --x: ..."
            raise argparse.ArgumentTypeError(str(exc)) from None
    convert.__name__ = o.name
    return convert


def add_overrides(p, scope: str, title: str | None = None) -> list:
    """Adds bsp-train's own options to argparse parser ``p`` as overrides (absent from the
    namespace unless given: the run's or the table's value): ``scope="scoring"`` every option declared with
    ``scoring=True`` (bsp-eval, bsp-predict), ``scope="table"`` every option but
    :data:`NOT_OVERRIDES` (bsp-reproduce: for every row). Help texts, types and messages
    are the options' own. Returns the option names added."""
    if scope not in ("scoring", "table"):
        raise ValueError(f"scope must be one of ['scoring', 'table'], got {scope!r}")
    group = p.add_argument_group(title or "bsp-train options (default: the run's)")
    names = []
    for o in C.OPTIONS:
        if o.name in NOT_OVERRIDES or (scope == "scoring" and not o.scoring):
            continue
        group.add_argument("--" + o.name.replace("_", "-"), help=o.help,
                           **_override_kwargs(o))
        names.append(o.name)
    return names


def given_overrides(ns, names) -> dict:
    """``{name: value}`` of the overrides of :func:`add_overrides` given on the line."""
    return {n: getattr(ns, n) for n in names if getattr(ns, n, None) is not None}
