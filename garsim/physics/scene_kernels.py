"""Warp kernels of the cloth scene's per-substep updates (pinned vertices, velocity damping, contact count).

Launched on the device rather than done as numpy round trips, so that every operation of a substep is a Warp
operation and the substep can be captured once and replayed as one graph (in C++ on the CPU, a CUDA graph on a GPU).
"""

from __future__ import annotations

import warp as wp


@wp.kernel
def place_pins(
    targets: wp.array(dtype=wp.vec3),
    index: wp.array(dtype=wp.int32),
    per_copy: int,
    q: wp.array(dtype=wp.vec3),
    qd: wp.array(dtype=wp.vec3),
):
    """Put pinned particle ``index[k]`` on ``targets[k % per_copy]`` (every copy), at rest."""
    k = wp.tid()
    p = index[k]
    q[p] = targets[k % per_copy]
    qd[p] = wp.vec3(0.0, 0.0, 0.0)


@wp.kernel
def scale_vec3(v: wp.array(dtype=wp.vec3), factor: float):
    """``v *= factor`` (per-substep velocity damping)."""
    i = wp.tid()
    v[i] = v[i] * factor


@wp.kernel
def atomic_max_int(value: wp.array(dtype=wp.int32), most: wp.array(dtype=wp.int32)):
    """``most[0] = max(most[0], value[0])`` (the largest contact count any collision pass needed)."""
    wp.atomic_max(most, 0, value[0])
