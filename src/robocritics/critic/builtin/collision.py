r"""Collision critic (RoboCritics paper §3.1.2; CoFrame).

Maths and units
---------------
Reads the trajectory's **environment** proximity pairs: ``d_{t,k}`` (m) is
the signed distance between robot part / carried object ``a_k`` and scene
entity ``b_k`` at sample ``t`` (``<= 0``: touching or penetrating). Some
contacts are the task itself and are excluded, per sample:

* pairs whose ``a`` side is the gripper (``group_a == "gripper"``) or the
  carried object (``"attached"``) and whose ``b_entity`` is listed in
  ``steps[step[t]].contacts`` (the grasp target during its grasp, the surface
  or container an object is set down on or into);
* the gripper (or the carried object) against the object attached at ``t``
  (``attached[t]``).

An intended contact is *touching*, never a penetration: it is excluded only
while ``d_{t,k} > -contact_tolerance_m`` (3 mm). Deeper, it counts like any
other pair, so a carried object pushed into what it is set down on (or into
an object that merely lies where the move ends) is an Error wherever the
move ends.

A carried-object pair (``group_a == "attached"``, ``a`` = the object's id)
only counts while that object is the one held (``attached[t] == a``): before
the grasp and after the release the object rests in the scene, and its contact
with what it rests on is not the robot's.

Arm links against anything always count. With ``D_t = min_k d_{t,k}`` over the
counted pairs:

* ERROR if ``min_t D_t <= penetration_m`` (0 m: touching or penetration);
* WARNING if ``min_t D_t < d_warn_m`` (0.05 m, CoFrame's default safety margin);
* OK otherwise.

The message names the robot part and the object, the time and the program
line; the hint proposes ``avoid_collision(<object>)`` from the paper's skill API.
"""

from __future__ import annotations

from functools import partial

import numpy as np
from pydantic import Field, model_validator

from ..._arrays import run_starts
from ..chunked import AnyOver, Extreme, Series, judge_in_chunks
from ..derived import columns_as_rows
from ..hookspecs import hookimpl  # not `from .. import`: the root imports the repairs, which import this module
from .. import CriticParams, Flag, ParamNames, Verdict, fmt_length, fmt_value, make_signal, threshold_verdict

__all__ = ["CollisionCritic", "register_critics", "Counted", "counted_distances"]


class Params(CriticParams):
    d_warn_m: float = Field(
        0.05, gt=0, description="warning when a counted pair comes closer than this, m (source: CoFrame default, 5 cm)"
    )
    penetration_m: float = Field(
        0.0, le=0, description="error when a counted pair's signed distance is at or below this, m (0 = any contact)"
    )
    ignore_pairs: ParamNames = Field((), description="names of proximity pairs never to count (e.g. a mount plate)")
    contact_tolerance_m: float = Field(
        0.003,
        ge=0,
        description="an intended contact (grasp, set-down, stacking) is excused only while it overlaps by less than "
        "this, m; deeper it is a collision (source: this project: the modelled spheres, cylinders and finger "
        "boxes only approximate compliant objects and finger pads; the careful examples touch within 1e-15 m)",
    )

    @model_validator(mode="after")
    def _order(self) -> "Params":
        if self.penetration_m >= self.d_warn_m:
            raise ValueError(f"penetration_m ({self.penetration_m}) must be below d_warn_m ({self.d_warn_m})")
        return self


def _run_ids(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Run-length code a 1-D array: (run id per element, value of each run). No per-sample Python."""
    starts = run_starts(values)
    ids = np.zeros(len(values), dtype=np.intp)
    ids[starts[1:]] = 1
    return np.cumsum(ids), values[starts]


class Counted:
    """Which proximity pairs count for the collision critic, per sample.

    ``columns (K,)`` selects the environment pairs (minus ignored ones);
    ``gcols`` are those whose a-side is the gripper or a carried object, and
    :meth:`excused` says, at given samples, which of them do not count there:
    intended contacts while they overlap by less than ``contact_tolerance_m``
    (m; deeper, they count), and carried-object pairs of an object that is not
    held at that sample; ``intended`` is None when that never happens. Built from
    per-step and per-attachment tables: the (step, held object) of a sample changes
    a few times per program, so :meth:`closest`'s gripper distances are masked
    segment by segment of constant (step, held object), with no loop over samples
    and no ``(T, Kg)`` mask.
    """

    def __init__(self, trajectory, ignore_pairs=(), contact_tolerance_m: float = Params().contact_tolerance_m):
        pairs = trajectory.pairs
        self.columns = np.array([p.kind == "environment" and p.name not in ignore_pairs for p in pairs], dtype=bool)
        self.gcols = np.flatnonzero(
            self.columns & np.array([p.group_a in ("gripper", "attached") for p in pairs], dtype=bool)
        )
        self.intended: bool | None = None
        self._proximity = trajectory.proximity
        # the counted pairs' distances (Ke, T), gathered in one pass over the (T, K) proximity (a gather per
        # group of columns reads every row again): the gripper pairs' rows get +inf where they do not count
        self._counted = columns_as_rows(self._proximity, np.flatnonzero(self.columns))
        if self.gcols.size == 0:
            return
        entities = [pairs[k].b_entity for k in self.gcols]
        carriers = [pairs[k].a if pairs[k].group_a == "attached" else None for k in self.gcols]
        # contacts allowed by each program step: an (S, Kg) table; a step names a few contacts, so mark the
        # columns of each named entity (not a test of every entity against every step's contacts)
        table = None
        if trajectory.steps:
            columns_of: dict[str, list[int]] = {}
            for j, e in enumerate(entities):
                if e != "":
                    columns_of.setdefault(e, []).append(j)
            table = np.zeros((len(trajectory.steps), len(entities)), dtype=bool)
            for i, s in enumerate(trajectory.steps):
                for e in s.contacts:
                    table[i, columns_of.get(e, [])] = True
            if not table.any():
                table = None
        # the object held at t: run-length code `attached` (it changes a few times per program), then per
        # run: the gripper against the held object is an intended contact, and a carried-object pair only
        # exists while that object is the one held
        run, held = _run_ids(trajectory.attached)
        holding = np.array([[h != "" and e == h for e in entities] for h in held.tolist()], dtype=bool)
        absent = np.array([[c is not None and c != h for c in carriers] for h in held.tolist()], dtype=bool)
        # per sample, the row of its (step, run) in one small (S R, Kg) table of intended contacts; the key
        # changes a few times per program, so the (Kg, T) gripper distances are masked segment by segment
        if table is not None:
            contact = (table[:, None, :] | holding[None, :, :]).reshape(-1, len(entities))
            key = trajectory.step * len(held) + run
        else:
            contact, key = holding, run
        self._contact, self._absent, self._key, self._run = contact, absent, key, run
        self._tolerance = contact_tolerance_m
        if not (contact.any() or absent.any()):
            return
        self.intended = True
        gripper = np.searchsorted(np.flatnonzero(self.columns), self.gcols)  # their rows of the counted distances
        counted = self._counted
        starts = run_starts(key)
        stops = np.append(starts[1:], len(key))
        keys = key[starts]
        active = np.flatnonzero(contact.any(axis=1)[keys] | absent.any(axis=1)[run[starts]])
        for i in active.tolist():
            a, b = int(starts[i]), int(stops[i])
            gone = gripper[absent[run[a]]]
            if gone.size:  # a carried object's pairs while it is not the one held
                counted[gone, a:b] = np.inf
            touched = gripper[contact[keys[i]]]
            if touched.size:  # an intended contact is touching, not a penetration: deeper it counts
                part = counted[touched, a:b]
                np.putmask(part, part > -contact_tolerance_m, np.inf)
                counted[touched, a:b] = part

    def excused(self, rows) -> np.ndarray:
        """``(len(rows), Kg)`` (or ``(Kg,)`` for one row): which gripper pairs (``gcols``) do not count at ``rows``
        (all False when every one counts)."""
        rows = np.asarray(rows)
        if self.intended is None:
            return np.zeros(rows.shape + self.gcols.shape, dtype=bool)
        depth = self._proximity[rows][..., self.gcols]
        return (self._contact[self._key[rows]] & (depth > -self._tolerance)) | self._absent[self._run[rows]]

    def row_mask(self, rows) -> np.ndarray:
        """``(len(rows), K)`` (or ``(K,)`` for one row) mask of the pairs that count at ``rows``."""
        if self.intended is None:
            return self.columns
        rows = np.asarray(rows)
        mask = np.empty(rows.shape + self.columns.shape, dtype=bool)
        mask[...] = self.columns
        mask[..., self.gcols] = ~self.excused(rows)
        return mask

    def closest(self) -> np.ndarray:
        """``(T,)`` closest counted distance per sample of the trajectory, m (+inf where nothing counts).

        The counted pairs' rows, gathered (and masked where the gripper pairs do not count) when this was built,
        reduced by elementwise minima of whole rows: a masked ``where=`` reduction over ``(T, K)`` is about 4x
        slower.
        """
        if not len(self._counted):
            return np.full(len(self._proximity), np.inf)
        return self._counted.min(axis=0)

    def nearest(self, rows: np.ndarray) -> np.ndarray:
        """``(K,)`` each pair's closest counted distance over the samples ``rows`` (non-empty), m, NaN left out;
        +inf for the pairs that never count. ``np.fmin.reduce`` of the proximity masked by :meth:`row_mask` there,
        from the counted pairs' gathered rows (masked where they do not count when this was built): no
        ``(len(rows), K)`` gather of the proximity and its mask."""
        out = np.full(len(self.columns), np.inf)
        if len(self._counted):
            out[self.columns] = np.fmin.reduce(self._counted[:, rows], axis=1)
        return out


def counted_distances(trajectory, ignore_pairs=(), contact_tolerance_m: float = Params().contact_tolerance_m) -> np.ndarray:
    """``(T, K)`` proximity, m, with every pair that does not count (self pairs, ignored pairs,
    intended contacts shallower than ``contact_tolerance_m``) set to +inf. For tests and plots; the critic
    avoids this copy."""
    counted = Counted(trajectory, ignore_pairs, contact_tolerance_m)
    return np.where(counted.row_mask(np.arange(len(trajectory))), trajectory.proximity, np.inf)


def _part(pair) -> str:
    return f"the carried {pair.a}" if pair.group_a == "attached" else f"the {pair.a}"


def _thing(pair) -> str:
    return pair.b_entity or pair.b


class CollisionCritic:
    name = "collision"
    description = "Distance between the robot (and what it carries) and the scene, excluding intended contacts."
    Params = Params

    def check(self, execution, params: Params) -> Verdict:
        return judge_in_chunks(self, execution, params)

    def reduction(self, execution, params: Params) -> "_Closest":
        return _Closest(self.name, execution.trajectory, params)


class _Closest:
    """The collision judgement, chunk by chunk: ``D_t`` per sample, where it is least (and its pair), and which
    pairs pass either threshold (:class:`Counted` is per sample, so a chunk's is the whole run's rows)."""

    def __init__(self, name: str, trajectory, params: Params):
        self.name, self.trajectory, self.params = name, trajectory, params
        pairs = trajectory.pairs
        self.any_counted = any(p.kind == "environment" and p.name not in params.ignore_pairs for p in pairs)
        self.per_sample = Series(len(trajectory))
        self.closest = Extreme("min")
        self.touching = AnyOver(len(pairs))  # counted pairs at or below penetration_m
        self.near = AnyOver(len(pairs))  # counted pairs closer than d_warn_m

    def add(self, chunk, execution) -> None:
        if not self.any_counted:
            return
        params = self.params
        window = chunk.trajectory
        counted = Counted(window, params.ignore_pairs, params.contact_tolerance_m)
        P = window.proximity
        own = np.arange(chunk.own.start, chunk.own.stop)
        per_sample = counted.closest()[chunk.own]  # D_t, without copying the (n, K) proximity
        self.per_sample.put(chunk.start, per_sample)
        self.closest.offer(
            chunk.start, per_sample, lambda i: int(np.argmin(np.where(counted.row_mask(own[i]), P[own[i]], np.inf)))
        )
        # which pairs come within either threshold: each pair's closest counted distance over the samples closer
        # than d_warn_m (penetration_m is lower, so those hold every sample at or below it; NaN left out)
        rows = own[per_sample < params.d_warn_m]
        if rows.size:
            nearest = counted.nearest(rows)[None, :]  # (1, K) m
            self.touching.add(nearest <= params.penetration_m)
            self.near.add(nearest < params.d_warn_m)

    def verdict(self) -> Verdict:
        params, trajectory = self.params, self.trajectory
        if not self.any_counted:
            return threshold_verdict(
                self.name,
                None,
                Flag.OK,
                message="The trajectory has no robot-environment proximity pairs to check.",
                threshold=params.d_warn_m,
                unit="m",
            )
        time, pairs = trajectory.time, trajectory.pairs
        per_sample = self.per_sample.values
        wt, worst = self.closest.index, float(self.closest.value)
        signal = make_signal(
            time,
            np.where(np.isfinite(per_sample), per_sample, np.nan),
            label="closest robot-environment distance (intended contacts excluded)",
            unit="m",
            warning=params.d_warn_m,
            error=params.penetration_m,
            worse="below",
        )
        if not np.isfinite(worst):
            return threshold_verdict(
                self.name,
                None,
                Flag.OK,
                message="Every robot-environment contact in this trajectory is intended (grasps and set-downs).",
                threshold=params.d_warn_m,
                unit="m",
                signal=signal,
            )
        wp = pairs[self.closest.detail]
        details = {"closest_pair": wp.name, "closest_distance_m": worst}
        verdict = partial(
            threshold_verdict, self.name, trajectory, worst=wt, value=worst, unit="m", signal=signal, details=details
        )
        hint = (
            f"you can consider using avoid_collision({_thing(wp)}) or moving through a higher or farther waypoint"
            "{during}."
        )

        def involved(hits: AnyOver) -> tuple[list[str], list[str]]:
            col_hit = np.flatnonzero(hits.hit)
            return list(dict.fromkeys(pairs[k].a for k in col_hit)), list(dict.fromkeys(_thing(pairs[k]) for k in col_hit))

        if worst <= params.penetration_m:
            links, objects = involved(self.touching)
            depth = -worst
            what = "penetrates" if depth >= 0.0005 else "touches"
            extra = f" by {fmt_length(depth)}" if depth >= 0.0005 else ""
            others = [o for o in objects if o != _thing(wp)]
            also = f" It also hits {', '.join(others)}." if others else ""
            return verdict(
                Flag.ERROR,
                per_sample <= params.penetration_m,
                links=links,
                objects=objects,
                threshold=params.penetration_m,
                message=f"Collision: {_part(wp)} {what} the {_thing(wp)}{extra} at {time[wt]:.2f} s "
                f"(sample {wt}).{also}",
                hint=f"To avoid the collision, {hint}",
            )
        if worst < params.d_warn_m:
            links, objects = involved(self.near)
            return verdict(
                Flag.WARNING,
                per_sample < params.d_warn_m,
                links=links,
                objects=objects,
                threshold=params.d_warn_m,
                message=f"{_part(wp).capitalize()} comes within {fmt_length(worst)} of the {_thing(wp)} at {time[wt]:.2f} s, "
                f"closer than the {fmt_length(params.d_warn_m)} safety margin.",
                hint=f"To keep a safe distance, {hint}",
            )
        return verdict(
            Flag.OK,
            links=[wp.a],
            objects=[_thing(wp)],
            threshold=params.d_warn_m,
            message=f"The robot keeps at least {fmt_length(worst)} from the scene outside intended contacts "
            f"(margin {fmt_value(params.d_warn_m)} m).",
        )


@hookimpl
def register_critics(register):
    register(CollisionCritic())
