"""Where ``BSPDataModule`` keeps converted files, and when one may be reused.

A converted file is reusable only for the same conversion settings (every option that
changes the output, resolved: see ``bsp_fast.conversion.conversion_settings``) and the
same ``data.csv``. The file name carries a hash of the settings; the file itself records
the size and CRC-32 of the data.csv it came from. A reuse check compares the sizes and,
when data.csv was modified after the file was written, the CRC (one read of data.csv), so
touching the CSV without changing it costs one scan and no conversion.
"""
from __future__ import annotations

import hashlib
import json
import os
import zlib
from pathlib import Path

__all__ = ["default_cache_dir", "cache_name", "stale_reason", "crc32_file"]


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
    except MissingShardError as exc:
        return f"its shard files are missing ({exc})"
    except (OSError, ValueError) as exc:
        return f"unreadable ({exc})"
    if stored != settings:
        diff = sorted(k for k in set(stored) | set(settings) if stored.get(k) != settings.get(k))
        return "converted with other options: " + ", ".join(
            f"{k}={stored.get(k)!r} (now {settings.get(k)!r})" for k in diff)
    st = csv.stat()
    if st.st_size != size:
        return f"{csv} changed size ({size} -> {st.st_size} bytes)"
    if st.st_mtime_ns > Path(h5_path).stat().st_mtime_ns and crc32_file(csv) != crc & 0xFFFFFFFF:
        return f"{csv} changed (CRC-32 differs)"
    return None
