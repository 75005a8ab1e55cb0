"""The checks every tool makes on a path it is about to write (`-o`, `--out`, `--state`), before any
work: one line naming the option and the path (`InputError`, exit 2) instead of a traceback after
minutes of computing, and never a write over the file the command reads."""

from __future__ import annotations

import os
from pathlib import Path

from .errors import InputError


def output_file(path, option: str = "-o", source=None, source_is: str = "the input", parents: bool = False) -> Path:
    """A file to write: not a folder, in a folder that exists (or, with `parents`, that the caller
    makes: nothing on the way is a file), and not `source` (what the command reads; writing it
    would destroy it)."""
    path = Path(path)
    if path.is_dir():
        raise InputError(f"{option} {path}: is a folder; give a file name")
    if parents:
        output_folder(path.parent, option)
    elif not path.parent.is_dir():
        raise InputError(f"{option} {path}: no folder {path.parent}")
    if source is not None and path.exists() and os.path.samefile(path, source):
        raise InputError(f"{option} {path}: is {source_is}")
    return path


def output_folder(path, option: str = "-o") -> Path:
    """A folder to write into (created with its parents by the caller): not a file, nor under one."""
    path = Path(path)
    existing = next(p for p in (path, *path.parents) if p.exists())
    if not existing.is_dir():
        where = "is a file" if existing == path else f"{existing} is a file"
        raise InputError(f"{option} {path}: {where}, not a folder")
    return path


def numpy_file(path, suffix: str = ".npz") -> Path:
    """The file numpy writes for `path`: it appends `suffix` when the name does not end with it."""
    path = Path(path)
    return path if path.suffix == suffix else path.with_name(path.name + suffix)
