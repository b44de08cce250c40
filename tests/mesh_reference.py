"""Brute-force distances to triangle meshes: the slow, obvious references the mesh kernels are tested against
(tests/test_scene_meshes.py, tests/test_link_meshes.py)."""

from __future__ import annotations

import numpy as np


def point_segment(p, a, b):
    """Distance of point(s) ``p`` to the segment(s) ``a``-``b`` (m), broadcast over leading axes."""
    d = b - a
    t = np.clip(((p - a) * d).sum(-1) / np.maximum((d * d).sum(-1), 1e-300), 0, 1)
    return np.linalg.norm(a + t[..., None] * d - p, axis=-1)


def point_triangle(p, tri):
    """Distance of point ``p`` to each triangle ``tri (F, 3, 3)``: the plane inside the triangle, else an edge."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    h = ((p - a) * n).sum(1)
    q = p - h[:, None] * n
    inside = np.ones(len(tri), dtype=bool)
    for u, v in ((a, b), (b, c), (c, a)):
        inside &= (np.cross(v - u, q - u) * n).sum(1) >= 0
    edges = np.min([point_segment(p, u, v) for u, v in ((a, b), (b, c), (c, a))], axis=0)
    return np.where(inside, np.abs(h), edges)
