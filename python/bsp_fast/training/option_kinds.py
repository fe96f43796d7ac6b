"""The value converters of the command options' kinds (``KINDS``: int, float, str, path,
flag, bool, mjp, hp, devices, mix, files) and :class:`ConfigError`, which every bad value
raises. :mod:`bsp_fast.training.config` declares bsp-train's options (also those of
bsp-eval, bsp-predict and bsp-reproduce) and re-exports these names; they live here to
keep that module within the house's file length."""
from __future__ import annotations

import argparse
import math

from ..data import mix_tables  # mixing tables (no torch)

__all__ = ["ConfigError", "KINDS", "parse_hp"]


class ConfigError(ValueError, argparse.ArgumentTypeError):
    """A bad option value or an unknown option (exit code 2 on the command line). Also an
    ``ArgumentTypeError``: raised by a converter while jsonargparse parses the command
    line, its message is the one the parser reports."""


def _int(value) -> int:
    if isinstance(value, bool) or (isinstance(value, float) and not value.is_integer()):
        raise ValueError
    return int(value)


def _float(value) -> float:
    if isinstance(value, bool) or not math.isfinite(value := float(value)):
        raise ValueError
    return value


def _str(value) -> str:
    if isinstance(value, (dict, list, bool)):
        raise ValueError
    return str(value)


def _bool(value) -> bool:
    if isinstance(value, bool):
        return value
    text = str(value).strip().lower()
    if text in ("1", "true", "yes", "on"):
        return True
    if text in ("0", "false", "no", "off"):
        return False
    raise ConfigError(f"expected a boolean (true/false), got {value!r}")


def _mjp(value):
    if isinstance(value, str):
        parts = [p for p in value.replace(" ", "").split(",") if p]
        try:
            value = [float(p) for p in parts]
        except ValueError:
            raise ConfigError(f"mjp must be a number or 26 comma-separated numbers, "
                              f"got {value!r}") from None
    if isinstance(value, (list, tuple)):
        value = [float(v) for v in value]
        if len(value) == 1:
            value = value[0]
        elif len(value) != 26:
            raise ConfigError(f"mjp takes one value or 26 (one per joint), got {len(value)}")
    if isinstance(value, bool) or not isinstance(value, (int, float, list)):
        raise ConfigError(f"mjp must be a number or a list of 26 numbers, got {value!r}")
    values = value if isinstance(value, list) else [value]
    if any(not (0.0 <= float(v) <= 1.0) or math.isnan(float(v)) for v in values):
        raise ConfigError(f"mjp values must lie in [0, 1], got {value!r}")
    return value if isinstance(value, list) else float(value)


def parse_hp(items) -> dict:
    """``["hidden=32", "layers=1"]`` (or a dict) -> ``{"hidden": 32, "layers": 1}``; values
    in YAML syntax (numbers, true/false, null, strings, [lists])."""
    if items is None:
        return {}
    if isinstance(items, dict):
        return {str(k).replace("-", "_"): v for k, v in items.items()}
    import yaml

    out = {}
    for item in ([items] if isinstance(items, str) else items):
        key, sep, text = str(item).partition("=")
        if not sep or not key.strip():
            raise ConfigError(f"--hp expects KEY=VALUE, got {item!r}")
        try:
            out[key.strip().replace("-", "_")] = yaml.safe_load(text) if text.strip() else ""
        except yaml.YAMLError as exc:
            raise ConfigError(f"--hp {item!r}: value is not valid YAML ({exc})") from None
    return out


def _devices(value):
    if isinstance(value, bool):
        raise ConfigError(f"devices must be 'auto', a count or a list of indices, got {value!r}")
    if isinstance(value, int):
        if value < 1 and value != -1:
            raise ConfigError(f"devices must be >= 1 (or -1 for all), got {value}")
        return value
    if isinstance(value, (list, tuple)):
        return [int(v) for v in value]
    text = str(value).strip()
    if text == "auto":
        return "auto"
    try:
        if "," in text:
            return [int(v) for v in text.split(",") if v]
        return _devices(int(text))
    except ValueError:
        raise ConfigError(f"devices must be 'auto', a count or a comma-separated list of "
                          f"indices, got {value!r}") from None


KINDS = {"int": _int, "float": _float, "str": _str, "path": _str, "flag": _bool,
         "bool": _bool, "mjp": _mjp, "hp": parse_hp, "devices": _devices,
         "mix": lambda v: mix_tables.as_mix(v, error=ConfigError),  # messages name the
         "files": lambda v: mix_tables.parse_files(v, error=ConfigError)}  # source, file
