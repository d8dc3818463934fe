"""Small LRU caches keyed by array content: per-body work (KD-trees, normals, fitted bone transforms)
done once and reused across garments and poses, never stale after an array is edited."""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable, Hashable
from typing import Any, TypeVar

import numpy as np

T = TypeVar("T")


def content_key(*arrays: Any) -> tuple:
    """A hashable key of the arrays' shapes, dtypes and bytes (a hash, not a copy of the data)."""
    key: list[Hashable] = []
    for a in arrays:
        arr = np.ascontiguousarray(a)
        key.append((arr.shape, arr.dtype.str, hash(arr.tobytes())))
    return tuple(key)


_REGISTRY: list[ContentCache] = []


def clear_all(scope: str | None = None) -> None:
    """Empty every ContentCache of the process, or only those of one ``scope`` ("body", "garment", ...):
    e.g. to time a cold first call, or a new garment on a known body."""
    for cache in _REGISTRY:
        if scope is None or cache.scope == scope:
            cache.clear()


class ContentCache:
    """A least-recently-used map of at most ``size`` entries; every instance is registered for ``clear_all``."""

    def __init__(self, size: int, scope: str = "body") -> None:
        """``scope`` names what the entries belong to ("body": per body mesh; "garment": per garment)."""
        if size < 1:
            raise ValueError(f"cache size must be >= 1, got {size}")
        self.size = size
        self.scope = scope
        self._items: OrderedDict[Hashable, Any] = OrderedDict()
        _REGISTRY.append(self)

    def peek(self, key: Hashable) -> Any | None:
        """The cached value for ``key`` (marked recently used), or None."""
        if key not in self._items:
            return None
        self._items.move_to_end(key)
        return self._items[key]

    def put(self, key: Hashable, value: T) -> T:
        """Store ``value`` under ``key``, evicting the least recently used entry beyond ``size``."""
        self._items[key] = value
        self._items.move_to_end(key)
        if len(self._items) > self.size:
            self._items.popitem(last=False)
        return value

    def get(self, key: Hashable, compute: Callable[[], T]) -> T:
        """The cached value for ``key``, computing (and storing) it on a miss."""
        if key in self._items:
            return self.peek(key)
        return self.put(key, compute())

    def clear(self) -> None:
        self._items.clear()

    def __len__(self) -> int:
        return len(self._items)
