"""Where garsim keeps caches (Anny model data, warp kernels) and default data folders.

Everything lives under one cache root, ``$XDG_CACHE_HOME/garsim`` (default
``~/.cache/garsim``), never inside the source tree.
"""

from __future__ import annotations

import os
from pathlib import Path


def cache_root() -> Path:
    """The garsim cache folder (created on demand)."""
    base = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache"))
    root = base / "garsim"
    root.mkdir(parents=True, exist_ok=True)
    return root


def anny_cache_dir() -> Path:
    """Folder for Anny's built model data (first build ~40-80 s, then ~0.5 s)."""
    path = cache_root() / "anny"
    path.mkdir(parents=True, exist_ok=True)
    return path
