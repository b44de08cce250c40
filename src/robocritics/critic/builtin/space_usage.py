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

from ..hookspecs import hookimpl
from ..._arrays import row_max, squared_norms, unique_values
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
    T, L, _ = X.shape
    if tolerance_m > 0 and T > 2:
        nb = -(-T // BLOCK)
        d2 = X[2:] - X[1:-1]  # second differences p_{t+1} - 2 p_t + p_{t-1}, centred at samples 1..T-2
        d2 -= X[1:-1]
        d2 += X[:-2]
        M = np.zeros((nb * BLOCK, L))  # squared second-difference norms by sample (0 where undefined)
        squared_norms(d2, out=M[1 : T - 1])
        # block maxima along contiguous rows of the (L, T) transpose: a maximum over axis 1 of the
        # (nb, BLOCK, L) view costs 4x more
        Mb = np.sqrt(np.ascontiguousarray(M.T).reshape(L, nb, BLOCK).max(axis=2)).T  # (nb, L) block maxima, m
        with np.errstate(divide="ignore"):
            smax = np.sqrt(8.0 * tolerance_m / Mb)
        # stride: largest power of two <= smax, within [1, BLOCK]; frame-major order (L, nb)
        stride = np.exp2(np.floor(np.log2(np.clip(smax, 1.0, BLOCK)))).astype(np.int64).T.ravel()
        start = np.tile(np.arange(nb, dtype=np.int64) * BLOCK, L)
        frame = np.repeat(np.arange(L, dtype=np.int64), nb)
        count = -(-np.minimum(BLOCK, T - start) // stride)  # kept samples per block
        run = np.repeat(np.arange(stride.size), count)
        offset = np.arange(run.size) - np.repeat(np.cumsum(count) - count, count)
        ti = start[run] + offset * stride[run]
        li = frame[run]
        # every frame's last sample closes its last chord
        last_start = (nb - 1) * BLOCK
        last = np.flatnonzero((T - 1 - last_start) % stride.reshape(L, nb)[:, -1] != 0)
        if last.size:
            ti = np.concatenate([ti, np.full(last.size, T - 1)])
            li = np.concatenate([li, last])
    else:
        li, ti = np.divmod(np.arange(T * L), T)
    P = X[ti, li]
    if len(P) > 1:
        same = P[1:] == P[:-1]
        dup = np.zeros(len(P), dtype=bool)
        dup[1:] = same[:, 0] & same[:, 1] & same[:, 2]
        if dup.any():
            P, ti, li = P[~dup], ti[~dup], li[~dup]
    return P, ti, li


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


class SpaceUsageCritic:
    name = "space_usage"
    description = "Convex-hull volume of the links' swept positions against the allowed workspace; leaving it is an error."
    Params = Params

    def check(self, execution, params: Params) -> Verdict:
        trajectory, scene = execution.trajectory, execution.scene
        names = trajectory.frame_names
        if params.frames:
            sel = [trajectory.frame_index(n) for n in params.frames]
            names = tuple(names[i] for i in sel)
            X = np.ascontiguousarray(trajectory.positions[:, sel])
        else:
            X = trajectory.positions  # (T, L, 3) m, contiguous, shared with the other critics
        time = trajectory.time
        workspace = scene.workspace or _robot_workspace(execution.robot)
        w_volume = float(workspace.volume_m3)

        # --- leaving the workspace: every point ---------------------------------
        outside = np.asarray(workspace.outside_distance(X), dtype=float)  # (T, L) m, > 0 outside
        per_sample = row_max(outside)
        oi = int(np.argmax(per_sample))
        ol = int(np.argmax(outside[oi]))
        worst_out = float(outside[oi, ol])
        signal = make_signal(
            time,
            per_sample,
            label="farthest link beyond the workspace boundary (negative: inside)",
            unit="m",
            error=params.outside_tolerance_m,
        )

        # --- swept volume ----------------------------------------------------------
        P, ti, li = hull_points(X, params.hull_tolerance_m)
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
            rows = per_sample > params.outside_tolerance_m  # samples with some link outside
            links_out = (outside[rows] > params.outside_tolerance_m).any(axis=0)
            return verdict(
                Flag.ERROR,
                rows,
                worst=oi,
                links=[names[i] for i in np.flatnonzero(links_out)],
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
            far = int(np.argmax(outside[samples, li[vertices]])) if len(samples) else None
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
