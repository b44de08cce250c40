"""Bounds over blocks of samples: where a pair is far, its exact distance is not computed there. Metres.

A trajectory's capsules move a little from one sample to the next, so over a block of :data:`BLOCK` samples each
capsule stays inside a few small balls (:func:`capsule_balls`); the distance of two such balls bounds the
distance of the capsules at every sample of the block from below and from above. The proximity kernel
(:meth:`robocritics.geometry.proximity.ProximityKernel.distances`) writes the lower bound of a pair over a block
where it is above every cutoff of the block's samples, and evaluates the pair exactly only in the other blocks
(:func:`near_entries`). The upper bounds of the pairs of a *column set* (:func:`column_sets`) bound the set's
least distance per sample (:func:`lower_upper`), so the cutoff can rise to it and the least distance over the
set stays exact.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .._arrays import unique_values

__all__ = ["BATCH", "BLOCK", "blocks", "capsule_balls", "column_sets", "fill_rows", "lower_upper", "near_entries", "self_bounds"]

#: Samples per block of the far-pair bounds: a capsule far from a shape over a block is not evaluated there;
#: shorter blocks bound tighter, longer ones cost less.
BLOCK = 32

#: Entries (pair-samples) handled at a time where the near blocks are gathered, evaluated or filled with their bound
#: (:func:`near_entries`, :func:`fill_rows`, the kernel's batches): their temporaries stay a few MB however long the
#: run is and however many of its blocks are near (every one, with ``far_m`` infinite).
BATCH = 16384


def blocks(x: np.ndarray, nb: int) -> np.ndarray:
    """``x (..., n)`` as ``(..., nb, BLOCK)``, the last block padded with copies of the last sample."""
    n = x.shape[-1]
    if nb * BLOCK != n:
        x = np.concatenate([x, np.repeat(x[..., -1:], nb * BLOCK - n, axis=-1)], axis=-1)
    return x.reshape(*x.shape[:-1], nb, BLOCK)


def capsule_balls(P0: np.ndarray, D: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per capsule and block of :data:`BLOCK` samples, balls ``(centre (3, C, nb), radius (C, nb))`` m holding
    the segment midpoints (the radius grown by the farthest one's half length: the ball holds the segments),
    the start points and the end points of segments ``P0 + t D`` ``(3, C, T)``. Centre: the block's middle sample.
    """
    nb = -(-P0.shape[2] // BLOCK)
    start, d = blocks(P0, nb), blocks(D, nb)  # (3, C, nb, B), padded once
    half = np.sqrt(np.einsum("icnb,icnb->cnb", d, d))
    half *= 0.5
    out = []
    for pb, h in ((start + 0.5 * d, half), (start, None), (start + d, None)):
        c = np.ascontiguousarray(pb[..., BLOCK // 2])  # padding repeats real samples: any index will do
        diff = pb - c[..., None]
        dist = np.sqrt(np.einsum("icnb,icnb->cnb", diff, diff))
        if h is not None:
            dist += h
        out.append((c, dist.max(axis=2)))
    return out


def column_sets(exact_min_of: Sequence[int] | Sequence[Sequence[int]], K: int) -> np.ndarray:
    """``(K,)`` int: the set of each of ``K`` columns (-1: none) from one list of column indices (one set) or a
    list of such lists; ValueError naming the column that is out of range or in two sets."""
    items = list(exact_min_of)
    sets = [items] if all(isinstance(v, (int, np.integer)) for v in items) else [list(v) for v in items]
    out = np.full(K, -1, dtype=np.int64)
    for s, cols in enumerate(sets):
        for k in cols:
            if not isinstance(k, (int, np.integer)) or not 0 <= int(k) < K:
                raise ValueError(f"exact_min_of[{s}]: {k!r} is not a column index in 0..{K - 1}")
            if out[k] not in (-1, s):
                raise ValueError(f"exact_min_of: column {int(k)} is in set {int(out[k])} and set {s}; a column is in one set")
            out[k] = s
    return out


def lower_upper(upper: np.ndarray, sets: np.ndarray, ub: np.ndarray, t0: int, n: int) -> None:
    """Lower each set's upper bound ``upper (S, T)`` (m, its least distance per sample) over the samples
    ``t0 .. t0 + n`` by the block upper bounds ``ub (m, nb)`` of rows of the sets ``sets (m,)``."""
    for s in unique_values(sets).tolist():  # not np.unique: it loads numpy.ma (tests/test_check_imports.py)
        u = np.repeat(ub[sets == s].min(axis=0), BLOCK)[:n]
        np.minimum(upper[s, t0 : t0 + n], u, out=upper[s, t0 : t0 + n])


def self_bounds(balls, ia, ib, r, cols, buf, upper, set_of, centre) -> np.ndarray:
    """Block bounds (m) of capsule pairs ``(ia[p], ib[p])`` (radius sums ``r (P, 1)``), the tighter of two:

    * from their balls (:func:`capsule_balls`): every point of capsule a's segment is within ``rho_a`` of the
      ball centre ``c_a`` at every sample of the block, so the segments are at least ``|c_a - c_b| - rho_a -
      rho_b`` apart and (start, end or midpoint balls, ``rho'`` without the half length) at most ``|c_a' -
      c_b'| + rho_a' + rho_b'``; less ``r``, the signed distance (the segment distance less the radii, exact
      also when they overlap) lies between;
    * from the exact signed distance ``centre (P, nb)`` at the block's centre sample (the centre of the start
      and end balls): the distance of two segments moves no more than their endpoints, so it stays within
      ``rho_a + rho_b`` of it, ``rho`` the larger radius of a capsule's start and end balls (less a rounding
      allowance of 1e-12 m).

    The lower bound goes to ``buf`` rows ``cols`` (and is returned, ``(P, nb)``); the upper bound of the rows in a
    column set lowers ``upper`` (:func:`lower_upper`).
    """
    T = buf.shape[1]
    out = []
    for c, rho in balls:
        diff = c[:, ia] - c[:, ib]
        gap = np.sqrt(np.einsum("ipn,ipn->pn", diff, diff))
        out.append((gap, rho[ia] + rho[ib]))
    move = np.maximum(balls[1][1], balls[2][1])
    slack = move[ia] + move[ib]
    slack += 1e-12
    lb = np.maximum(out[0][0] - out[0][1] - r, centre - slack)
    fill_rows(buf, cols, lb, 0, T)
    if set_of is not None:
        sel = set_of[cols] >= 0
        if sel.any():
            ub = np.minimum.reduce([(gap + rho)[sel] for gap, rho in out]) - r[sel]
            np.minimum(ub, (centre + slack)[sel], out=ub)
            lower_upper(upper, set_of[cols[sel]], ub, 0, T)
    return lb


def near_entries(rows: np.ndarray, near: np.ndarray, n: int):
    """The ``(row, sample)`` entries ``(m,)`` of the near blocks ``(rows[i], near[i])`` of a run of ``n`` samples,
    in slices of at most :data:`BATCH` entries (samples below ``n``): the gathers that follow hold no more
    than a slice, whatever the run's length and however many blocks are near."""
    per = max(1, BATCH // BLOCK)
    for i in range(0, len(rows), per):
        bi = near[i : i + per]
        ti = (bi[:, None] * BLOCK + np.arange(BLOCK)).ravel()
        pi = np.repeat(rows[i : i + per], BLOCK)
        if n % BLOCK:  # the run's last block is short
            ok = ti < n
            pi, ti = pi[ok], ti[ok]
        yield pi, ti


def fill_rows(buf: np.ndarray, rows: np.ndarray, lb: np.ndarray, t0: int, n: int) -> None:
    """``buf[rows[i], t0 : t0 + n]`` = the block bounds ``lb[i] (nb,)`` m, each repeated over its block's samples;
    about :data:`BATCH` values at a time (the repeated copy of a slice of rows is the only temporary)."""
    per = max(1, BATCH // max(n, 1))
    for i in range(0, len(rows), per):
        buf[rows[i : i + per], t0 : t0 + n] = np.repeat(lb[i : i + per], BLOCK, axis=1)[:, :n]
