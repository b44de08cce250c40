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


def bumpy_sphere(n: int = 24, radius: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """A closed UV sphere of ``2 n (n - 1)`` triangles, ``radius`` (m) with bumps (convex and dented patches)."""
    theta, phi = np.meshgrid(np.linspace(0, np.pi, n + 1)[1:-1], np.linspace(0, 2 * np.pi, 2 * n, endpoint=False), indexing="ij")
    r = radius * (1 + 0.15 * np.sin(3 * theta) * np.cos(4 * phi))
    ring = np.stack([r * np.sin(theta) * np.cos(phi), r * np.sin(theta) * np.sin(phi), r * np.cos(theta)], axis=-1).reshape(-1, 3)
    V = np.vstack([ring, [[0, 0, radius], [0, 0, -radius]]])
    top, bottom, m = len(ring), len(ring) + 1, 2 * n
    F = []
    for j in range(m):
        F.append((top, j, (j + 1) % m))
        F.append((bottom, (n - 2) * m + (j + 1) % m, (n - 2) * m + j))
    for i in range(n - 2):
        for j in range(m):
            a, b, c, d = i * m + j, i * m + (j + 1) % m, (i + 1) * m + j, (i + 1) * m + (j + 1) % m
            F += [(a, c, b), (b, c, d)]
    return V, np.array(F, np.int64)
