"""What every ``bsp-*`` command shares on its command line: "did you mean" for names
(:func:`did_you_mean`) and a help formatter that shows real defaults only
(:class:`HelpFormatter`). Torch-free: ``--help`` and argument errors come before PyTorch is
imported (docs/design.md, "Commands answer at once")."""
from __future__ import annotations

import argparse
import difflib
import re

__all__ = ["did_you_mean", "unknown", "error_hint", "HelpFormatter", "ArgumentParser"]


def did_you_mean(word, choices) -> str:
    """``" (did you mean 'lifting'?)"`` for the closest of ``choices``, or ``""``."""
    close = difflib.get_close_matches(str(word), [str(c) for c in choices], n=1, cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""


def unknown(what: str, word, choices) -> str:
    """``"unknown task 'lifitng' (did you mean 'lifting'?); allowed: ..."``."""
    return (f"unknown {what} {word!r}{did_you_mean(word, choices)}; allowed: "
            + ", ".join(str(c) for c in choices))


class HelpFormatter(argparse.HelpFormatter):
    """An option's default appended to its help when it has one worth saying (not None,
    False, an empty list or suppressed) and the help does not already say it."""

    def _get_help_string(self, action):
        text = action.help or ""
        default = action.default
        if "default" in text or action.option_strings == [] or default in (
                None, False, [], argparse.SUPPRESS) or isinstance(default, (dict, tuple)):
            return text
        return f"{text} (default: {default})"


def error_hint(message: str, parser) -> str:
    """A "did you mean" for argparse's message about a mistyped option or choice."""
    m = re.search(r"unrecognized arguments: (\S+)", message)
    if m and m.group(1).startswith("-"):
        return did_you_mean(m.group(1).split("=")[0], parser._option_string_actions)
    m = re.search(r"invalid choice: '([^']*)' \(choose from (.*)\)", message)
    if m:
        return did_you_mean(m.group(1), [c.strip(" '") for c in m.group(2).split(",")])
    return ""


class ArgumentParser(argparse.ArgumentParser):
    """argparse's parser whose errors are one line: the message, a "did you mean" for a
    mistyped option or choice, and where the help is (not the whole usage)."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message}{error_hint(message, self)} "
                     f"(see {self.prog} --help)\n")
