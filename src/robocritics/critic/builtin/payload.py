r"""Payload: what the arm carries against its rating, and the joint torques the motion needs against their limits.

Two checks, at every sample ``t``:

1. **Rated payload.** ``m(t) = m_tool + m_obj(t)``: the tool's mass (the robot model's inertias of what is fixed
   to the last joint: the bundled gripper weighs 1.0 kg) plus the held object's ``mass_kg`` attribute (kg).
   Its centre of gravity's offset from the tool flange ``r(t)`` (m) sets the allowed payload
   ``m_max(r) = m_rated`` for ``r <= r_full``, ``m_rated * r_full / r`` beyond (a constant wrist moment), with
   ``m_rated`` and ``r_full`` the arm's published figures (:attr:`robocritics.robot.arms.ArmSpec.rated_payload_kg`,
   ``payload_full_offset_m``: the UR3e 3 kg up to 0.15 m).
2. **Joint torques.** ``tau(t) = RNEA(q, q', q'')``: Pinocchio's recursive Newton-Euler inverse dynamics with
   the model's inertial parameters (the bundled UR3e: UR's published link masses) and the held object added
   to the last link as a point mass at its centre; ``q'`` and ``q''`` are finite differences on the physical
   time axis. Against the joint torque limits of the model (the URDF's ``effort``; UR3e 56/56/28/12/12/12 N m,
   :data:`robocritics.robot.arms.UR3E`).

Flags: ERROR when the payload exceeds the allowed payload or a torque exceeds its limit; WARNING when either
exceeds ``warn_fraction`` of its limit; OK otherwise. A held object without ``mass_kg`` counts as 0 kg and the
message says so. On demand: requested when any object of the scene states its ``mass_kg``.
"""

from __future__ import annotations

import numpy as np
from pydantic import Field

from ..chunked import judge_in_chunks
from ..hookspecs import hookimpl
from .. import CriticParams, Flag, Verdict, fmt_value, make_signal, threshold_verdict
from ...robot.arms import ARMS
from .cobot import carried_mass, object_mass, robot_masses

__all__ = ["PayloadCritic", "register_critics", "allowed_payload_kg", "joint_torques"]

NAME = "payload"
_FLANGE = "tool0"


class Params(CriticParams):
    warn_fraction: float = Field(
        0.9, gt=0, le=1.0, description="fraction of the allowed payload or of a joint torque limit above which it "
        "is a Warning (chosen: a 10 % margin for the objects' stated masses and the model's inertias)"
    )


def allowed_payload_kg(rated_kg: float, full_offset_m: float, offset_m: np.ndarray) -> np.ndarray:
    """The payload allowed at centre-of-gravity offsets ``offset_m`` from the flange, kg (see the docstring)."""
    offset_m = np.asarray(offset_m, dtype=float)
    with np.errstate(divide="ignore"):
        return np.where(offset_m <= full_offset_m, rated_kg, rated_kg * full_offset_m / offset_m)


class _Levers:
    """Centre of each held object in the frame ``frame`` (m), averaged over the samples it is held, read chunk by
    chunk (a long run's frames are made a chunk at a time): :meth:`add` every chunk, then :meth:`levers`."""

    def __init__(self, execution, frame: str):
        trajectory = execution.trajectory
        self.index = trajectory.frame_index(frame)
        poses_of = getattr(execution, "object_poses", {}) or {}
        self.local: dict[str, list[np.ndarray]] = {o: [] for o in poses_of if (trajectory.attached == o).any()}

    def add(self, chunk, window) -> None:
        own = chunk.own
        attached = chunk.trajectory.attached[own]
        for obj_id, parts in self.local.items():
            held = attached == obj_id
            if not held.any():
                continue
            f = chunk.trajectory.frames[own][held, self.index]  # (H, 4, 4)
            centre = np.asarray(window.object_poses[obj_id], dtype=float)[own][held, :3, 3]
            parts.append(np.einsum("hji,hj->hi", f[:, :3, :3], centre - f[:, :3, 3]))  # R^T (c - t)

    def levers(self) -> dict[str, np.ndarray]:
        return {o: np.concatenate(parts).mean(axis=0) for o, parts in self.local.items()}


def _held_levers(execution, frame: str) -> dict[str, np.ndarray]:
    """:class:`_Levers` of every chunk of ``execution``."""
    levers = _Levers(execution, frame)
    if levers.local:
        for chunk, window in execution.chunks():
            levers.add(chunk, window)
    return levers.levers()


def joint_torques(execution, levers: dict[str, np.ndarray] | None = None) -> np.ndarray:
    """``(T, n)`` joint torques (N m) of the motion by RNEA, with each held object's ``mass_kg`` on the last link
    (at ``levers``: its centre in the last link's frame, m; default measured on ``execution``)."""
    import pinocchio as pin  # here: a check that does not run this on-demand critic need not load Pinocchio

    trajectory, robot = execution.trajectory, execution.robot
    model = robot.model
    last = model.njoints - 1
    if levers is None:
        levers = _held_levers(execution, _link_of_joint(robot, last))
    q = np.asarray(trajectory.q, dtype=float)
    v = np.gradient(q, trajectory.time, axis=0) if len(q) > 1 else np.zeros_like(q)
    a = np.gradient(v, trajectory.time, axis=0) if len(q) > 1 else np.zeros_like(q)
    tau = np.empty_like(q)
    for held in [""] + sorted(levers):
        rows = np.flatnonzero(trajectory.attached == held)
        if not rows.size:
            continue
        m = pin.Model(model)  # a copy: the robot's model is shared and read-only
        mass = object_mass(execution, held) if held else None
        if mass:
            m.inertias[last] = m.inertias[last] + pin.Inertia.FromSphere(mass, 0.01).se3Action(
                pin.SE3(np.eye(3), levers[held])
            )
        data = m.createData()
        for i in rows.tolist():  # Pinocchio's RNEA is one configuration per call (C++: microseconds each)
            tau[i] = pin.rnea(m, data, q[i], v[i], a[i])
    return tau


def _link_of_joint(robot, joint: int) -> str:
    """The link (frame) the URDF attaches to joint ``joint``: the body frame whose parent frame is the joint."""
    import pinocchio as pin  # here: a check that does not run this on-demand critic need not load Pinocchio

    model = robot.model
    for f in model.frames:
        if f.type == pin.FrameType.BODY and f.parentJoint == joint and model.frames[f.parentFrame].name == model.names[joint]:
            return f.name
    raise ValueError(f"no link on joint {model.names[joint]!r}")


def _tool_cog(robot) -> tuple[np.ndarray, np.ndarray]:
    """``(lever, flange)``: the tool's centre of gravity and the flange's position in the last joint's frame, m."""
    import pinocchio as pin  # here: a check that does not run this on-demand critic need not load Pinocchio

    model = robot.model
    last = model.njoints - 1
    total, moment = 0.0, np.zeros(3)
    for f in model.frames:
        if f.parentJoint == last and f.type == pin.FrameType.FIXED_JOINT and f.inertia.mass > 0:
            total += f.inertia.mass
            moment += f.inertia.mass * (f.placement.act(f.inertia.lever))
    flange = model.frames[model.getFrameId(_FLANGE)].placement.translation if model.existFrame(_FLANGE) else np.zeros(3)
    return (moment / total if total else np.zeros(3)), np.asarray(flange, dtype=float)


def requested(execution) -> bool:
    """Whether any object of the run's scene states its mass (``attributes.mass_kg``)."""
    return any("mass_kg" in o.attributes for o in execution.scene.objects)


class PayloadCritic:
    name = NAME
    description = "Carried mass against the arm's rated payload curve, and RNEA joint torques against their limits."
    Params = Params

    def requested(self, execution) -> bool:
        return requested(execution)

    def check(self, execution, params: Params) -> Verdict:
        return judge_in_chunks(self, execution, params)

    def reduction(self, execution, params: Params) -> "_Payload":
        return _Payload(execution, params)


class _Payload:
    """The payload judgement: the held objects' levers read chunk by chunk, then the payload curve and the
    torques (RNEA of ``q``, which every trajectory stores) over the whole run."""

    def __init__(self, execution, params: Params):
        self.execution, self.params = execution, params
        robot = execution.robot
        self.levers = None if robot is None else _Levers(execution, _link_of_joint(robot, robot.model.njoints - 1))

    def add(self, chunk, execution) -> None:
        if self.levers is not None and self.levers.local:
            self.levers.add(chunk, execution)

    def verdict(self) -> Verdict:
        execution, params = self.execution, self.params
        trajectory, robot = execution.trajectory, execution.robot
        if robot is None:
            return Verdict(critic=NAME, flag=Flag.OK, message="no robot model: nothing to check (its inertias and "
                           "torque limits are needed)", hint="judge the motion with its robot")  # fmt: skip
        spec = ARMS.get(robot.name)
        carried, unknown = carried_mass(execution)
        _, tool_kg = robot_masses(robot)
        mass = tool_kg + carried  # (T,) kg
        tool_lever, flange = _tool_cog(robot)
        levers = self.levers.levers()
        cog = np.tile(tool_lever * tool_kg, (len(trajectory), 1))
        for obj_id, lever in levers.items():
            rows = trajectory.attached == obj_id
            cog[rows] += carried[rows, None] * lever
        cog /= np.maximum(mass, 1e-12)[:, None]
        offset = np.linalg.norm(cog - flange, axis=1)  # (T,) m from the flange
        if spec is not None and spec.rated_payload_kg:
            allowed = allowed_payload_kg(spec.rated_payload_kg, spec.payload_full_offset_m or np.inf, offset)
        else:
            allowed = np.full(len(trajectory), np.inf)
        load = mass / allowed  # (T,) fraction of the allowed payload
        tau = joint_torques(execution, levers)
        limits = np.asarray(robot.model.effortLimit, dtype=float)
        torque = np.abs(tau) / limits  # (T, n)
        worst_joint = torque.argmax(axis=1)
        per_sample = np.maximum(load, torque.max(axis=1))
        signal = make_signal(trajectory.time, per_sample, label="payload or joint torque / limit (worst)",
                             unit="fraction of limit", warning=params.warn_fraction, error=1.0)
        t = int(np.argmax(per_sample))
        j = int(worst_joint[t])
        names = robot.joint_names
        details = {"payload_kg": float(mass[t]), "allowed_payload_kg": float(allowed[t]), "cog_offset_m": float(offset[t]),
                   "tool_kg": tool_kg, "max_torque_fraction": float(torque.max()), "joint": names[j],
                   "torque_nm": float(tau[t, j]), "torque_limit_nm": float(limits[j]), "mass_unknown": unknown}
        held = str(trajectory.attached[t])
        what = f"{mass[t]:.2f} kg (tool {tool_kg:.2f} kg" + (f" + {held} {carried[t]:.2f} kg" if held else "") + ")"
        note = (f" The mass of {', '.join(unknown)} is not stated (attributes.mass_kg): counted as 0 kg."
                if unknown else "")
        if load[t] >= torque[t, j]:
            said = (f"The arm carries {what} with its centre of gravity {offset[t] * 100:.0f} cm from the flange; "
                    f"the allowed payload there is {allowed[t]:.2f} kg")
            value, threshold, unit = float(mass[t]), float(allowed[t]), "kg"
        else:
            said = (f"The {names[j]} needs {abs(tau[t, j]):.1f} N m at {trajectory.time[t]:.2f} s (carrying {what}); "
                    f"its limit is {limits[j]:.0f} N m")
            value, threshold, unit = float(abs(tau[t, j])), float(limits[j]), "N m"
        common = dict(worst=t, objects=[held] if held else [], value=value, threshold=threshold, unit=unit,
                      signal=signal, details=details)
        hint = "Carry less{during}: a lighter object, or move it slower (lib.reduce_speed) so the joints need less torque."
        if per_sample[t] > 1.0:
            return threshold_verdict(NAME, trajectory, Flag.ERROR, per_sample > 1.0, hint=hint,
                                     message=f"{said}: over the limit.{note}", **common)
        if per_sample[t] > params.warn_fraction:
            return threshold_verdict(NAME, trajectory, Flag.WARNING, per_sample > params.warn_fraction, hint=hint,
                                     message=f"{said}: above {fmt_value(100 * params.warn_fraction)} % of it.{note}",
                                     **common)
        return threshold_verdict(NAME, trajectory, Flag.OK, message=f"Within the arm's payload and joint torque "
                                 f"limits (at most {100 * per_sample[t]:.0f} %: {said}).{note}", **common)


@hookimpl
def register_critics(register):
    register(PayloadCritic())
