r"""Joint speed critic (RoboCritics paper, Algorithm 1).

Maths and units
---------------
For every frame ``l`` (link reference point: the frame origin ``p_{t,l}``, m,
in the base frame) and every sample ``t >= 1`` on the **physical** time axis
``tau`` (s)::

    v_{t,l} = || p_{t,l} - p_{t-1,l} || / (tau_t - tau_{t-1})        [m/s]

i.e. the paper's per-sample-pair linear speed, a proxy for joint speed that
the operator can see (it is what hurts when it hits). We also check the
angular joint speeds against the robot's own limits::

    w_{t,j} = | q_{t,j} - q_{t-1,j} | / (tau_t - tau_{t-1})           [rad/s]

Flags
-----
* ERROR if any ``v_{t,l} > max_speed_m_s`` (1.5 m/s: the UR e-series default
  safety configuration, normal mode, limits TCP and elbow speed to 1.5 m/s), or
  any ``w_{t,j} > (1 + joint_limit_tolerance) * limit_j`` (limits from the
  robot model, e.g. UR3e pi rad/s base/shoulder/elbow, 2 pi rad/s wrists; the
  1 % tolerance absorbs finite-difference error);
* WARNING if any ``v_{t,l} > warn_speed_m_s`` (1 m/s: the "recommended value"
  of the paper's joint-speed feedback);
* OK otherwise.

Speeds are assigned to the sample they arrive at (``t``), so the evidence's
samples, program lines and skills are those of the motion that reached the
speed. Because speeds are displacement over elapsed time, the verdict does not
depend on the sampling rate (a motion sampled at 125 Hz or 500 Hz gives the
same speeds up to discretisation of its peaks).
"""

from __future__ import annotations

from functools import partial

import numpy as np
from pydantic import Field, model_validator

from ..chunked import AnyOver, Extreme, Series, judge_in_chunks
from ..hookspecs import hookimpl
from ..._arrays import squared_norms
from ..derived import frame_kinds, moving_frames, position_planes
from .. import CriticParams, Flag, ParamNames, Verdict, fmt_value, make_signal, threshold_verdict

__all__ = ["JointSpeedCritic", "register_critics", "link_speeds"]

HINT = (
    "To minimize joint speed, you can consider reducing the speed of the robot{during}. "
    "This potentially increases the cycle time of the program."
)


class Params(CriticParams):
    warn_speed_m_s: float = Field(
        1.0,
        gt=0,
        description="recommended maximum linear speed of any link reference point, m/s "
        "(source: RoboCritics paper, joint-speed feedback 'recommended value of 1 m/s')",
    )
    max_speed_m_s: float = Field(
        1.5,
        gt=0,
        description="maximum allowed linear speed of any link reference point, m/s "
        "(source: UR e-series default safety configuration, normal mode TCP and elbow speed limit 1.5 m/s)",
    )
    joint_limit_tolerance: float = Field(
        0.01,
        ge=0,
        le=1,
        description="fraction by which an angular joint speed may exceed the robot's joint velocity limit "
        "before it is an error, to absorb finite-difference error (0.01 = 1 %)",
    )
    frames: ParamNames = Field(
        (), description="names of the frames whose origins are checked; empty = every frame of the trajectory"
    )

    @model_validator(mode="after")
    def _order(self) -> "Params":
        if self.warn_speed_m_s > self.max_speed_m_s:
            raise ValueError(
                f"warn_speed_m_s ({self.warn_speed_m_s}) must not exceed max_speed_m_s ({self.max_speed_m_s})"
            )
        return self


def link_speeds(positions: np.ndarray, time: np.ndarray) -> np.ndarray:
    """``(T-1, L)`` linear speeds, m/s, of ``positions (T, L, 3)`` m over ``time (T,)`` s.

    Row ``i`` is the speed reached at sample ``i + 1``: ``|p_{i+1} - p_i| / (tau_{i+1} - tau_i)``.
    """
    p = np.ascontiguousarray(positions)  # contiguous: faster to difference than a strided view (no copy if already)
    step = p[1:] - p[:-1]  # (T-1, L, 3) m
    speed = squared_norms(step)
    np.sqrt(speed, out=speed)
    speed /= np.diff(time)[:, None]
    return speed


def squared_steps(Y: np.ndarray, rows: slice) -> np.ndarray:
    """``(L, n)`` squared lengths, m^2, of the steps ``p_{i+1} - p_i`` of the positions ``Y (3, L, T)``
    (coordinate planes, :func:`robocritics.critic.derived.position_planes`) for the intervals ``i`` of ``rows``,
    as :func:`link_speeds` squares them (``x^2 + z^2 + y^2``, :func:`robocritics._arrays.squared_norms`' order)."""
    lo, hi = rows.start, rows.stop
    d = [Y[c, :, lo + 1 : hi + 1] - Y[c, :, lo:hi] for c in (0, 2, 1)]
    out = np.multiply(d[0], d[0], out=d[0])
    for dc in d[1:]:
        dc *= dc
        out += dc
    return out


def _joint_speeds(q: np.ndarray, time: np.ndarray, limits: np.ndarray, tolerance: float):
    """Joint speeds ``w (n, T-1)`` rad/s (joint by joint: each joint's series contiguous, where the ``(T-1, n)``
    layout's short rows cost numpy an overhead per row), the (interval, joint) of the highest fraction of its
    limit, that fraction, where a joint is over its limit by more than ``tolerance`` ``(n, T-1)``, and which
    intervals have one ``(T-1,)``. The (interval, joint) is ``np.argmax`` of the ``(T-1, n)`` fractions: the
    earliest interval of the highest (or first NaN), then the lowest joint."""
    qT = np.ascontiguousarray(q.T)  # (n, T)
    w = np.abs(qT[:, 1:] - qT[:, :-1])
    w /= np.diff(time)
    n = w.shape[0]
    if not n or not w.shape[1]:
        return w, (0, 0), 0.0, np.zeros(w.shape, dtype=bool), np.zeros(w.shape[1], dtype=bool)
    ratio = w / limits[:, None]  # (n, T-1)
    first = ratio.argmax(axis=1)  # each joint's earliest interval of its highest fraction (or of its first NaN)
    best = ratio[np.arange(n), first]
    nan = np.isnan(best)
    candidates = np.flatnonzero(nan if nan.any() else best == best.max())
    jj = int(candidates[np.argmin(first[candidates])])  # the earliest interval; argmin: the lowest joint of a tie
    ji = int(first[jj])
    over_joint = ratio > 1.0 + tolerance  # (n, T-1)
    return w, (ji, jj), float(ratio[jj, ji]), over_joint, over_joint.any(axis=0)


def _sample_values(per_interval: np.ndarray, first=0.0) -> np.ndarray:
    """Per-sample values ``(T,)`` from per-interval ones ``(T-1,)``: interval i ends at sample i + 1; sample 0 is
    ``first``."""
    out = np.empty(len(per_interval) + 1, dtype=per_interval.dtype)
    out[0] = first
    out[1:] = per_interval
    return out


class JointSpeedCritic:
    name = "joint_speed"
    description = "Linear speed of every link (paper Algorithm 1) and angular joint speed against the robot's limits."
    Params = Params

    def check(self, execution, params: Params) -> Verdict:
        return judge_in_chunks(self, execution, params)

    def reduction(self, execution, params: Params) -> "_Speeds":
        return _Speeds(self.name, execution.trajectory, params)


class _Speeds:
    """The joint-speed judgement, chunk by chunk: the fastest link per sample (from the chunk's frames and the
    sample before it), where it is fastest (and that sample's link speeds), which links pass either threshold.
    The angular joint speeds come from ``q``, which every trajectory stores."""

    def __init__(self, name: str, trajectory, params: Params):
        self.name, self.trajectory, self.params = name, trajectory, params
        if params.frames:
            self.sel = [trajectory.frame_index(n) for n in params.frames]
            self.names = tuple(trajectory.frame_names[i] for i in self.sel)
        else:
            self.sel, self.names = None, trajectory.frame_names
        T = len(trajectory)
        self.vmax = Series(max(T - 1, 0))  # (T-1,): interval i ends at sample i + 1
        self.fastest = Extreme("max")
        self.over_max, self.over_warn = AnyOver(len(self.names)), AnyOver(len(self.names))

    def add(self, chunk, execution) -> None:
        if len(self.trajectory) < 2 or not self.names:
            return
        window = chunk.trajectory
        Y = position_planes(execution)  # (3, L, n) m
        kinds = moving_frames(execution) if self.sel is None else None
        if self.sel is not None:
            Y = Y[:, self.sel]
            kinds = frame_kinds(Y)
        # the intervals ending at the chunk's own samples (the first sample of the run ends none)
        first = max(chunk.start, 1)
        rows = slice(first - chunk.lo - 1, chunk.stop - chunk.lo - 1)
        # (L, n) squared steps, m^2: a still frame's are 0 and a copy's its twin's (derived.frame_kinds)
        squared = np.empty((Y.shape[1], rows.stop - rows.start))
        for a, b in kinds.runs:
            squared[a:b] = squared_steps(Y[:, a:b], rows)
        squared[kinds.still] = 0.0
        squared[kinds.copies] = squared[kinds.twins]
        dt = np.diff(window.time)[rows]
        # the fastest link per sample: sqrt and division by dt > 0 keep the order of the squared steps, so
        # sqrt(max |step|^2) / dt is max(|step| / dt) bit for bit, without a speed per link
        vmax = np.sqrt(squared.max(axis=0)) / dt

        def speeds(r):  # link_speeds of rows r, as it computes them: sqrt, then / dt
            v = np.sqrt(squared[:, r].T)
            v /= dt[r] if np.ndim(r) == 0 else dt[r][:, None]
            return v

        self.vmax.put(first - 1, vmax)
        self.fastest.offer(first - 1, vmax, speeds)
        for hits, threshold in ((self.over_max, self.params.max_speed_m_s), (self.over_warn, self.params.warn_speed_m_s)):
            over = np.flatnonzero(vmax > threshold)
            if over.size:
                hits.add(speeds(over) > threshold)

    def verdict(self) -> Verdict:
        params, trajectory, names = self.params, self.trajectory, self.names
        T = len(trajectory)
        time = trajectory.time
        limits = np.asarray(trajectory.limits.velocity_rad_s, dtype=float)
        if T < 2 or len(names) == 0:
            return threshold_verdict(
                self.name,
                trajectory,
                Flag.OK,
                worst=0,
                message="Nothing to check: the trajectory has a single sample or no frames.",
                value=0.0,
                threshold=params.warn_speed_m_s,
                unit="m/s",
            )
        vmax = self.vmax.values  # (T-1,) fastest link per sample
        wi = self.fastest.index
        wl = int(np.argmax(self.fastest.detail))
        worst_v = float(self.fastest.detail[wl])
        w, (ji, jj), worst_ratio, over_joint, over_joint_rows = _joint_speeds(
            trajectory.q, time, limits, params.joint_limit_tolerance
        )

        over_max = vmax > params.max_speed_m_s
        over_warn = vmax > params.warn_speed_m_s
        err_lin, err_joint, warn = bool(over_max.any()), bool(over_joint_rows.any()), bool(over_warn.any())

        signal = make_signal(time, _sample_values(vmax), label="fastest link speed", unit="m/s",
                             warning=params.warn_speed_m_s, error=params.max_speed_m_s)  # fmt: skip
        details = {
            "max_link_speed_m_s": worst_v,
            "fastest_link": names[wl],
            "max_joint_speed_fraction_of_limit": worst_ratio,
            "fastest_joint": trajectory.limits.joint_names[jj] if w.shape[0] else "",
        }

        verdict = partial(threshold_verdict, self.name, trajectory, unit="m/s", signal=signal, details=details)

        if err_lin or err_joint:
            rows = over_max | over_joint_rows
            links = [names[i] for i in np.flatnonzero(self.over_max.hit)] if err_lin else []
            joints_over = []
            if err_joint:
                jover = over_joint.any(axis=1)
                joints_over = [trajectory.limits.joint_names[i] for i in np.flatnonzero(jover)]
            details["joints_over_limit"] = joints_over
            sentences = []
            if err_lin:
                sentences.append(
                    f"Joint speed is higher than the robot's maximum allowed speed of {fmt_value(params.max_speed_m_s)} m/s "
                    f"({worst_v:.2f} m/s at the {names[wl]} at {time[wi + 1]:.2f} s)."
                )
            if err_joint:
                sentences.append(
                    f"The {trajectory.limits.joint_names[jj]} turns at {w[jj, ji]:.2f} rad/s, above its limit of "
                    f"{limits[jj]:.2f} rad/s (at {time[ji + 1]:.2f} s)."
                )
            if err_lin:
                value, threshold, unit = worst_v, params.max_speed_m_s, "m/s"
            else:
                value, threshold, unit = float(w[jj, ji]), float(limits[jj]), "rad/s"
            return verdict(
                Flag.ERROR,
                _sample_values(rows, False),
                worst=(wi if err_lin else ji) + 1,
                links=links,
                value=value,
                threshold=threshold,
                unit=unit,
                message=" ".join(sentences),
                hint=HINT,
            )
        if warn:
            return verdict(
                Flag.WARNING,
                _sample_values(over_warn, False),
                worst=wi + 1,
                links=[names[i] for i in np.flatnonzero(self.over_warn.hit)],
                value=worst_v,
                threshold=params.warn_speed_m_s,
                message=f"Joint speed is higher than the recommended value of {fmt_value(params.warn_speed_m_s)} m/s "
                f"({worst_v:.2f} m/s at the {names[wl]} at {time[wi + 1]:.2f} s).",
                hint=HINT,
            )
        return verdict(
            Flag.OK,
            worst=wi + 1,
            links=[names[wl]],
            value=worst_v,
            threshold=params.warn_speed_m_s,
            message=f"Joint speed stays below the recommended value of {fmt_value(params.warn_speed_m_s)} m/s "
            f"(at most {worst_v:.2f} m/s, at the {names[wl]}).",
        )


@hookimpl
def register_critics(register):
    register(JointSpeedCritic())
