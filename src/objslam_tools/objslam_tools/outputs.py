"""Where a command may write: checked before the work starts, and never over what it reads.

A command names its inputs (bags, files) and its outputs (a file, a folder). Before any
long work, :func:`check_output_file` and :func:`check_output_dir` refuse an output inside
an input bag or equal to an input file, a file that exists unless ``--force`` was given,
and a place that cannot be written: a mistake costs one line, not a run, and never the
user's data.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path

from objslam_tools.errors import UserError


def _inside(path: Path, inputs: Iterable[Path]) -> Path | None:
    """The input that ``path`` is, or lies inside of (resolved, so links do not hide it)."""
    resolved = path.resolve()
    for source in inputs:
        source = Path(source).resolve()
        if resolved == source or (source.is_dir() and resolved.is_relative_to(source)):
            return source
    return None


def _writable_dir(folder: Path, flag: str) -> None:
    """``folder`` exists (made if missing) and this user may create files in it."""
    existing = folder
    while not existing.exists():
        existing = existing.parent
    if not existing.is_dir():
        raise UserError(f"{flag} {folder}: {existing} is a file, not a folder")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise UserError(f"{flag} {folder}: no permission to write in {existing}")


def check_output_file(path: Path, inputs: Iterable[Path], *, force: bool, flag: str = "--out") -> Path:
    """``path`` may be written (module docstring); the path, unchanged."""
    path = Path(path)
    source = _inside(path, inputs)
    if source is not None:
        raise UserError(f"{flag} {path} would overwrite the input {source}; write the output elsewhere")
    if path.is_dir():
        raise UserError(f"{flag} {path} is a folder; give the file's path")
    if path.exists() and not force:
        raise UserError(f"{flag} {path} exists; pass --force to replace it, or choose another name")
    _writable_dir(path.parent, flag)
    return path


def check_output_dir(folder: Path, inputs: Iterable[Path], *, flag: str) -> Path:
    """``folder`` may be written into (module docstring); the folder, unchanged."""
    folder = Path(folder)
    source = _inside(folder, inputs)
    if source is not None:
        raise UserError(f"{flag} {folder} is inside the input {source}; write the output elsewhere")
    if folder.exists() and not folder.is_dir():
        raise UserError(f"{flag} {folder} is a file, not a folder")
    _writable_dir(folder, flag)
    return folder
