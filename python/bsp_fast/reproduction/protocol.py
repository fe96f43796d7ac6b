"""The registered protocol of a table (issue #37): what a table's results were made under,
and the record of every change made to a table after its results existed.

* **The protocol hash.** A table file's content hash is the SHA-256 of its parsed YAML
  *without* its ``deviations:`` list, written as canonical JSON (sorted keys, no spaces):
  comments, layout and deviations appended later leave it unchanged, so the runs made
  before a deviation was written down keep their hash; any change to budgets, rows,
  metrics or findings changes it. (The bytes of the file would change with every comment
  and every deviation.)
* **The ledger.** ``OUT/TABLE-BUDGET/protocol.json`` records, for every run of the folder,
  the hash, the options given over the table file's (``--set`` and option flags; the
  loader's ``workers`` and ``threads`` left out: they change no result), the code (git
  commit, or the package version outside a checkout) and the UTC time it was started
  under. :func:`guard` refuses to reuse or continue a run recorded under another hash or
  other options (or under none: made before the ledger existed) unless told
  (``--allow-changed``); an allowed mix is recorded in the ledger and in results.json and
  printed under the table.
* **Deviations.** ``deviations:`` in a table file lists each change made after test
  numbers existed: ``what``, ``when`` (a date), ``commit``, ``why`` and ``seen_test_numbers``
  (yes/no), optionally ``seen_in`` (the commit that held the numbers seen). Checked on
  load (:func:`check_deviations`) and printed under the table.
* **Exploratory findings.** A finding added after results were seen carries
  ``exploratory: true``: it is printed with that label, never in bold, and is not in the
  table's confirmatory family (:func:`confirmatory`), the family a multiplicity
  correction runs over.
"""
from __future__ import annotations

import datetime as dt
import hashlib
import json
import re
import subprocess
from pathlib import Path

from ..atomic import write_text
from ..reporting.reproduced import protocols_text

__all__ = ["HASHED", "LEDGER", "DEVIATION_KEYS", "ProtocolChanged", "table_hash",
           "code_version", "utc_now", "check_deviations", "check_exploratory",
           "confirmatory", "mark_exploratory", "guard", "record_runs"]

#: what :func:`table_hash` hashes, in words (recorded beside the hash)
HASHED = ("sha256 of the table file's parsed YAML without its deviations list (and power "
          "block), as canonical JSON (sorted keys)")
#: top-level keys of a table file outside its hash: records about the protocol (its
#: deviations; ``power``, the sizes a finding needs, experiments/power_analysis.py), which
#: change no run
UNHASHED = ("deviations", "power")
LEDGER = "protocol.json"
#: command-line options that change how a run executes, not what it computes
EXECUTION_KEYS = ("workers", "threads")
#: options naming a dataset by its path: recorded by its folder's name, as ``--data`` is
#: published (a machine's path is no part of a protocol; a registered test set is what it
#: is by test_sets' check, whichever disk holds it)
PATH_KEYS = ("test_data",)
#: ``{key: required}`` of a deviation entry
DEVIATION_KEYS = {"what": True, "when": True, "commit": True, "why": True,
                  "seen_test_numbers": True, "seen_in": False}
_COMMIT = re.compile(r"[0-9a-f]{7,40}")


class ProtocolChanged(ValueError):
    """Runs of an output folder were made under another version of the table file
    (bsp-reproduce exits 2)."""


# ---------------------------------------------------------------------- hash and code
def canonical(doc: dict) -> str:
    """The canonical JSON of a parsed table file, without :data:`UNHASHED` (dates, which
    YAML parses, as ISO strings)."""
    body = {k: v for k, v in doc.items() if k not in UNHASHED}
    return json.dumps(body, sort_keys=True, ensure_ascii=False, separators=(",", ":"),
                      default=str)


def table_hash(path) -> str:
    """The protocol hash of a table file (:data:`HASHED`), hex."""
    import yaml

    doc = yaml.safe_load(Path(path).read_text(encoding="utf-8"))
    return hashlib.sha256(canonical(doc).encode("utf-8")).hexdigest()


def _git(pkg: Path, *args) -> str | None:
    try:
        p = subprocess.run(["git", "-C", str(pkg), *args], capture_output=True, text=True,
                           timeout=30)
    except (OSError, subprocess.SubprocessError):  # no git, or it hung
        return None
    return p.stdout if p.returncode == 0 else None


def code_version() -> dict:
    """``{"commit", "dirty"}`` when the running package is a file of a git checkout
    (``dirty``: tracked files differ from the commit), else ``{"version"}``."""
    import bsp_fast

    pkg = Path(bsp_fast.__file__).resolve().parent
    # the package itself must be tracked: a site-packages inside some other checkout is not
    if _git(pkg, "ls-files", "--error-unmatch", "__init__.py") is not None:
        head = (_git(pkg, "rev-parse", "HEAD") or "").strip()
        if _COMMIT.fullmatch(head):
            status = _git(pkg, "status", "--porcelain", "--untracked-files=no") or ""
            return {"commit": head, "dirty": bool(status.strip())}
    return {"version": bsp_fast.__version__}


def utc_now() -> str:
    return dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")


# ---------------------------------------------------------------------- table file fields
def check_deviations(doc: dict, path) -> list:
    """The table's ``deviations`` (default none), checked, ``when`` as ``YYYY-MM-DD``;
    ValueError naming the file, the entry and what is wrong."""
    devs = doc.get("deviations") or []
    if not isinstance(devs, list):
        raise ValueError(f"{path}: deviations must be a list of entries with keys "
                         f"{list(DEVIATION_KEYS)}, got {type(devs).__name__}")
    out = []
    for i, d in enumerate(devs, 1):
        where = f"{path}: deviation {i}"
        if not isinstance(d, dict):
            raise ValueError(f"{where}: an entry is a mapping with keys {list(DEVIATION_KEYS)}")
        missing = [k for k, need in DEVIATION_KEYS.items() if need and k not in d]
        extra = sorted(set(d) - set(DEVIATION_KEYS))
        if missing or extra:
            raise ValueError(f"{where}: " + "; ".join(
                ([f"missing {missing}"] if missing else [])
                + ([f"unknown {extra}"] if extra else []))
                + f" (allowed: {list(DEVIATION_KEYS)})")
        for key in ("what", "why"):
            if not isinstance(d[key], str) or not d[key].strip():
                raise ValueError(f"{where}: {key} must be a non-empty text")
        when = d["when"]
        if isinstance(when, dt.datetime) or not isinstance(when, (dt.date, str)):
            raise ValueError(f"{where}: when must be a date (YYYY-MM-DD), got {when!r}")
        try:
            when = dt.date.fromisoformat(str(when))
        except ValueError:
            raise ValueError(f"{where}: when must be a date (YYYY-MM-DD), got {when!r}") from None
        for key in ("commit", "seen_in"):
            if key in d and not (isinstance(d[key], str) and _COMMIT.fullmatch(d[key])):
                raise ValueError(f"{where}: {key} must be a commit id of 7-40 hex digits, "
                                 f"quoted (YAML reads 1234567 as a number), got {d[key]!r}")
        if not isinstance(d["seen_test_numbers"], bool):
            raise ValueError(f"{where}: seen_test_numbers must be yes or no, got "
                             f"{d['seen_test_numbers']!r}")
        out.append(dict(d, when=when.isoformat()))
    return out


def check_exploratory(doc: dict, path) -> None:
    """A finding's ``exploratory`` must be a YAML boolean (ValueError naming it)."""
    for f in doc.get("findings") or []:
        if "exploratory" in f and not isinstance(f["exploratory"], bool):
            raise ValueError(f"{path}: finding {f.get('text')!r}: exploratory must be true "
                             f"or false, got {f['exploratory']!r}")


def confirmatory(tab: dict) -> list:
    """Indices into ``tab["findings"]`` of the confirmatory family: every finding registered
    before results were seen, i.e. without ``exploratory: true``. Holm's correction
    (:mod:`.evidence`) runs over these; the exploratory ones are a family of their own."""
    return [i for i, f in enumerate(tab["findings"]) if not f.get("exploratory")]


def mark_exploratory(tab: dict, found: list) -> list:
    """Sets ``exploratory`` (bool) on each marked finding of ``found`` (in the order of
    ``tab["findings"]``); returns ``found``."""
    for spec, f in zip(tab["findings"], found):
        f["exploratory"] = bool(spec.get("exploratory"))
    return found


# ---------------------------------------------------------------------- the ledger
def _read_ledger(base: Path, tab: dict, budget: str) -> dict:
    p = base / LEDGER
    if not p.is_file():
        return {"table": tab["table"], "budget": budget, "runs": {}, "allowed_changes": []}
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise ValueError(f"{p}: not JSON ({exc}); it records which protocol each run of "
                         f"{base} was made under") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("runs"), dict):
        raise ValueError(f"{p}: no 'runs' mapping; it records which protocol each run of "
                         f"{base} was made under")
    doc.setdefault("allowed_changes", [])
    return doc


def _options(overrides) -> dict:
    """The given options that change what a run computes, as JSON values."""
    given = {k: v for k, v in (overrides or {}).items() if k not in EXECUTION_KEYS}
    return portable_options(json.loads(json.dumps(given, sort_keys=True, default=str)))


def portable_options(options: dict) -> dict:
    """``options`` with each :data:`PATH_KEYS` value a folder's name (also applied to
    what a ledger recorded before, so runs recorded with a path compare equal)."""
    return {k: Path(v).name if k in PATH_KEYS and isinstance(v, str) else v
            for k, v in options.items()}


def guard(base, tab: dict, budget: str, runs, overrides=None, *,
          allow_changed: bool = False, known=None) -> tuple:
    """Checks the runs this call would reuse or continue (``runs``: names ``ROW`` or
    ``ROW/seed-S``) against the ledger of ``base``; returns ``(protocol, ledger)``: the
    protocol of this call (``table_file``, ``hash``, ``hashed``, ``options`` (the given
    ``overrides`` that change results), ``code``, ``utc``, ``allow_changed`` and
    ``mixed``: ``{name: {"hash", "options"}}`` of the runs let in under another protocol)
    and the ledger for :func:`record_runs`. Raises :class:`ProtocolChanged` (nothing
    written) when one was made under another hash or other options (or none) unless
    ``allow_changed``. ``known``: ``{name: record}`` of runs recorded elsewhere (read from a
    published table, :mod:`.restore`), entered in the ledger before the check."""
    base = Path(base)
    ledger = _read_ledger(base, tab, budget)
    ledger["runs"].update(known or {})
    now = {"table_file": tab["path"], "hash": table_hash(tab["path"]), "hashed": HASHED,
           "options": _options(overrides), "code": code_version(), "utc": utc_now()}
    mixed = {}
    for name in runs:
        old = ledger["runs"].get(name) or {}
        recorded = portable_options(old.get("options", {}))
        if (old.get("hash"), recorded) != (now["hash"], now["options"]):
            mixed[name] = {"hash": old.get("hash"), "options": old.get("options", {})}
    if mixed and not allow_changed:
        shown = ", ".join(list(mixed)[:6]) + (", ..." if len(mixed) > 6 else "")
        raise ProtocolChanged(
            f"{base}: {len(mixed)} finished or interrupted run(s) were made under another "
            f"version of the table file {tab['path']} or other options ({protocols_text(mixed)}; "
            f"now {now['hash'][:12]}"
            + (f", options {json.dumps(now['options'], sort_keys=True)}" if now["options"]
               else "") + "; 'none': made before runs were recorded): "
            f"{shown}. bsp-reproduce does not mix runs of different protocols; use a new --out, "
            "retrain those rows with --force, or mix them with --allow-changed (recorded in "
            "results.json and printed under the table). A change made after results "
            "existed belongs in the table file's deviations: list (docs/reproduce.md, "
            "'Registered protocol').")
    if mixed:
        ledger["allowed_changes"].append({"utc": now["utc"], "code": now["code"],
                                          "hash": now["hash"], "runs": mixed})
    return dict(now, allow_changed=bool(allow_changed), mixed=mixed), ledger


def record_runs(base, protocol: dict, ledger: dict, names) -> None:
    """Records ``names`` (runs about to be trained from scratch) under this call's hash,
    and writes the ledger (before training: an interrupted run is on record)."""
    for name in names:
        ledger["runs"][name] = {k: protocol[k] for k in ("hash", "options", "code", "utc")}
    Path(base).mkdir(parents=True, exist_ok=True)
    write_text(Path(base) / LEDGER, json.dumps(ledger, indent=1))
