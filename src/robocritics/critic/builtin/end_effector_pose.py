r"""End-effector pose ("spearing") critic (RoboCritics paper §3.1.2; CoFrame).

Risk: the gripper moving fast in the direction its fingers point, like a spear.

Maths and units
---------------
With ``p_t`` the TCP position (m, base frame; the TCP sits at the fingertips)
and ``f_t`` the unit finger direction (the TCP frame's z axis, rotation column
2: straight down is ``(0, 0, -1)``), the TCP velocity is the derivative of
position over the **physical** time axis, by second-order central differences
on the (possibly uneven) sample times and one-sided differences at the ends
(``numpy.gradient``)::

    v_t = dp/dtau (t)                                   [m/s]
    s_t = max(0, v_t · f_t) = |v_t| max(0, cos angle(v_t, f_t))   [m/s]

``s_t``, the spearing speed, grows with speed and with the alignment between
motion and fingers; only motion *toward* where the fingers point counts
(moving back, along -f, or sideways scores 0). Because it is a velocity, not a
per-sample displacement, the same motion sampled at 125 Hz or 500 Hz gives the
same verdict.

* ERROR if ``max_t s_t > max_speed_m_s`` (0.5 m/s: edged or pointed tools at
  up to 0.5 m/s generally prevented open wounds in hand-surrogate tests,
  Kirschner et al. 2024);
* WARNING if ``max_t s_t > warn_speed_m_s`` (0.25 m/s: ISO 10218-1 reduced speed);
* OK otherwise.

A finger direction that is zero (the authors' prototype's defect) is refused
with a :class:`~robocritics.errors.CriticError` rather than judged.
"""

from __future__ import annotations

from functools import partial

import numpy as np
from pydantic import Field, model_validator

from ..derived import position_planes
from ..chunked import Extreme, Series, judge_in_chunks
from ..hookspecs import hookimpl
from .. import CriticParams, Flag, ParamName, Verdict, fmt_value, make_signal, threshold_verdict
from ...errors import CriticError

__all__ = ["EndEffectorPoseCritic", "register_critics", "spearing_speed"]


class Params(CriticParams):
    warn_speed_m_s: float = Field(
        0.25,
        gt=0,
        description="warning above this spearing speed, m/s (source: ISO 10218-1 reduced speed, 250 mm/s)",
    )
    max_speed_m_s: float = Field(
        0.5,
        gt=0,
        description="error above this spearing speed, m/s (source: Kirschner et al. 2024, edged/pointed tools "
        "at <= 0.5 m/s generally prevented open wounds)",
    )
    frame: ParamName | None = Field(
        None, description="frame at the fingertips whose z axis is the finger direction (default: the trajectory's TCP frame)"
    )

    @model_validator(mode="after")
    def _order(self) -> "Params":
        if self.warn_speed_m_s > self.max_speed_m_s:
            raise ValueError(
                f"warn_speed_m_s ({self.warn_speed_m_s}) must not exceed max_speed_m_s ({self.max_speed_m_s})"
            )
        return self


def spearing_speed(p: np.ndarray, f: np.ndarray, time: np.ndarray, first_sample: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(s (T,), v (3, T), f (3, T))``: spearing speed m/s, TCP velocity m/s, unit finger direction.

    ``p (3, T)`` m are the TCP positions and ``f (3, T)`` its finger directions (the z axes of its poses, any
    length: normalised in place); component rows keep every operation contiguous.
    ``first_sample``: the index of sample 0 in the run (for the error naming a sample).
    """
    norm = np.linalg.norm(f, axis=0)
    if np.any(norm < 1e-9):
        i = int(np.argmax(norm < 1e-9))
        raise CriticError(
            f"the finger direction (z axis of the TCP frame) is zero at sample {first_sample + i}; cannot judge spearing"
        )
    f /= norm
    v = np.gradient(p, time, axis=1) if len(time) > 1 else np.zeros_like(p)  # (3, T) m/s
    s = np.maximum(np.einsum("it,it->t", v, f), 0.0)
    return s, v, f


class EndEffectorPoseCritic:
    name = "end_effector_pose"
    description = "Spearing: speed of the gripper toward where its fingers point (speed x alignment)."
    Params = Params

    def check(self, execution, params: Params) -> Verdict:
        return judge_in_chunks(self, execution, params)

    def reduction(self, execution, params: Params) -> "_Spearing":
        return _Spearing(self.name, execution.trajectory, params)


class _Spearing:
    """The spearing judgement, chunk by chunk: the spearing speed per sample (central differences need the
    samples either side: the chunk's halo), where it is largest (and the TCP velocity there), the fastest TCP."""

    def __init__(self, name: str, trajectory, params: Params):
        self.name, self.trajectory, self.params = name, trajectory, params
        self.frame = params.frame or trajectory.tcp_frame
        self.index = trajectory.frame_index(self.frame)
        self.s = Series(len(trajectory))
        self.fastest = Extreme("max")
        self.tcp_speed = 0.0

    def add(self, chunk, execution) -> None:
        window = chunk.trajectory
        p = position_planes(execution)[:, self.index]  # (3, n) m, shared with the other critics
        f = np.array(window.frames[:, self.index, :3, 2].T, order="C")  # (3, n), a copy spearing_speed normalises
        s, v, _ = spearing_speed(p, f, window.time, chunk.lo)
        s, v = s[chunk.own], v[:, chunk.own]
        self.s.put(chunk.start, s)
        self.fastest.offer(chunk.start, s, lambda i: v[:, i].copy())
        self.tcp_speed = max(self.tcp_speed, float(np.linalg.norm(v, axis=0).max()))

    def verdict(self) -> Verdict:
        params, trajectory, frame = self.params, self.trajectory, self.frame
        time = trajectory.time
        s = self.s.values
        wt = self.fastest.index
        worst = float(self.fastest.value)
        speed = float(np.linalg.norm(self.fastest.detail))
        details = {
            "max_spearing_speed_m_s": worst,
            "tcp_speed_at_worst_m_s": speed,
            "alignment_at_worst": worst / speed if speed > 0 else 0.0,
            "max_tcp_speed_m_s": self.tcp_speed,
        }
        signal = make_signal(
            time,
            s,
            label="speed toward where the fingers point",
            unit="m/s",
            warning=params.warn_speed_m_s,
            error=params.max_speed_m_s,
        )
        angle = float(np.degrees(np.arccos(np.clip(worst / speed, -1, 1)))) if speed > 0 else 90.0
        how = f"{worst:.2f} m/s ({speed:.2f} m/s at {angle:.0f}° from the finger direction) at {time[wt]:.2f} s"
        verdict = partial(
            threshold_verdict, self.name, trajectory, worst=wt, value=worst, unit="m/s", signal=signal, details=details
        )
        levels = (
            (Flag.ERROR, params.max_speed_m_s, "the {} m/s limit for pointed tools"),
            (Flag.WARNING, params.warn_speed_m_s, "the recommended {} m/s"),
        )
        for flag, threshold, limit in levels:
            if worst > threshold:
                return verdict(
                    flag,
                    s > threshold,
                    links=[frame],
                    threshold=threshold,
                    message="The gripper moves in the direction its fingers point faster than "
                    f"{limit.format(fmt_value(threshold))}: {how}.",
                    hint="To reduce the risk of spearing, you can consider reducing the speed of the robot{during}, "
                    "or approaching so that the fingers do not point along the motion. "
                    "This potentially increases the cycle time of the program.",
                )
        return verdict(
            Flag.OK,
            links=[frame],
            threshold=params.warn_speed_m_s,
            message=f"The gripper never moves toward where its fingers point faster than "
            f"{fmt_value(params.warn_speed_m_s)} m/s (at most {worst:.2f} m/s).",
        )


@hookimpl
def register_critics(register):
    register(EndEffectorPoseCritic())
