"""What every ``bsp-*`` command shares on its command line: "did you mean" for names
(:func:`did_you_mean`), a help formatter that shows real defaults only
(:class:`HelpFormatter`), one-line argument errors (:class:`ArgumentParser`) and the one
ladder from an exception to a message and an exit code (:func:`run_command`). Torch-free:
``--help`` and argument errors come before PyTorch is imported.

Exit codes, the same for every command (docs/architecture.md, "Exit codes"):

====  ==============================================================================
0     success
1     bad data or input file, a failed run, an I/O error, a missing optional package
2     bad arguments or options (also an output that is one of the inputs)
3     the output exists (``--force`` replaces it)
4     ``bsp-convert --verify``: recordings beyond tolerance
130   interrupted by SIGINT (143: SIGTERM); an interrupted run can be resumed
====  ==============================================================================
"""
from __future__ import annotations

import argparse
import difflib
import re
import sys

__all__ = ["did_you_mean", "unknown", "error_hint", "HelpFormatter", "ArgumentParser",
           "EXIT", "exit_code", "run_command", "BadInput"]

#: the exit codes of every command (module docstring)
EXIT = {"ok": 0, "failure": 1, "usage": 2, "exists": 3, "verify": 4, "interrupted": 130}


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


def exit_code(prog: str, exc: BaseException):
    """Prints ``exc`` as one line ``PROG: message`` and returns its exit code, or None for
    an exception that is no command's error (a bug: the caller re-raises it). An error
    that carries its own ``code`` (a run's, an interruption's, bad data's) keeps it; the C++
    core's errors are named (``VideoDecodeError: ...``); an interruption says what it left
    (``PROG: interrupted; MESSAGE``)."""
    from .atomic import OutputOverlapError, refuse

    if isinstance(exc, OutputOverlapError):
        return refuse(prog, exc)
    code = getattr(exc, "code", None)
    text = str(exc).replace("\n", " ")
    if isinstance(code, int) and not isinstance(exc, SystemExit):
        pass
    elif isinstance(exc, FileExistsError):
        code = EXIT["exists"]
    elif isinstance(exc, (ValueError, argparse.ArgumentTypeError)):
        code = EXIT["usage"]
    elif isinstance(exc, KeyboardInterrupt):
        code, text = EXIT["interrupted"], "interrupted" + (f"; {text}" if text else "")
    elif isinstance(exc, (ImportError, OSError)) or type(exc).__module__.startswith("bsp_fast"):
        code = EXIT["failure"]
    else:
        return None
    if type(exc).__module__ == f"{__package__}._core":
        text = f"{type(exc).__name__}: {text}"
    print(f"{prog}: {text}", file=sys.stderr)
    return code


class BadInput(Exception):
    """An input file holds what the command cannot read (the message names the file and
    what is missing or wrong): bad data, exit code 1."""

    code = EXIT["failure"]


def run_command(prog: str, fn, *args, **kwargs) -> int:
    """``fn(*args, **kwargs)``'s exit code (its return value, 0 for None), or the code of
    the error it raised, printed as one line (:func:`exit_code`)."""
    try:
        result = fn(*args, **kwargs)
    except BaseException as exc:  # KeyboardInterrupt and signals' Interrupted too
        code = exit_code(prog, exc)
        if code is None:
            raise
        return code
    return 0 if result is None else int(result)
