"""Atomic file writes: write a temp file beside the target, fsync, then rename over it.

A reader never sees a half-written file, and an interrupted write leaves the old file intact.
Files get the usual permissions (0666 minus the umask), not mkstemp's 0600.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from pathlib import Path


def _umask_mode() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


def atomic_write(path: str | os.PathLike, write: Callable[[str], None]) -> Path:
    """Call ``write(tmp_path)`` to fill a temp file, then move it to ``path`` atomically."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    try:
        write(tmp)
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        os.chmod(tmp, _umask_mode())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically."""
    return atomic_write(path, lambda tmp: Path(tmp).write_bytes(data))


class OutputError(ValueError):
    """An output path that cannot be written; the one-line message says what to fix."""


def check_writable_folder(folder: str | os.PathLike, label: str | None = None) -> Path:
    """Fail early when files cannot be created in ``folder`` (it or its nearest existing ancestor).

    The check creates and removes a probe file (``os.access`` lies for root and read-only mounts);
    missing folders are not created here, only later by the atomic write.
    """
    folder = Path(folder) if str(folder) else Path(".")
    label = label or str(folder)
    probe_dir = folder
    while not probe_dir.exists():
        if probe_dir.parent == probe_dir:
            break
        probe_dir = probe_dir.parent
    if probe_dir.exists() and not probe_dir.is_dir():
        raise OutputError(f"{label}: cannot create the output folder, {probe_dir} is a file")
    try:
        fd, tmp = tempfile.mkstemp(dir=probe_dir, prefix=".garsim-write-probe.")
        os.close(fd)
        os.unlink(tmp)
    except OSError as exc:
        raise OutputError(f"{label}: the output folder {probe_dir} is not writable ({exc.strerror or exc})") from None
    return folder
