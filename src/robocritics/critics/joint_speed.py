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

from .. import hookimpl
from .._arrays import row_any, row_max, squared_norms
from ..critic import CriticParams, Flag, ParamNames, Verdict, fmt_value, make_signal, threshold_verdict

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


class JointSpeedCritic:
    name = "joint_speed"
    description = "Linear speed of every link (paper Algorithm 1) and angular joint speed against the robot's limits."
    Params = Params

    def check(self, trajectory, scene, params: Params) -> Verdict:
        T = len(trajectory)
        names = trajectory.frame_names
        if params.frames:
            sel = [trajectory.frame_index(n) for n in params.frames]
            names = tuple(names[i] for i in sel)
            positions = trajectory.positions[:, sel]
        else:
            positions = trajectory.positions  # (T, L, 3) m, shared with the other critics
        time = trajectory.time
        limits = np.asarray(trajectory.limits.velocity_rad_s, dtype=float)
        if T < 2 or positions.shape[1] == 0:
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

        # --- measure: all samples at once --------------------------------------
        v = link_speeds(positions, time)  # (T-1, L), speed reached at sample t = i + 1
        vmax = row_max(v)  # (T-1,) fastest link per sample
        wi = int(np.argmax(vmax))
        wl = int(np.argmax(v[wi]))
        worst_v = float(v[wi, wl])
        w = np.abs(np.diff(trajectory.q, axis=0)) / np.diff(time)[:, None]  # (T-1, n) rad/s
        if w.shape[1]:
            ratio = w / limits  # (T-1, n)
            jflat = int(np.argmax(ratio))
            ji, jj = divmod(jflat, ratio.shape[1])
            worst_ratio = float(ratio[ji, jj])
            over_joint = ratio > 1.0 + params.joint_limit_tolerance  # (T-1, n)
            over_joint_rows = row_any(over_joint)
        else:
            ji = jj = 0
            worst_ratio = 0.0
            over_joint_rows = np.zeros(T - 1, dtype=bool)

        over_max = vmax > params.max_speed_m_s
        over_warn = vmax > params.warn_speed_m_s
        err_lin, err_joint, warn = bool(over_max.any()), bool(over_joint_rows.any()), bool(over_warn.any())

        signal_values = np.empty(T)
        signal_values[0] = 0.0
        signal_values[1:] = vmax
        signal = make_signal(
            time,
            signal_values,
            label="fastest link speed",
            unit="m/s",
            warning=params.warn_speed_m_s,
            error=params.max_speed_m_s,
        )
        details = {
            "max_link_speed_m_s": worst_v,
            "fastest_link": names[wl],
            "max_joint_speed_fraction_of_limit": worst_ratio,
            "fastest_joint": trajectory.limits.joint_names[jj] if w.shape[1] else "",
        }

        verdict = partial(threshold_verdict, self.name, trajectory, unit="m/s", signal=signal, details=details)

        def sample_mask(rows: np.ndarray) -> np.ndarray:
            mask = np.zeros(T, dtype=bool)
            mask[1:] = rows
            return mask

        def links_over(threshold: float) -> list[str]:
            over = (v > threshold).any(axis=0)
            return [names[i] for i in np.flatnonzero(over)]

        if err_lin or err_joint:
            rows = over_max | over_joint_rows
            links = links_over(params.max_speed_m_s) if err_lin else []
            joints_over = []
            if err_joint:
                jover = over_joint.any(axis=0)
                joints_over = [trajectory.limits.joint_names[i] for i in np.flatnonzero(jover)]
            details["joints_over_limit"] = joints_over
            sentences = []
            if err_lin:
                sentences.append(
                    f"Joint speed is higher than the robot's maximum allowed speed of {fmt_value(params.max_speed_m_s)} m/s "
                    f"({worst_v:.2f} m/s at the {names[wl]} at {time[wi + 1]:.2f} s)."
                )
            if err_joint:
                limit = limits[jj]
                sentences.append(
                    f"The {trajectory.limits.joint_names[jj]} turns at {w[ji, jj]:.2f} rad/s, above its limit of "
                    f"{limit:.2f} rad/s (at {time[ji + 1]:.2f} s)."
                )
            if err_lin:
                value, threshold, unit = worst_v, params.max_speed_m_s, "m/s"
            else:
                value, threshold, unit = float(w[ji, jj]), float(limits[jj]), "rad/s"
            return verdict(
                Flag.ERROR,
                sample_mask(rows),
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
                sample_mask(over_warn),
                worst=wi + 1,
                links=links_over(params.warn_speed_m_s),
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
