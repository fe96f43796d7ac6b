"""Outputs that appear complete or not at all: the one temp-then-rename helper of bsp_fast.

Every writer of the package (bsp-convert's HDF5 file and shard folder, bsp-synth's and
bsp-check --fix's dataset folders, run directories, predictions, previews, tables) writes
under :func:`temp_path` beside its target and then calls :func:`publish`:

* no ``force``: the rename refuses to replace anything that appeared meanwhile (another
  run with the same output started at the same time): ``FileExistsError``;
* ``force``: a file is swapped in by one atomic ``rename``; a folder is swapped with the
  old one by one atomic exchange (Linux ``renameat2(RENAME_EXCHANGE)``) and the old one,
  now under the temporary name, is deleted after. A crash at any point leaves the target
  holding either the old or the new output, never neither. Where the exchange is not
  supported (another OS, some network filesystems) the old folder is first moved aside
  to ``.NAME.old-*`` and deleted after the rename.

One output rule for every command (:func:`check_outputs`, before any work): no output is,
holds or would replace one of the command's own inputs, and no two outputs are one file,
with or without ``--force``, through symlinks and hard links too. The refusal is an
:class:`OutputOverlapError`; a command's ``main()`` prints it with :func:`refuse` as one
line ``PROG: error: ...`` on stderr and exits 2.

``BSP_ATOMIC_TEST_KILL=STEP`` (tests only) sends SIGKILL to the process at a step of
:func:`publish` (``before``, ``swapped``), to check the above.
"""
from __future__ import annotations

import contextlib
import ctypes
import errno
import fnmatch
import os
import shutil
import signal
import sys
import uuid
from pathlib import Path

__all__ = ["temp_path", "publish", "remove", "atomic_output", "write_bytes", "write_text",
           "OutputOverlapError", "check_outputs", "refuse", "OVERLAP_EXIT", "DATASET_FILES"]

_AT_FDCWD = -100
_RENAME_NOREPLACE = 1
_RENAME_EXCHANGE = 2


class OutputOverlapError(ValueError):
    """An output that is, holds or would replace one of the command's inputs, or two
    outputs that are one file. Refused with or without ``force``; exit code 2."""


#: the exit code of a refused output (a bad argument)
OVERLAP_EXIT = 2

#: the files a reader of a CARLA-BSP dataset directory reads (data.csv, config.yaml, the
#: media of clips/): an output inside a dataset directory must not match these
DATASET_FILES = ("*.csv", "*.mp4", "*.apng", "*.png", "*.yaml")


def _named(items, default: str) -> list:
    """``[(name, Path)]`` from paths or ``(name, path)`` pairs; None paths left out."""
    out = []
    for item in items or ():
        name, path = item if isinstance(item, tuple) else (default, item)
        if path is not None:
            out.append((name, Path(os.fspath(path))))
    return out


def _real(path: Path) -> Path:
    return Path(os.path.realpath(path))


def _same_file(a: Path, b: Path) -> bool:
    if _real(a) == _real(b):
        return True
    try:
        return os.path.samefile(a, b)  # hard links: the same inode under two names
    except OSError:
        return False


def check_outputs(inputs=(), outputs=(), *, read_dirs=()) -> None:
    """The one output rule of every command, checked before any work.

    ``inputs`` and ``outputs`` are paths or ``(name, path)`` pairs (the name says what the
    path is in messages, e.g. ``("--images", p)``; defaults "the input" and "output");
    None paths are skipped. Raises :class:`OutputOverlapError` (one line naming both
    paths) when

    * an output is an input: the same real path (symlinks resolved, ``..`` too) or the
      same file (a hard link);
    * an output folder holds an input (replacing the folder would delete it);
    * an output lies below one of ``read_dirs``, ``(name, folder, patterns)``: a folder
      the command reads, whose files matching one of the glob ``patterns`` (on the file
      name, case-insensitive, at any depth) are inputs; ``patterns=None``: any path
      inside the folder;
    * two outputs are one file.
    """
    ins, outs = _named(inputs, "the input"), _named(outputs, "output")
    for oname, out in outs:
        real = _real(out)
        for iname, inp in ins:
            if _same_file(out, inp):
                raise OutputOverlapError(f"{oname} {out} is {iname} {inp}; refusing to "
                                         "overwrite it (choose another output path)")
            if real in _real(inp).parents:
                raise OutputOverlapError(f"{oname} {out} holds {iname} {inp}; refusing to "
                                         "replace it (choose another output path)")
        for dname, folder, patterns in read_dirs or ():
            if folder is None:
                continue
            top = _real(Path(os.fspath(folder)))
            if top not in real.parents:
                continue
            if patterns is None:
                raise OutputOverlapError(f"{oname} {out} is inside {dname} {folder}, which "
                                         "this command reads; refusing to write there "
                                         "(choose another output path)")
            name = real.name.lower()
            if any(fnmatch.fnmatchcase(name, p.lower()) for p in patterns):
                kind = f"{real.suffix} " if real.suffix else ""
                raise OutputOverlapError(
                    f"{oname} {out} would replace {dname}'s {kind}file {real}; refusing "
                    "to overwrite an input (choose another output path)")
    for i, (aname, a) in enumerate(outs):
        for bname, b in outs[i + 1:]:
            if _same_file(a, b):
                raise OutputOverlapError(f"{aname} {a} and {bname} {b} are the same file; "
                                         "refusing to write both (choose different output "
                                         "paths)")


def refuse(prog: str, exc: BaseException, file=None) -> int:
    """The command-line side of :func:`check_outputs`: prints ``PROG: error: MESSAGE`` as
    one line on stderr (``file``) and returns :data:`OVERLAP_EXIT` (2) for ``main()``."""
    text = str(exc).replace("\r", " ").replace("\n", " ")
    print(f"{prog}: error: {text}", file=sys.stderr if file is None else file)
    return OVERLAP_EXIT


def temp_path(target, suffix: str = "") -> Path:
    """``.NAME.tmp-PID-RANDOM[suffix]`` beside ``target`` (same filesystem, so the final
    rename is atomic; hidden, so nothing mistakes it for an output)."""
    target = Path(target)
    return target.with_name(f".{target.name}.tmp-{os.getpid()}-{uuid.uuid4().hex[:8]}{suffix}")


def remove(path) -> None:
    """Deletes a file, symlink or folder if it exists."""
    p = Path(path)
    if p.is_dir() and not p.is_symlink():
        shutil.rmtree(p, ignore_errors=True)
    else:
        with contextlib.suppress(FileNotFoundError):
            p.unlink()


@contextlib.contextmanager
def atomic_output(target, *, force: bool = False, folder: bool = False, suffix: str = ""):
    """``with atomic_output(out, force=...) as tmp:`` write ``tmp`` (a path; with ``folder``
    an empty folder made for you); on success it is published as ``out``, on any exception
    (KeyboardInterrupt included) it is removed and ``out`` is untouched."""
    target = Path(target)
    if target.exists() and not force:
        raise FileExistsError(f"{target} exists; pass --force to replace it")
    tmp = temp_path(target, suffix)
    try:
        if folder:
            tmp.mkdir(parents=True)
        yield tmp
        publish(tmp, target, force=force)
    except BaseException:
        remove(tmp)
        raise


def publish(tmp, target, *, force: bool = False) -> None:
    """Moves the finished output ``tmp`` to ``target`` (see the module docstring).
    ``FileExistsError`` when ``target`` exists and ``force`` is off; ``tmp`` is then left
    for the caller to remove."""
    tmp, target = Path(tmp), Path(target)
    _test_kill("before")
    if not (target.exists() or target.is_symlink()):
        try:
            if _rename_noreplace(tmp, target):
                _test_kill("swapped")
                return
            appeared = FileExistsError(f"{target} appeared while this output was written; "
                                       "refusing to replace it (pass --force to replace it)")
        except FileExistsError as exc:
            appeared = exc
        if not force:  # another writer published it since the caller checked
            raise appeared
    elif not force:  # the callers checked before writing: it appeared meanwhile
        raise FileExistsError(f"{target} appeared while this output was written; refusing "
                              "to replace it (pass --force to replace it)")
    if not tmp.is_dir() or not target.is_dir() or target.is_symlink():
        if target.is_dir() and not target.is_symlink():
            raise IsADirectoryError(f"{target} is a folder; refusing to replace it with a file")
        os.replace(tmp, target)  # atomic for files (and a folder over a missing path)
        _test_kill("swapped")
        return
    if _exchange(tmp, target):
        _test_kill("swapped")
        remove(tmp)  # now holds the old output
        return
    old = target.with_name(f".{target.name}.old-{uuid.uuid4().hex[:8]}")
    os.replace(target, old)
    os.replace(tmp, target)
    _test_kill("swapped")
    remove(old)


def _libc():
    try:
        lib = ctypes.CDLL(None, use_errno=True)
        fn = lib.renameat2
    except (OSError, AttributeError):
        return None
    fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    fn.restype = ctypes.c_int
    return fn


_renameat2 = _libc()


def _renameat2_call(src: Path, dst: Path, flags: int):
    """True on success, False where the call or flag is unsupported; raises other errors."""
    if _renameat2 is None:
        return False
    if _renameat2(_AT_FDCWD, os.fsencode(src), _AT_FDCWD, os.fsencode(dst), flags) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.EINVAL, errno.ENOSYS, errno.ENOTSUP, errno.EOPNOTSUPP):
        return False
    if err == errno.EEXIST or err == errno.ENOTEMPTY:
        raise FileExistsError(err, f"{dst} appeared while this output was written; refusing "
                              "to replace it (pass --force to replace it)", str(dst))
    raise OSError(err, os.strerror(err), str(src), None, str(dst))


def _rename_noreplace(tmp: Path, target: Path) -> bool:
    """Renames only if ``target`` still does not exist. False: no such primitive here (the
    caller falls back to a plain rename)."""
    if _renameat2_call(tmp, target, _RENAME_NOREPLACE):
        return True
    if tmp.is_dir():
        # rename(2) onto an existing non-empty folder fails, onto an empty one replaces it
        try:
            target.mkdir()
        except FileExistsError:
            return False
        os.replace(tmp, target)
        return True
    try:
        os.link(tmp, target)  # fails if target exists
    except FileExistsError:
        return False
    except OSError:  # no hard links on this filesystem
        os.replace(tmp, target)
        return True
    os.unlink(tmp)
    return True


def _exchange(tmp: Path, target: Path) -> bool:
    return _renameat2_call(tmp, target, _RENAME_EXCHANGE)


def _test_kill(step: str) -> None:
    if os.environ.get("BSP_ATOMIC_TEST_KILL") == step:
        os.kill(os.getpid(), signal.SIGKILL)


def write_bytes(path, data: bytes, *, force: bool = True, mode: int = 0o644) -> None:
    """Writes a file whole from ``data`` (bytes or any buffer, e.g. a memoryview:
    temporary name, then :func:`publish`)."""
    with atomic_output(path, force=force) as tmp:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, mode)
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())


def write_text(path, text: str, *, force: bool = True) -> None:
    """:func:`write_bytes` of UTF-8 text."""
    write_bytes(path, text.encode("utf-8"), force=force)
