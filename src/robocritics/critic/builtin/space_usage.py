r"""Space usage critic (RoboCritics paper §3.1.2; CoFrame).

Maths and units
---------------
Let ``P = { p_{t,l} }`` be the origins (m, base frame) of every frame ``l`` of
the robot at every sample ``t``. The space the motion sweeps is measured by the
volume (m^3) of the convex hull ``conv(P)`` (coal's Qhull, already loaded for proximity); the allowed
workspace ``W`` is ``scene.workspace`` (default: the robot's reach sphere around its shoulder; for the
UR3e, the default arm, 0.5 m and 0.523 m^3, as in the authors' prototype).

* ERROR if any point lies outside ``W``:
  ``max_{t,l} scene.workspace.outside_distance(p_{t,l}) > outside_tolerance_m``;
  the message names the link, the time and the sample;
* WARNING if ``volume(conv(P)) > warn_fraction * volume(W)`` (paper: 50 %);
* OK otherwise.

Speed with a known error bound
------------------------------
Consecutive samples at 500 Hz lie a fraction of a millimetre apart, and a
hull of every one of them is slow (every point of a convex arc is a hull
vertex). Before the hull we drop samples that cannot matter by more than
``hull_tolerance_m``: per frame and per block of 64 samples, with ``M`` the
largest second difference ``|p_{t+1} - 2 p_t + p_{t-1}|`` in the block, every
``s``-th sample is kept where ``s`` is the largest power of two with
``M s^2 / 8 <= hull_tolerance_m``. By the discrete maximum principle each
dropped point then lies within ``hull_tolerance_m`` of the chord between its
kept neighbours, so ``conv(kept) ⊆ conv(P) ⊆ conv(kept) ⊕ B(hull_tolerance_m)``:
the volume is under-estimated by at most about ``area * hull_tolerance_m``
(the bound, by Steiner's formula, is reported as ``details["volume_error_bound_m3"]``). ``hull_tolerance_m = 0``
gives the exact hull. Identical consecutive points (a frame that does not
move) are kept once. The workspace check always uses every point.

Degenerate point sets (fewer than 4 distinct points, all coplanar or
collinear to rounding, about 1e-12 of their size) have volume 0; thinner
sets than coal's Qhull copes with are measured by the numpy quickhull (see
:mod:`robocritics.geometry.hull`).
"""

from __future__ import annotations

from functools import partial

import numpy as np
from pydantic import Field

from ..chunked import AnyOver, Extreme, Series, judge_in_chunks
from ..hookspecs import hookimpl
from ..._arrays import row_max, unique_values
from ...scene import Workspace
from ..derived import Frames, frame_kinds, moving_frames, position_planes
from .. import CriticParams, Flag, ParamNames, Verdict, fmt_length, make_signal, threshold_verdict
from ...geometry.hull import convex_hull

__all__ = ["SpaceUsageCritic", "register_critics", "hull_points", "hull_volume", "volume_error_bound"]

BLOCK = 64

class Params(CriticParams):
    warn_fraction: float = Field(
        0.5,
        gt=0,
        le=1,
        description="warning when the hull volume exceeds this fraction of the allowed workspace volume "
        "(source: RoboCritics paper, 50 % of W_allowed)",
    )
    outside_tolerance_m: float = Field(
        0.0, ge=0, description="how far, m, a link point may lie outside the allowed workspace before it is an error"
    )
    hull_tolerance_m: float = Field(
        0.0005,
        ge=0,
        description="points within this distance, m, of the chord between retained samples of the same frame are "
        "left out of the hull; bounds the volume under-estimate by ~hull area x tolerance (0 = exact hull)",
    )
    frames: ParamNames = Field((), description="frames whose origins make up the swept points; empty = every frame")


def hull_points(X: np.ndarray, tolerance_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points of ``X (T, L, 3)`` that determine the hull to within ``tolerance_m``.

    Returns ``(points (N, 3), sample index (N,), frame index (N,))``.
    """
    T = X.shape[0]
    ti, li = kept_samples(np.ascontiguousarray(X.transpose(2, 1, 0)), 0, 0, T, T, tolerance_m)
    ti, li = frame_major(ti, li)
    return without_repeats(X[ti, li], ti, li)


def second_differences(Y: np.ndarray, rows: slice, out: np.ndarray | None = None) -> np.ndarray:
    """``(L, n)`` squared norms, m^2, of the second differences ``p_{t+1} - 2 p_t + p_{t-1}`` of the positions
    ``Y (3, L, T)`` (coordinate planes) at the samples ``t`` of ``rows`` (each with a sample either side), as
    ``((p_{t+1} - p_t) - p_t) + p_{t-1}`` per coordinate and ``x^2 + z^2 + y^2``
    (:func:`robocritics._arrays.squared_norms`' order); into ``out`` when given."""
    lo, hi = rows.start, rows.stop
    total = out
    for c in (0, 2, 1):  # x, then z and y added
        Yc = Y[c]
        dc = np.subtract(Yc[:, lo + 1 : hi + 1], Yc[:, lo:hi])
        dc -= Yc[:, lo:hi]
        dc += Yc[:, lo - 1 : hi - 1]
        if c == 0:
            total = np.multiply(dc, dc, out=out)
        else:
            dc *= dc
            total += dc
    return total


def kept_samples(Y: np.ndarray, lo: int, start: int, stop: int, T: int, tolerance_m: float, kinds: Frames | None = None):
    """``(sample (N,), frame (N,))`` indices (in the run of ``T`` samples) of the points kept from samples
    ``start..stop-1`` (``start`` a multiple of :data:`BLOCK`), frame-major: for each frame, its kept samples
    block by block. ``Y (3, L, n)`` holds the coordinate planes of samples ``lo..lo+n-1``
    (:func:`robocritics.critic.derived.position_planes`): those and the sample either side (for the second
    differences). Without the closing sample of :func:`frame_major`. The second differences are computed for
    ``kinds.runs`` only (:func:`frame_kinds`, found here if not given): 0 for the still frames, a copy's its twin's.
    """
    L = Y.shape[1]
    n = stop - start
    if not (tolerance_m > 0 and T > 2):
        li, ti = np.divmod(np.arange(n * L), n)
        return ti + start, li
    nb = -(-n // BLOCK)
    kinds = frame_kinds(Y) if kinds is None else kinds
    block_max = np.zeros((L, nb))  # largest squared second-difference norm, m^2, by frame and block
    first, last = max(start, 1), min(stop, T - 1)  # the samples with a second difference
    if last > first:
        for a, b in kinds.runs:
            M = np.zeros((b - a, nb * BLOCK))  # squared second-difference norms by frame and sample (0 where undefined)
            second_differences(Y[:, a:b], slice(first - lo, last - lo), out=M[:, first - start : last - start])
            block_max[a:b] = M.reshape(b - a, nb, BLOCK).max(axis=2)
        block_max[kinds.copies] = block_max[kinds.twins]
    Mb = np.sqrt(block_max).T  # (nb, L) block maxima, m
    with np.errstate(divide="ignore"):
        smax = np.sqrt(8.0 * tolerance_m / Mb)
    # stride: largest power of two <= smax, within [1, BLOCK]; frame-major order (L, nb)
    stride = np.exp2(np.floor(np.log2(np.clip(smax, 1.0, BLOCK)))).astype(np.int64).T.ravel()
    block_start = np.tile(np.arange(nb, dtype=np.int64) * BLOCK + start, L)
    frame = np.repeat(np.arange(L, dtype=np.int64), nb)
    count = -(-np.minimum(BLOCK, stop - block_start) // stride)  # kept samples per block
    run = np.repeat(np.arange(stride.size), count)
    offset = np.arange(run.size) - np.repeat(np.cumsum(count) - count, count)
    ti = block_start[run] + offset * stride[run]
    li = frame[run]
    if stop == T:  # every frame's last sample closes its last chord
        last_start = start + (nb - 1) * BLOCK
        closing = np.flatnonzero((T - 1 - last_start) % stride.reshape(L, nb)[:, -1] != 0)
        if closing.size:  # marked by a negative frame index, for frame_major to put last
            ti = np.concatenate([ti, np.full(closing.size, T - 1)])
            li = np.concatenate([li, -1 - closing])
    return ti, li


def frame_major(ti: np.ndarray, li: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The kept points of consecutive chunks (:func:`kept_samples`, concatenated) in the order of the whole run:
    frame by frame, then the closing samples of the frames that need one; the frame indices made plain."""
    order = frame_major_order(li)
    li = li[order]
    return ti[order], np.where(li < 0, -1 - li, li)


def frame_major_order(li: np.ndarray) -> np.ndarray:
    """The permutation :func:`frame_major` applies (frame indices as :func:`kept_samples` marks them)."""
    order = np.argsort(li, kind="stable")
    closing = li[order] < 0
    return np.concatenate([order[~closing], order[closing][::-1]])


def without_repeats(P: np.ndarray, *along: np.ndarray) -> tuple[np.ndarray, ...]:
    """``(P, *along)`` without each point of ``P (N, 3)`` equal to the one before it (a frame that does not
    move: kept once), and the same rows of the arrays ``along``."""
    if len(P) > 1:
        same = P[1:] == P[:-1]
        dup = np.zeros(len(P), dtype=bool)
        dup[1:] = same[:, 0] & same[:, 1] & same[:, 2]
        if dup.any():
            return (P[~dup], *(a[~dup] for a in along))
    return (P, *along)


def hull_volume(P: np.ndarray) -> tuple[float, float, np.ndarray]:
    """``(volume m^3, area m^2, vertex indices)`` of the convex hull of ``P (N, 3)``; 0 for degenerate sets.

    See :func:`robocritics.geometry.hull.convex_hull`: vertex indices ascend (the first of equal points); sets flat
    to rounding give ``(0, 0, [])``.
    """
    if len(P) < 4:
        return 0.0, 0.0, np.arange(len(P))
    hull = convex_hull(P)
    return hull.volume_m3, hull.area_m2, hull.vertices


def volume_error_bound(P: np.ndarray, area: float, tolerance_m: float) -> float:
    """Upper bound, m^3, on ``volume(conv(all points)) - volume(conv(P))`` when every dropped point
    lies within ``tolerance_m`` of ``conv(P)``: Steiner's formula for ``conv(P) ⊕ B(tol)``,
    ``A tol + 2 pi w tol^2 + 4/3 pi tol^3`` with the mean width ``w`` bounded by the bounding-box diagonal."""
    if tolerance_m <= 0 or len(P) == 0:
        return 0.0
    Pt = np.ascontiguousarray(P.T)  # (3, N): extremes along contiguous rows, 15x faster than along axis 0
    diagonal = float(np.linalg.norm(Pt.max(axis=1) - Pt.min(axis=1)))
    return area * tolerance_m + 2 * np.pi * diagonal * tolerance_m**2 + 4 / 3 * np.pi * tolerance_m**3


def _robot_workspace(robot):
    """The workspace of a scene that names none: its robot's reach sphere, or the default arm's."""
    if robot is not None:
        return robot.workspace
    from ...robot.model import default_workspace

    return default_workspace()


def _outside(workspace, Y: np.ndarray, own: slice, kinds: Frames | None = None):
    """``(per_sample (n,), outside, farthest)`` for the samples ``own`` of the planes ``Y (3, L, T)``: how far
    the farthest point of each sample lies outside ``workspace``, m; ``outside(rows, frames)``, the outside
    distances of the points at those (broadcast) indices, rows counted from ``own.start``; and
    ``farthest(rows) (L,)``, each frame's largest outside distance over ``rows`` (NaN left out): all as
    ``workspace.outside_distance`` gives them, bit for bit.

    The farthest of several points is the one of largest squared centre distance (``outside_of_squared`` does
    not decrease), so only the samples' square roots are taken for every sample, and the squared distances only
    of the frames of ``kinds.runs`` (:func:`frame_kinds`): a still frame's is one number, a copy's its twin's.
    The asked points' are computed where asked. A workspace that defines its own ``outside_distance`` is asked
    for every point.
    """
    if type(workspace).outside_distance is not Workspace.outside_distance:
        distance = np.asarray(workspace.outside_distance(Y[:, :, own].transpose(2, 1, 0)), dtype=float)  # (n, L)
        return (row_max(distance), lambda rows, frames: distance[rows, frames],
                lambda rows: np.fmax.reduce(distance[rows], axis=0))  # fmt: skip
    kinds = frame_kinds(Y) if kinds is None else kinds
    squared = workspace.squared_centre_distance  # (x, y, z) -> |p - c|^2, m^2, elementwise
    widest = None  # (n,) the largest squared centre distance of each sample, m^2
    for a, b in kinds.runs:
        part = squared(Y[0, a:b, own], Y[1, a:b, own], Y[2, a:b, own]).max(axis=0)
        widest = part if widest is None else np.maximum(widest, part, out=widest)
    if kinds.still.size:
        at = own.start
        part = float(squared(Y[0, kinds.still, at], Y[1, kinds.still, at], Y[2, kinds.still, at]).max())
        widest = np.full(own.stop - own.start, part) if widest is None else np.maximum(widest, part, out=widest)

    def outside(rows, frames):
        t = np.asarray(rows) + own.start
        return workspace.outside_of_squared(squared(Y[0, frames, t], Y[1, frames, t], Y[2, frames, t]))

    def farthest(rows):
        t = np.asarray(rows) + own.start
        widest = np.empty(Y.shape[1])  # each frame's largest squared centre distance over the rows, m^2
        for a, b in kinds.runs:
            X = Y[:, a:b]
            widest[a:b] = np.fmax.reduce(squared(X[0][:, t], X[1][:, t], X[2][:, t]), axis=1)
        widest[kinds.still] = squared(Y[0, kinds.still, t[0]], Y[1, kinds.still, t[0]], Y[2, kinds.still, t[0]])
        widest[kinds.copies] = widest[kinds.twins]
        return workspace.outside_of_squared(widest)

    return workspace.outside_of_squared(widest), outside, farthest


class SpaceUsageCritic:
    name = "space_usage"
    description = "Convex-hull volume of the links' swept positions against the allowed workspace; leaving it is an error."
    Params = Params

    def check(self, execution, params: Params) -> Verdict:
        return judge_in_chunks(self, execution, params)

    def reduction(self, execution, params: Params) -> "_Swept":
        return _Swept(self.name, execution, params)


class _Swept:
    """The space-usage judgement, chunk by chunk: the farthest link beyond the workspace per sample (where it is
    farthest, and which links leave it), and the points each chunk keeps for the hull (:func:`kept_samples`:
    chunks start on the hull's 64-sample blocks), with how far outside each lies; the hull of them all at the end."""

    def __init__(self, name: str, execution, params: Params):
        trajectory = execution.trajectory
        self.name, self.trajectory, self.params = name, trajectory, params
        names = trajectory.frame_names
        self.sel = None
        if params.frames:
            self.sel = [trajectory.frame_index(n) for n in params.frames]
            names = tuple(names[i] for i in self.sel)
        self.names = names
        self.workspace = execution.scene.workspace or _robot_workspace(execution.robot)
        self.per_sample = Series(len(trajectory))
        self.farthest = Extreme("max")
        self.links_out = AnyOver(len(names))
        self.kept: list[tuple[np.ndarray, ...]] = []  # per chunk: (sample, frame, point, outside distance)

    def add(self, chunk, execution) -> None:
        params, workspace = self.params, self.workspace
        Y = position_planes(execution)  # (3, L, n) m
        if self.sel is not None:
            Y = Y[:, self.sel]
        # the frames that need their own work (a robot's base is still), shared with the joint-speed critic
        kinds = moving_frames(execution) if self.sel is None else frame_kinds(Y)
        per_sample, outside, farthest = _outside(workspace, Y, slice(chunk.own.start, chunk.own.stop), kinds)
        self.per_sample.put(chunk.start, per_sample)
        frames = np.arange(Y.shape[1])
        self.farthest.offer(chunk.start, per_sample, lambda i: int(np.argmax(outside(i, frames))))
        over = np.flatnonzero(per_sample > params.outside_tolerance_m)
        if over.size:  # the links outside at some sample where some link is: those whose farthest there is
            self.links_out.add((farthest(over) > params.outside_tolerance_m)[None, :])
        # --- the points the hull needs ----------------------------------------
        ti, li = kept_samples(Y, chunk.lo, chunk.start, chunk.stop, len(self.trajectory), params.hull_tolerance_m, kinds)
        frame = np.where(li < 0, -1 - li, li)
        points = Y[:, frame, ti - chunk.lo].T
        self.kept.append((ti, li, points, outside(ti - chunk.start, frame)))

    def verdict(self) -> Verdict:
        params, trajectory, names = self.params, self.trajectory, self.names
        time = trajectory.time
        w_volume = float(self.workspace.volume_m3)
        per_sample = self.per_sample.values
        oi, ol = self.farthest.index, self.farthest.detail
        worst_out = float(self.farthest.value)
        signal = make_signal(
            time,
            per_sample,
            label="farthest link beyond the workspace boundary (negative: inside)",
            unit="m",
            error=params.outside_tolerance_m,
        )

        # --- swept volume ----------------------------------------------------------
        ti, li, points, outside_at = (np.concatenate(parts) for parts in zip(*self.kept))
        order = frame_major_order(li)
        ti, li = frame_major(ti, li)
        P, ti, li, outside_at = without_repeats(points[order], ti, li, outside_at[order])
        volume, area, vertices = hull_volume(P)
        fraction = volume / w_volume if w_volume > 0 else float("inf")
        tol = params.hull_tolerance_m
        details = {
            "hull_volume_m3": volume,
            "workspace_volume_m3": w_volume,
            "fraction_of_workspace": fraction,
            "hull_points": int(len(P)),
            "volume_error_bound_m3": volume_error_bound(P, area, tol),
            "max_outside_distance_m": worst_out,
        }

        verdict = partial(threshold_verdict, self.name, trajectory, signal=signal, details=details)
        if worst_out > params.outside_tolerance_m:
            return verdict(
                Flag.ERROR,
                per_sample > params.outside_tolerance_m,  # samples with some link outside
                worst=oi,
                links=[names[i] for i in np.flatnonzero(self.links_out.hit)],
                value=worst_out,
                threshold=params.outside_tolerance_m,
                unit="m",
                message=f"The robot leaves the allowed workspace: the {names[ol]} is {fmt_length(worst_out)} outside it "
                f"at {time[oi]:.2f} s (sample {oi}).",
                hint="To keep the robot inside the allowed workspace, you can consider moving to positions closer to "
                "the robot{during}.",
            )
        limit = params.warn_fraction * w_volume
        if volume > limit:
            samples = ti[vertices]
            # the hull vertex nearest to leaving the workspace
            far = int(np.argmax(outside_at[vertices])) if len(samples) else None
            return verdict(
                Flag.WARNING,
                samples,
                worst=int(samples[far]) if far is not None else None,
                links=[names[i] for i in unique_values(li[vertices]).tolist()],
                value=volume,
                threshold=limit,
                unit="m³",
                message=f"The motion sweeps {volume:.3f} m³, {fraction * 100:.0f} % of the allowed workspace "
                f"(more than the recommended {params.warn_fraction * 100:.0f} %).",
                hint="To use less space, you can consider moving through fewer or closer waypoints, or lower approach "
                "heights{during}.",
            )
        return verdict(
            Flag.OK,
            worst=oi,
            links=[names[ol]],
            value=volume,
            threshold=limit,
            unit="m³",
            message=f"The motion sweeps {volume:.3f} m³, {fraction * 100:.0f} % of the allowed workspace, and stays inside it.",
        )


@hookimpl
def register_critics(register):
    register(SpaceUsageCritic())
