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


class ContentCache:
    """A least-recently-used map of at most ``size`` entries."""

    def __init__(self, size: int) -> None:
        if size < 1:
            raise ValueError(f"cache size must be >= 1, got {size}")
        self.size = size
        self._items: OrderedDict[Hashable, Any] = OrderedDict()

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
