"""Virtual datasets of a sharded conversion, written and checked in one module.

:func:`write_virtual` makes ``OUT.h5`` of a ``--scheduler dask`` conversion: for every
dataset of the shards, one virtual dataset over their pieces in order.

``bsp-convert --scheduler dask`` writes ``OUT.h5`` as HDF5 virtual datasets over the shard
files in ``OUT.h5.shards/`` (named relative to ``OUT.h5``'s folder). HDF5 reads a virtual
dataset whose source file is missing as its fill value (zeros) without any error, so every
reader of converted files opens them through :func:`open_clip_file`, which raises
:class:`MissingShardError` instead. The check opens each source file once; its result is
kept per process for the file (path, size, modification time) and re-validated with one
``stat`` per source, so reopening in DataLoader workers or every epoch costs microseconds.
"""
from __future__ import annotations

import os
from pathlib import Path

__all__ = ["MissingShardError", "open_clip_file", "check_virtual_sources", "write_virtual",
           "part_name"]


class MissingShardError(FileNotFoundError, ValueError):
    """A virtual dataset of a converted file names a source file (a shard of
    ``bsp-convert --scheduler dask``) that is missing or cannot be read. Both a
    ``FileNotFoundError`` and a ``ValueError`` (a bad converted file)."""


# (absolute path, cwd, HDF5_VDS_PREFIX) -> (stat signature of the file, ((source, sig), ...))
_checked: dict = {}


def _sig(path: str):
    st = os.stat(path)
    return st.st_mtime_ns, st.st_size, st.st_ino


def _candidates(name: str, vds_dir: str) -> list:
    """Where HDF5 looks for a virtual dataset's source file ``name``, in its order: the
    name itself when absolute, each ``HDF5_VDS_PREFIX`` folder, the folder of the virtual
    file (the default), then the name relative to the working directory."""
    out = []
    if os.path.isabs(name):
        out.append(name)
        name = os.path.basename(name)
    for prefix in filter(None, os.environ.get("HDF5_VDS_PREFIX", "").split(os.pathsep)):
        out.append(os.path.join(prefix.replace("${ORIGIN}", vds_dir), name))
    out.append(os.path.join(vds_dir, name))
    out.append(name)
    return out


def _sources(f) -> dict:
    """{source file name as stored: [(virtual dataset, source dataset), ...]} of ``f``."""
    import h5py

    found: dict = {}

    def visit(name, obj):
        if isinstance(obj, h5py.Dataset) and obj.is_virtual:
            for m in obj.virtual_sources():
                found.setdefault(m.file_name, []).append(("/" + name, m.dset_name))

    f.visititems(visit)
    return found


def _problem(vds: str, dataset: str, shard: str, what: str) -> MissingShardError:
    folder = os.path.dirname(shard) or "."
    return MissingShardError(
        f"{vds}: virtual dataset {dataset} reads {shard}, which {what}; HDF5 would read "
        f"zeros in its place. The shard folder {folder}{os.sep} written by bsp-convert "
        f"--scheduler dask must travel with {os.path.basename(vds)} (copy both: cp -r "
        f"{os.path.basename(vds)} {os.path.basename(vds)}.shards DEST/), or convert "
        "without --scheduler dask for one self-contained file")


def check_virtual_sources(f, path=None) -> None:
    """Raises :class:`MissingShardError` (naming the file, the dataset and the missing
    shard) unless every source of every virtual dataset of the open h5py file ``f`` exists
    and holds its dataset. Relative source names resolve against the folder of the file,
    as HDF5 does; ``.`` is the file itself. ``path``: the file's name for messages and the
    cache (default ``f.filename``)."""
    import h5py

    path = os.path.abspath(str(path if path is not None else f.filename))
    key = (path, os.getcwd(), os.environ.get("HDF5_VDS_PREFIX"))
    try:
        own = _sig(path)
    except OSError:
        own = None
    hit = _checked.get(key)
    if hit is not None and own is not None and hit[0] == own:
        try:
            if all(_sig(src) == sig for src, sig in hit[1]):
                return
        except OSError:
            pass
    vds_dir = os.path.dirname(path)
    seen = []
    for name, uses in sorted(_sources(f).items()):
        if name == "." or "%" in name:  # the file itself; printf-style patterns: not checked
            continue
        dataset, _ = uses[0]
        expected = os.path.normpath(os.path.join(vds_dir, name))
        src = next((c for c in _candidates(name, vds_dir) if os.path.isfile(c)), None)
        if src is None:
            raise _problem(path, dataset, expected, "does not exist")
        try:
            with h5py.File(src, "r") as s:
                for vds_name, dset in uses:
                    if "%" not in dset and dset not in s:
                        raise _problem(path, vds_name, os.path.abspath(src),
                                       f"holds no dataset {dset}")
            seen.append((os.path.abspath(src), _sig(src)))
        except MissingShardError:
            raise
        except OSError as exc:
            raise _problem(path, dataset, os.path.abspath(src),
                           f"cannot be opened ({exc})") from None
    if own is not None:
        _checked[key] = (own, tuple(seen))


def open_clip_file(path):
    """``h5py.File(path, "r")`` after :func:`check_virtual_sources`; use it wherever a
    converted file is opened for reading."""
    import h5py

    f = h5py.File(path, "r")
    try:
        check_virtual_sources(f, path)
    except BaseException:
        f.close()
        raise
    return f


def part_name(k: int) -> str:
    """The file of shard ``k`` inside the shards' folder."""
    return f"part-{k:05d}.h5"


#: Attributes that count a shard's part: the virtual file holds their sum over the shards.
SUMMED_ATTRS = ("fully_occluded_frames",)


def _copy_attrs(src, dst, parts=(), name="/") -> None:
    for key in src.attrs:
        value = src.attrs[key]
        if key in SUMMED_ATTRS and parts:
            value = sum(p[name].attrs[key] for p in parts)
        dst.attrs.create(key, value, dtype=src.attrs.get_id(key).dtype)


def write_virtual(path: Path, folder: Path, rel_folder: str, count: int) -> None:
    """``path``: the root and group attributes of shard 0 and one virtual dataset per
    dataset, the shards' pieces concatenated along axis 0 (sources: ``rel_folder/part-k``,
    relative to ``path``'s folder)."""
    import h5py

    parts = [h5py.File(folder / part_name(k), "r") for k in range(count)]
    try:
        first = parts[0]
        names: list = []
        first.visit(names.append)
        with h5py.File(path, "w", libver="latest") as out:
            _copy_attrs(first, out)
            for name in names:
                obj = first[name]
                if isinstance(obj, h5py.Group):
                    _copy_attrs(obj, out.require_group(name), parts, name)
                    continue
                pieces = [p[name] for p in parts]
                total = sum(d.shape[0] for d in pieces)
                layout = h5py.VirtualLayout(shape=(total,) + obj.shape[1:], dtype=obj.dtype)
                at = 0
                for k, d in enumerate(pieces):
                    n = d.shape[0]
                    if n:
                        layout[at:at + n] = h5py.VirtualSource(
                            f"{rel_folder}/{part_name(k)}", name, shape=d.shape,
                            dtype=d.dtype)
                    at += n
                ds = out.create_virtual_dataset(name, layout)
                _copy_attrs(obj, ds)
    finally:
        for p in parts:
            p.close()
