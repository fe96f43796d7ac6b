"""The conversion's own exceptions (no other module of the package needs to import the
converter to catch them)."""
from __future__ import annotations

__all__ = ["BadDataset", "UnusableConversion"]


class BadDataset(ValueError):
    """The dataset cannot be converted as it is (e.g. a malformed config.yaml): bad data,
    not a bad argument: exit code 1 (``command_line.exit_code`` reads ``code``)."""

    code = 1


class UnusableConversion(ValueError):
    """``strict=True`` and the conversion has an empty split or a single-class split: exit
    code 1."""

    code = 1
