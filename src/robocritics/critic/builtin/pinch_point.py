r"""Pinch point critic (RoboCritics paper §3.1.2; CoFrame).

Risk: two parts of the robot closing on each other with a hand in between.

Maths and units
---------------
Reads **only** the trajectory's ``kind == "self"`` proximity pairs, which the
robot model limits to non-adjacent arm links and arm-vs-gripper pairs (CoFrame's
careful version; the authors' prototype fired on any proximity value, which
this critic does not: environment pairs never count here). With ``d_{t,k}``
the distance (m) of self pair ``k`` at sample ``t`` and
``D = min_{t,k} d_{t,k}``:

* ERROR if ``D < d_min_m`` (0.025 m, CoFrame);
* WARNING if ``d_min_m <= D < d_max_m`` (0.06 m, CoFrame);
* OK otherwise.
"""

from __future__ import annotations

from functools import partial

import numpy as np
from pydantic import Field, model_validator

from ..hookspecs import hookimpl
from ..chunked import AnyOver, Extreme, Series, judge_in_chunks
from ..derived import columns_as_rows
from .. import CriticParams, Flag, Verdict, fmt_length, make_signal, threshold_verdict

__all__ = ["PinchPointCritic", "register_critics"]


class Params(CriticParams):
    d_min_m: float = Field(0.025, ge=0, description="error below this self distance, m (source: CoFrame default, 2.5 cm)")
    d_max_m: float = Field(0.06, gt=0, description="warning below this self distance, m (source: CoFrame default, 6 cm)")

    @model_validator(mode="after")
    def _order(self) -> "Params":
        if self.d_min_m > self.d_max_m:
            raise ValueError(f"d_min_m ({self.d_min_m}) must not exceed d_max_m ({self.d_max_m})")
        return self


class PinchPointCritic:
    name = "pinch_point"
    description = "Closest approach between non-adjacent robot links and between arm and gripper."
    Params = Params

    def check(self, execution, params: Params) -> Verdict:
        return judge_in_chunks(self, execution, params)

    def reduction(self, execution, params: Params) -> "_Closest":
        return _Closest(self.name, execution.trajectory, params)


class _Closest:
    """The pinch-point judgement, chunk by chunk: the closest self distance per sample, where it is least (and
    its pair), and which pairs pass either threshold."""

    def __init__(self, name: str, trajectory, params: Params):
        self.name, self.trajectory, self.params = name, trajectory, params
        self.columns = trajectory.pair_mask(kind="self")  # (K,) only self pairs ever count
        self.gather = np.flatnonzero(self.columns)
        self.per_sample = Series(len(trajectory))
        self.closest = Extreme("min")
        self.hits = {t: AnyOver(len(self.columns)) for t in (params.d_min_m, params.d_max_m)}

    def add(self, chunk, execution) -> None:
        if not self.gather.size:
            return
        P = chunk.trajectory.proximity[chunk.own]
        # (n,): the self columns gathered as rows of P.T (Ks, n), then elementwise minima of whole rows (the minimum
        # along each short row of P[:, gather] costs 2x, a masked `where=` reduction 8x)
        rows_of_pairs = columns_as_rows(P, self.gather)
        per_sample = rows_of_pairs.min(axis=0)
        self.per_sample.put(chunk.start, per_sample)
        self.closest.offer(chunk.start, per_sample, lambda i: int(np.argmin(np.where(self.columns, P[i], np.inf))))
        # which pairs come within either threshold: each self pair's closest distance over the samples closer than
        # d_max_m (d_min_m is no larger, so those hold every sample below it; NaN left out)
        rows = np.flatnonzero(per_sample < self.params.d_max_m)
        if rows.size:
            nearest = np.full((1, len(self.columns)), np.inf)  # (1, K) m; the gathered rows, not P[rows]
            nearest[0, self.gather] = np.fmin.reduce(rows_of_pairs[:, rows], axis=1)
            for threshold, hits in self.hits.items():
                hits.add(nearest < threshold)

    def verdict(self) -> Verdict:
        params, trajectory = self.params, self.trajectory
        if not self.gather.size:
            return threshold_verdict(
                self.name,
                None,
                Flag.OK,
                message="The trajectory has no robot self-proximity pairs to check.",
                threshold=params.d_max_m,
                unit="m",
            )
        time, pairs = trajectory.time, trajectory.pairs
        per_sample = self.per_sample.values
        wt, worst, wk = self.closest.index, float(self.closest.value), self.closest.detail
        wp = pairs[wk]
        signal = make_signal(
            time,
            per_sample,
            label="closest distance between robot parts (self pairs)",
            unit="m",
            warning=params.d_max_m,
            error=params.d_min_m,
            worse="below",
        )
        details = {"closest_pair": wp.name, "closest_distance_m": worst}
        verdict = partial(
            threshold_verdict, self.name, trajectory, worst=wt, value=worst, unit="m", signal=signal, details=details
        )
        if worst <= 0:
            where = f"the {wp.a} and the {wp.b} touch (overlap {fmt_length(-worst)}) at {time[wt]:.2f} s"
        else:
            where = f"the {wp.a} and the {wp.b} come within {fmt_length(worst)} of each other at {time[wt]:.2f} s"
        for flag, threshold in ((Flag.ERROR, params.d_min_m), (Flag.WARNING, params.d_max_m)):
            if worst < threshold:
                col_hit = np.flatnonzero(self.hits[threshold].hit)
                links = list(dict.fromkeys(n for k in col_hit for n in (pairs[k].a, pairs[k].b)))
                return verdict(
                    flag,
                    per_sample < threshold,
                    links=links,
                    threshold=threshold,
                    message=f"Pinch point: {where}, closer than {fmt_length(threshold)}.",
                    hint="To avoid pinch points, you can consider keeping the arm more open, for example by moving "
                    "through a higher or farther waypoint{during}.",
                )
        return verdict(
            Flag.OK,
            links=[wp.a, wp.b],
            threshold=params.d_max_m,
            message=f"No pinch points: robot parts stay at least {fmt_length(worst)} apart "
            f"(closest: the {wp.a} and the {wp.b}).",
        )


@hookimpl
def register_critics(register):
    register(PinchPointCritic())
