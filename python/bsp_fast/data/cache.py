"""Where ``BSPDataModule`` keeps converted files, and when one may be reused.

A converted file is reusable only for the same conversion settings (every option that
changes the output, resolved: see ``bsp_fast.conversion.conversion_settings``) and the
same ``data.csv``. The file name carries a hash of the settings; the file itself records
the size and CRC-32 of the data.csv it came from. A reuse check compares the sizes and,
when data.csv was modified after the file was written, the CRC (one read of data.csv), so
touching the CSV without changing it costs one scan and no conversion.

Every new set of options adds a whole file, so the cache can grow to several times the
size of data.csv: :func:`cache_entries` lists it (``bsp-cache ls``), :func:`prune` removes
the least recently used files (``bsp-cache prune``). A file's last use is its access time
(set on every reuse; the modification time stays the conversion's, which the data.csv
check compares with) or its modification time, whichever is later.
"""
from __future__ import annotations

import hashlib
import json
import os
import time
import zlib
from pathlib import Path

__all__ = ["file_crop_box", "default_cache_dir", "cache_name", "stale_reason", "crc32_file", "describe_difference",
           "cache_entries", "cache_usage", "mark_used", "last_used", "prune", "format_bytes", "parse_bytes", "CACHE_GLOB"]

#: The converted files of a cache folder (cache_name's pattern).
CACHE_GLOB = "clips-*.h5"


def default_cache_dir(dataset_dir: Path) -> Path:
    """``<dataset>/bsp_fast-cache`` when the dataset folder is writable, else
    ``$XDG_CACHE_HOME/bsp_fast/<name>-<hash of its path>`` (``~/.cache`` by default)."""
    dataset_dir = Path(dataset_dir).resolve()
    inside = dataset_dir / "bsp_fast-cache"
    if inside.is_dir() and os.access(inside, os.W_OK):
        return inside
    if not inside.exists() and os.access(dataset_dir, os.W_OK):
        return inside
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "bsp_fast"
    tag = hashlib.sha256(str(dataset_dir).encode()).hexdigest()[:10]
    return base / f"{dataset_dir.name}-{tag}"


def cache_name(settings: dict) -> str:
    """``clips-L<L>-o<offset>[-benchmark][-balanced][-media]-<hash>.h5`` for ``settings``."""
    tags = f"L{settings['clip_length']}-o{settings['clip_offset']}"
    tags += "-benchmark" if settings["benchmark"] else ""
    tags += "-balanced" if settings["balance"] else ""
    tags += "-media" if settings["media"] else ""
    key = hashlib.sha256(json.dumps(settings, sort_keys=True).encode()).hexdigest()[:12]
    return f"clips-{tags}-{key}.h5"


def crc32_file(path: Path, chunk: int = 1 << 24) -> int:
    """CRC-32 of a file, as bsp-convert stores it (``source_crc32``)."""
    crc = 0
    with open(path, "rb") as f:
        while True:
            block = f.read(chunk)
            if not block:
                return crc
            crc = zlib.crc32(block, crc)


def stale_reason(h5_path: Path, settings: dict, csv: Path) -> str | None:
    """Why ``h5_path`` is not the conversion of ``csv`` with ``settings`` (None: reusable)."""
    from ..conversion.vds import MissingShardError, open_clip_file

    try:
        with open_clip_file(h5_path) as f:
            stored = json.loads(f.attrs.get("settings_json", "{}"))
            size = int(f.attrs.get("source_bytes", -1))
            crc = int(f.attrs.get("source_crc32", -1))
            no_tte = "test" in f and "meta/tte" not in f["test"]
    except MissingShardError as exc:
        return f"its shard files are missing ({exc})"
    except (OSError, ValueError) as exc:
        return f"unreadable ({exc})"
    if stored != settings:
        return "converted with other options: " + describe_difference(stored, settings)
    if no_tte and settings.get("benchmark"):
        return "written before the time to event (meta/tte) of benchmark windows was stored"
    st = csv.stat()
    if st.st_size != size:
        return f"{csv} changed size ({size} -> {st.st_size} bytes)"
    if st.st_mtime_ns > Path(h5_path).stat().st_mtime_ns and crc32_file(csv) != crc & 0xFFFFFFFF:
        return f"{csv} changed (CRC-32 differs)"
    return None


def file_crop_box(attrs) -> str | None:
    """The crop-box policy of a converted file from its root attributes: ``crop_box``;
    ``mask+joints`` for a file with media written before the attribute existed (the only
    policy then); None without media."""
    if not int(attrs.get("media", 0)):
        return None
    value = attrs.get("crop_box", "mask+joints")
    return value.decode() if isinstance(value, bytes) else str(value)


# ---------------------------------------------------------------------- messages
#: How a user sets each conversion setting (bsp-convert / bsp-train option), when it is
#: not simply ``--`` + the key with dashes.
_OPTIONS = {"media": "media (off: --no-media)", "fov_source": "the FOV's source",
            "benchmark": "--benchmark", "balance": "--balance"}


def _shown(v) -> str:
    if isinstance(v, bool):
        return "on" if v else "off"
    if v is None:
        return "unset"
    if isinstance(v, float):
        return f"{v:g}"
    return str(v)


def describe_difference(stored: dict, wanted: dict) -> str:
    """``--clip-offset 4 vs 30 in the file, --balance on vs off in the file``: every
    setting where ``wanted`` (asked for) differs from ``stored`` (in the file), named by
    its command-line option."""
    keys = sorted(k for k in set(stored) | set(wanted) if stored.get(k) != wanted.get(k))
    return ", ".join(f"{_OPTIONS.get(k, '--' + k.replace('_', '-'))} {_shown(wanted.get(k))} "
                     f"vs {_shown(stored.get(k))} in the file" for k in keys)


# ---------------------------------------------------------------------- size and pruning
def mark_used(path) -> None:
    """Records a reuse of a cached file: its access time becomes now (its modification
    time is left alone)."""
    st = os.stat(path)
    os.utime(path, ns=(time.time_ns(), st.st_mtime_ns))


def last_used(st: os.stat_result) -> float:
    """POSIX seconds of a cached file's last use (conversion or reuse)."""
    return max(st.st_atime, st.st_mtime)


def _bytes(path: Path) -> int:
    if path.is_dir():
        return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())
    return path.stat().st_size


def cache_entries(folder) -> list:
    """The converted files of a cache folder, least recently used first: ``[{"path",
    "bytes" (with a virtual file's ``.shards`` folder), "last_used" (POSIX seconds, see
    :func:`last_used`), "settings" (dict, or None when unreadable)}]``.
    A missing folder holds nothing."""
    import h5py

    folder = Path(folder)
    if not folder.is_dir():
        return []
    out = []
    for path in folder.glob(CACHE_GLOB):
        if not path.is_file():
            continue
        size = _bytes(path)
        shards = path.with_name(path.name + ".shards")
        if shards.is_dir():
            size += _bytes(shards)
        st = path.stat()
        try:
            with h5py.File(path, "r") as f:
                settings = json.loads(f.attrs.get("settings_json", "null"))
        except (OSError, ValueError):
            settings = None
        os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns))  # listing is not a use
        out.append({"path": path, "bytes": size, "last_used": last_used(st),
                    "settings": settings})
    return sorted(out, key=lambda e: (e["last_used"], e["path"].name))


def cache_usage(folder) -> tuple:
    """(number of converted files, their bytes) in a cache folder."""
    entries = cache_entries(folder)
    return len(entries), sum(e["bytes"] for e in entries)


def format_bytes(n: int) -> str:
    """``158 MB`` (decimal units, as ``ls -h --si`` and file managers show them)."""
    for unit, scale in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= scale:
            return f"{n / scale:.{0 if n >= 10 * scale else 1}f} {unit}"
    return f"{n} B"


def parse_bytes(text) -> int:
    """``500M``, ``2G``, ``1.5GB``, ``0`` or a plain number of bytes -> bytes (ValueError
    otherwise; decimal units)."""
    import re

    m = re.fullmatch(r"\s*(\d+(?:\.\d+)?)\s*([kKmMgGtT]?)[bB]?\s*", str(text))
    if not m:
        raise ValueError(f"size must be a number with an optional unit k, M, G or T "
                         f"(e.g. 500M, 2G), got {text!r}")
    return int(float(m.group(1)) * {"": 1, "k": 1e3, "m": 1e6, "g": 1e9,
                                    "t": 1e12}[m.group(2).lower()])


def prune(folder, *, max_bytes: int | None = None, keep: int | None = None,
          dry_run: bool = False) -> list:
    """Removes the least recently used converted files of ``folder`` until at most
    ``max_bytes`` remain and at most ``keep`` files (both optional; neither: remove all).
    Returns the removed entries (of :func:`cache_entries`); ``dry_run`` removes nothing."""
    import shutil

    for name, v in (("max_bytes", max_bytes), ("keep", keep)):
        if v is not None and (isinstance(v, bool) or not isinstance(v, int) or v < 0):
            raise ValueError(f"{name} must be an integer >= 0 or None, got {v!r}")
    entries = cache_entries(folder)
    total = sum(e["bytes"] for e in entries)
    removed = []
    for k, e in enumerate(entries):  # oldest first
        left = len(entries) - k
        over = ((max_bytes is None and keep is None) or (max_bytes is not None and total > max_bytes)
                or (keep is not None and left > keep))
        if not over:
            break
        if not dry_run:
            shards = e["path"].with_name(e["path"].name + ".shards")
            e["path"].unlink(missing_ok=True)
            if shards.is_dir():
                shutil.rmtree(shards)
        total -= e["bytes"]
        removed.append(e)
    return removed
