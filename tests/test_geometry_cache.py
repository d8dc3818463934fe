"""Content-keyed caches: equal content hits, edited content misses, least-recently-used eviction."""

import numpy as np
import pytest
import trimesh

from garsim.geometry.cache import ContentCache, content_key
from garsim.geometry.io import as_mesh
from garsim.geometry.mesh import cached_vertex_normals, vertex_normals


def test_content_key_follows_content_not_identity():
    a = np.arange(12, dtype=np.float32).reshape(4, 3)
    assert content_key(a) == content_key(a.copy())
    b = a.copy()
    b[2, 1] += 1e-6
    assert content_key(a) != content_key(b)
    assert content_key(a) != content_key(a.astype(np.float64))  # dtype is part of the key
    assert content_key(a) != content_key(a.reshape(3, 4))


def test_lru_eviction_and_recompute():
    calls = []
    cache = ContentCache(2)
    for k in ("a", "b", "a", "c", "b"):
        cache.get(k, lambda k=k: calls.append(k) or k.upper())
    assert calls == ["a", "b", "c", "b"]  # "a" hit once; "b" was evicted by "c" (least recently used)
    assert len(cache) == 2
    assert cache.peek("a") is None and cache.peek("b") == "B"  # peek marks "b" recently used
    cache.put("d", "D")  # evicts "c", not the just-peeked "b"
    assert cache.peek("c") is None and cache.peek("b") == "B" and cache.peek("d") == "D"
    with pytest.raises(ValueError):
        ContentCache(0)


def test_edited_body_is_never_served_stale():
    s = trimesh.creation.icosphere(subdivisions=2)
    v, f = np.asarray(s.vertices, np.float64), np.asarray(s.faces)
    n1 = cached_vertex_normals(v, f)
    moved = v.copy()
    moved[:, 2] *= 2.0  # an edited body (new array content)
    np.testing.assert_allclose(cached_vertex_normals(moved, f), vertex_normals(moved, f))
    assert cached_vertex_normals(v, f) is n1 and not n1.flags.writeable
    mv, mf = as_mesh((v, f))
    assert as_mesh((v.copy(), f.copy()))[0] is mv and not mv.flags.writeable  # validated once, read-only


def test_clear_all_empties_registered_caches_by_scope():
    from garsim.geometry.cache import ContentCache, clear_all

    body, garment = ContentCache(2), ContentCache(2, scope="garment")
    body.put("b", 1)
    garment.put("g", 2)
    clear_all("garment")
    assert len(garment) == 0 and body.peek("b") == 1
    clear_all()
    assert len(body) == 0
