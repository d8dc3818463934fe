"""Saved models on disk, without torch: file names, checksum, layout and config checks, and the verified
loading that both the torch model (``GraphModel.load``) and the numpy runtime (``garsim.model.runtime``) use."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import struct
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, TypeVar

from garsim.model.config import GarSimConfig

WEIGHTS_FILE = "model.safetensors"
CONFIG_FILE = "config.json"
CHECKSUM_KEY = "weights_sha256"
"""Top-level key of ``config.json`` holding the sha256 of ``model.safetensors`` (not a GarSimConfig field)."""
MODEL_KEY = "model"
DEFAULT_KIND = "garsim"
"""Top-level key of ``config.json`` naming the model (``GraphModel.kind``) when it is not GarSim; absent: GarSim."""

log = logging.getLogger(__name__)


class WeightsError(ValueError):
    """A saved model that cannot be trusted: one line naming the file and what is wrong with it."""


def file_sha256(path: Path) -> str:
    """Hex sha256 of a file, read in 1 MiB chunks."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _safetensors_problem(path: Path) -> str | None:
    """What is wrong with the layout of a safetensors file (truncated, bad header), or None; never raises."""
    try:
        size = path.stat().st_size
        with open(path, "rb") as fh:
            head = fh.read(8)
            if len(head) < 8:
                return f"truncated: {size} bytes, too short for a safetensors header"
            (n,) = struct.unpack("<Q", head)
            if n > size - 8:
                return f"truncated: {size} bytes, but its header alone claims {n + 8}"
            header = json.loads(fh.read(n))
        if not isinstance(header, dict):
            return "corrupt safetensors header (not a JSON object)"
        end = 0
        for key, info in header.items():
            if key == "__metadata__":
                continue
            end = max(end, int(info["data_offsets"][1]))
        if size < 8 + n + end:
            return f"truncated: {size} bytes, its header expects {8 + n + end}"
    except (OSError, ValueError, TypeError, KeyError, IndexError) as exc:
        return f"corrupt safetensors header ({type(exc).__name__}: {exc})".replace("\n", " ")
    return None


_SIMPLE_TYPES: dict[str, tuple[type, ...]] = {"int": (int,), "float": (int, float), "bool": (bool,), "str": (str,)}


def _check_config_types(d: dict[str, Any]) -> None:
    """Refuse values whose JSON type does not fit the GarSimConfig field (``"latent": "64"``, ``"residual": 1``)."""
    for f in dataclasses.fields(GarSimConfig):
        if f.name not in d:
            continue
        v, t = d[f.name], str(f.type).replace(" ", "")
        optional = t.endswith("|None")
        base = t[: -len("|None")] if optional else t
        if v is None and optional:
            continue
        if base in _SIMPLE_TYPES:
            ok = isinstance(v, _SIMPLE_TYPES[base]) and (base == "bool" or not isinstance(v, bool))
        elif base.startswith("tuple[int"):
            ok = isinstance(v, list | tuple) and all(isinstance(x, int) and not isinstance(x, bool) for x in v)
        else:
            continue
        if not ok:
            raise ValueError(f"{f.name} must be {t.replace('|', ' | ')}, got {v!r}")


def _read_config(path: Path) -> tuple[GarSimConfig, str | None, str]:
    """config.json -> (GarSimConfig, recorded weights sha256 or None, model kind); WeightsError when malformed."""
    try:
        d = json.loads(path.read_text())
        if not isinstance(d, dict):
            raise TypeError(f"expected a JSON object, got {type(d).__name__}")
        checksum = d.pop(CHECKSUM_KEY, None)
        if checksum is not None and not (isinstance(checksum, str) and len(checksum) == 64):
            raise ValueError(f"{CHECKSUM_KEY} must be a 64-digit hex string, got {checksum!r}")
        kind = d.pop(MODEL_KEY, DEFAULT_KIND)
        _check_config_types(d)
        return GarSimConfig.from_dict(d), checksum, kind
    except (OSError, UnicodeDecodeError, ValueError, TypeError) as exc:
        msg = str(exc).replace("\n", " ")
        raise WeightsError(f"{path}: malformed config ({type(exc).__name__}: {msg})") from None


def read_model_config(path: str | Path) -> tuple[GarSimConfig, str]:
    """(GarSimConfig, model kind) of a ``config.json``; ``WeightsError`` when it is malformed."""
    config, _, kind = _read_config(Path(path))
    return config, kind


T = TypeVar("T")


def load_verified(
    directory: str | Path, kind: str, read: Callable[[str], Mapping[str, T]], owner: str = "GarSimModel"
) -> tuple[GarSimConfig, dict[str, T]]:
    """(config, state) of a model directory whose ``config.json`` names ``kind``, after every check: files
    present, checksum, safetensors layout, config types. ``read`` loads the safetensors file (torch or numpy).

    Raises ``WeightsError`` (one line naming the file) when the weights fail their checksum, are truncated or
    corrupt, or the config is malformed. A config without a checksum (written before checksums) loads with a
    warning. Whether the tensors fit the config is the caller's check."""
    from safetensors import SafetensorError

    d = Path(directory)
    wpath, cpath = d / WEIGHTS_FILE, d / CONFIG_FILE
    if not wpath.exists() or not cpath.exists():
        raise FileNotFoundError(f"{d} must contain {WEIGHTS_FILE} and {CONFIG_FILE} (written by {owner}.save)")
    config, expected, found = _read_config(cpath)
    if found != kind:
        raise WeightsError(f"{cpath}: holds a {found!r} model, not {kind!r}; load it with that model's class")
    problem = _safetensors_problem(wpath)
    if expected is None:
        log.warning("%s has no %s (saved before checksums): %s is loaded unverified", cpath, CHECKSUM_KEY, wpath)
    else:
        actual = file_sha256(wpath)
        if actual != expected.lower():
            detail = f"; {problem}" if problem else ""
            raise WeightsError(
                f"{wpath}: checksum mismatch (sha256 {actual[:12]}..., "
                f"{CONFIG_FILE} records {expected[:12]}...){detail}"
            )
    if problem:
        raise WeightsError(f"{wpath}: {problem}")
    try:
        return config, dict(read(str(wpath)))
    except (SafetensorError, OSError, ValueError, RuntimeError) as exc:
        msg = str(exc).replace("\n", " ")
        raise WeightsError(f"{wpath}: unreadable safetensors ({type(exc).__name__}: {msg})") from None


def check_state(state: Mapping[str, Any], own: Mapping[str, tuple[int, ...]], wpath: str | Path) -> None:
    """Raise ``WeightsError`` unless ``state`` has exactly the tensor names and shapes of ``own`` (name -> shape)."""
    name = CONFIG_FILE
    missing = sorted(set(own) - set(state))
    unexpected = sorted(set(state) - set(own))
    if missing or unexpected:
        raise WeightsError(f"{wpath}: weights do not match {name}: missing {missing[:5]}, unexpected {unexpected[:5]}")
    wrong = [f"{k} {tuple(state[k].shape)} vs {tuple(s)}" for k, s in own.items() if tuple(state[k].shape) != tuple(s)]
    if wrong:
        raise WeightsError(
            f"{wpath}: weights do not match {name}: {len(wrong)} tensor shapes differ "
            f"(file vs config), e.g. {'; '.join(wrong[:3])}"
        )
