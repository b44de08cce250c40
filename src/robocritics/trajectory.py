"""The motion-level trace critics read: the paper's s_t = {J_t, F_t, P_t, tau_t}, column-wise.

A :class:`Trajectory` of ``T`` samples of an ``n``-joint robot with ``L`` named
frames and ``K`` proximity pairs holds

* ``q`` ``(T, n)`` joint angles, rad (J_t);
* ``frames`` ``(T, L, 4, 4)`` link poses in the robot base frame, m (F_t);
  the frame named ``tcp`` sits at the fingertip centre, and its **z axis is
  the finger direction** (the way the fingers point);
* ``proximity`` ``(T, K)`` signed distances, m, of the named pairs in ``pairs``
  (P_t; <= 0 on penetration; a simulated trajectory's array is column-major, each pair's
  time series contiguous, as the critics read it). Self pairs are exact; an environment pair's value
  is exact when it is at most 0.10 m (:data:`robocritics.planning.trace.EXACT_WITHIN_M`)
  or at most the arm's closest environment distance at that sample, and otherwise
  a lower bound beyond both (far pairs are not measured exactly). So every
  threshold up to 0.10 m, and the closest distance over any set of environment
  pairs that includes the arm links' at each sample, are exact;
* ``time`` ``(T,)`` seconds on the physical time axis the robot executes (tau_t);
* ``gripper_opening_m`` ``(T,)`` distance between the fingers, m;
* ``attached`` ``(T,)`` id of the object held by the gripper at each sample ('' for none);
* ``step`` ``(T,)`` index into ``steps``: the program step (skill call, and so
  the source line) that produced each sample;
* ``limits``: the robot's joint limits, so critics need nothing else.

Built by :func:`robocritics.robot.model.Robot.trajectory` from joint samples; validated
on construction; :meth:`Trajectory.to_json` / :meth:`Trajectory.from_json` are lossless.

Long motion
-----------
A simulated motion of more than :data:`CHUNK_SAMPLES` samples is *compact*: it stores only ``q``, ``time``,
``gripper_opening_m``, ``attached`` and ``step`` (about 100 bytes a sample) and computes ``frames`` and
``proximity`` on demand, chunk by chunk (:meth:`Trajectory.chunks`), from its ``geometry`` (the robot and the
scene's distance kernel: :class:`robocritics.planning.trace.ChunkGeometry`). ``trajectory.frames`` and
``trajectory.proximity`` still work on a compact trajectory, but build the whole array (1.5 kB and some 100 bytes a
sample), as a stored one holds; critics that read :meth:`chunks` need memory for one chunk only.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from typing import Iterator, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from ._arrays import run_starts, unique_values
from .errors import TrajectoryError

__all__ = ["Pair", "Step", "RobotLimits", "State", "Trajectory", "Chunk", "CHUNK_SAMPLES", "CHUNK_ALIGN"]

#: Samples per chunk of a long motion (:meth:`Trajectory.chunks`): a simulated motion longer than this is stored
#: compactly. 16,384 samples are 33 s at 500 Hz, 131 s at 125 Hz (every bundled program is one chunk); building
#: one chunk's frames and proximity takes some 120 MB with 14 scene shapes.
CHUNK_SAMPLES = 16_384
#: Chunks start at multiples of this many samples: the space-usage critic's hull thins blocks of 64 samples and the
#: proximity kernel bounds blocks of 32, so a chunk's reductions are the whole motion's bit for bit (and its
#: proximity is wherever exact: see :class:`robocritics.planning.trace.ChunkGeometry`).
CHUNK_ALIGN = 64

PairKind = Literal["self", "environment"]


class Pair(BaseModel):
    """A named proximity pair: robot part ``a`` against robot part or scene entity ``b``.

    ``kind`` is ``self`` (two robot parts) or ``environment`` (a robot part or the
    carried object against a scene entity). ``group_a`` / ``group_b`` say what
    each side is: ``arm``, ``gripper``, ``attached`` (the carried object), or for
    ``b`` of an environment pair ``object``, ``container`` or ``table``. ``b_entity``
    is the scene id (a container's wall belongs to the container).
    """

    model_config = ConfigDict(frozen=True)
    name: str
    kind: PairKind
    a: str
    b: str
    group_a: str
    group_b: str
    b_entity: str = ""


class Step(BaseModel):
    """One program step (a skill call) and where it came from in the source."""

    model_config = ConfigDict(frozen=True)
    skill: str
    line: int = Field(0, description="1-based source line of the call (0 if unknown)")
    args: str = ""
    contacts: tuple[str, ...] = Field(
        (), description="scene ids the gripper or carried object may touch during this step (grasp target, set-down surface)"
    )
    speed_fraction: float = Field(1.0, description="speed scaling in force for this step, (0, 1]")


class RobotLimits(BaseModel):
    """Joint limits of the robot that produced a trajectory."""

    model_config = ConfigDict(frozen=True)
    joint_names: tuple[str, ...]
    lower_rad: tuple[float, ...]
    upper_rad: tuple[float, ...]
    velocity_rad_s: tuple[float, ...]
    acceleration_rad_s2: tuple[float, ...]


@dataclass(frozen=True)
class State:
    """One sample s_t of a trajectory (views into the arrays, not copies)."""

    index: int
    J: np.ndarray  # (n,) rad
    F: np.ndarray  # (L, 4, 4)
    P: np.ndarray  # (K,) m
    tau: float  # s


def _frozen(arr: np.ndarray) -> np.ndarray:
    """``arr`` made read-only; a read-only copy when it is a view of memory that can still be written (a view of
    the caller's array), so what :meth:`Trajectory.content_hash` hashed cannot change under the trajectory. A view
    of read-only memory (a slice of another trajectory) is kept as it is."""
    root = arr
    while isinstance(root.base, np.ndarray):
        root = root.base
    if root is not arr and (root.flags.writeable or (root.base is not None and arr.flags.writeable)):
        arr = arr.copy()
    arr.setflags(write=False)
    return arr


def _array(name: str, value, dtype=float, ndim: int | None = None) -> np.ndarray:
    arr = np.asarray(value, dtype=dtype)
    if ndim is not None and arr.ndim != ndim:
        raise TrajectoryError(f"{name} must have {ndim} dimensions, got shape {arr.shape}")
    # one pass without a temporary: a NaN or inf makes the sum non-finite (so can an overflow of finite values,
    # which the exact test below then clears)
    if dtype is float:
        with np.errstate(over="ignore", invalid="ignore"):
            total = np.add.reduce(arr, axis=None)
        if not np.isfinite(total) and not np.all(np.isfinite(arr)):
            bad = np.argwhere(~np.isfinite(arr))[0]
            raise TrajectoryError(f"{name} is not finite at index {tuple(int(i) for i in bad)}")
    return arr


class Trajectory:
    """Columnar motion trace; see the module docstring for every field and its unit."""

    def __init__(
        self,
        *,
        q,
        time,
        frames,
        frame_names,
        proximity,
        pairs,
        gripper_opening_m,
        attached,
        step,
        steps,
        limits: RobotLimits,
        robot_name: str = "",
        tcp_frame: str = "tcp",
        kinematic_hash: str = "",
        geometry=None,
    ):
        self.q = _array("q", q, ndim=2)
        T, n = self.q.shape
        self.time = _array("time", time, ndim=1)
        self.geometry = geometry  # computes frames and proximity of a compact trajectory (see the module docstring)
        if geometry is None:
            self._frames = _array("frames", frames, ndim=4)
            self._proximity = _array("proximity", proximity, ndim=2)
        elif frames is not None or proximity is not None:
            raise TrajectoryError("a compact trajectory (geometry given) computes its frames and proximity: pass None")
        self.frame_names = tuple(frame_names)
        self.pairs = tuple(p if isinstance(p, Pair) else Pair.model_validate(p) for p in pairs)
        self.gripper_opening_m = _array("gripper_opening_m", gripper_opening_m, ndim=1)
        self.attached = np.asarray(attached, dtype=str).reshape(-1)
        self.step = np.asarray(step, dtype=np.int64).reshape(-1)
        self.steps = tuple(s if isinstance(s, Step) else Step.model_validate(s) for s in steps)
        self.limits = limits if isinstance(limits, RobotLimits) else RobotLimits.model_validate(limits)
        self.robot_name = robot_name
        self.tcp_frame = str(tcp_frame)
        self.kinematic_hash = str(kinematic_hash)  # Robot.kinematic_hash of the arm it was planned for
        self._validate(T, n)
        self.q, self.time, self.gripper_opening_m, self.attached, self.step = map(
            _frozen, (self.q, self.time, self.gripper_opening_m, self.attached, self.step)
        )
        if geometry is None:
            self._frames.setflags(write=False)
            self._proximity.setflags(write=False)

    def _validate(self, T: int, n: int) -> None:
        if T < 1:
            raise TrajectoryError("a trajectory needs at least one sample")
        for name, arr in (
            ("time", self.time),
            ("gripper_opening_m", self.gripper_opening_m),
            ("attached", self.attached),
            ("step", self.step),
        ):
            if arr.shape[0] != T:
                raise TrajectoryError(f"{name} has {arr.shape[0]} samples but q has {T}")
        if self.geometry is None:
            frames, proximity = self._frames, self._proximity
            if frames.shape[0] != T or frames.shape[2:] != (4, 4):
                raise TrajectoryError(f"frames must have shape ({T}, L, 4, 4), got {frames.shape}")
            if frames.shape[1] != len(self.frame_names):
                raise TrajectoryError(f"frames hold {frames.shape[1]} frames but {len(self.frame_names)} names were given")
            if proximity.shape != (T, len(self.pairs)):
                raise TrajectoryError(f"proximity must have shape ({T}, {len(self.pairs)}), got {proximity.shape}")
        if T > 1:
            dt = np.diff(self.time)
            if np.any(dt <= 0):
                i = int(np.argmax(dt <= 0))
                raise TrajectoryError(
                    f"time must increase strictly: sample {i + 1} at {self.time[i + 1]} s follows {self.time[i]} s"
                )
        if self.tcp_frame not in self.frame_names:
            raise TrajectoryError(f"the TCP frame {self.tcp_frame!r} is not one of the frames ({', '.join(self.frame_names)})")
        if len(self.limits.joint_names) != n:
            raise TrajectoryError(f"limits name {len(self.limits.joint_names)} joints but q has {n} columns")
        if len(self.steps) and (self.step.min() < 0 or self.step.max() >= len(self.steps)):
            raise TrajectoryError(f"step indices must lie in [0, {len(self.steps)}), got {self.step.min()}..{self.step.max()}")
        if not len(self.steps) and np.any(self.step != 0):
            raise TrajectoryError("step indices given without steps")

    # --- access --------------------------------------------------------------------

    def __len__(self) -> int:
        return self.q.shape[0]

    @property
    def duration_s(self) -> float:
        return float(self.time[-1] - self.time[0])

    def frame_index(self, name: str) -> int:
        try:
            return self.frame_names.index(name)
        except ValueError:
            raise TrajectoryError(f"no frame {name!r}; frames are {', '.join(self.frame_names)}") from None

    @property
    def compact(self) -> bool:
        """Whether frames and proximity are computed on demand (a long motion; see the module docstring)."""
        return self.geometry is not None

    @property
    def frames(self) -> np.ndarray:
        """``(T, L, 4, 4)`` link poses, m, base frame (computed, whole, on every read of a compact trajectory)."""
        if self.geometry is None:
            return self._frames
        return self._computed(0, len(self))[0]

    @property
    def proximity(self) -> np.ndarray:
        """``(T, K)`` signed distances, m, of ``pairs`` (computed, whole, on every read of a compact trajectory)."""
        if self.geometry is None:
            return self._proximity
        return self._computed(0, len(self))[1]

    def _computed(self, start: int, stop: int) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        """Frames, proximity and moving objects' poses of samples ``start..stop-1`` of a compact trajectory,
        computed a chunk at a time on the chunk grid (:data:`CHUNK_ALIGN`): frames and poses are the whole motion's
        rows bit for bit, proximity wherever it is exact (:class:`~robocritics.planning.trace.ChunkGeometry`)."""
        cuts = {start, stop}
        if start % CHUNK_ALIGN:  # a halo sample before a chunk: computed apart, so the chunk starts on the grid
            cuts.add(min(stop, start - start % CHUNK_ALIGN + CHUNK_ALIGN))
        cuts.update(range((start // CHUNK_SAMPLES + 1) * CHUNK_SAMPLES, stop, CHUNK_SAMPLES))
        cuts = sorted(cuts)
        parts = [self.geometry.compute(a, b) for a, b in zip(cuts[:-1], cuts[1:])]
        if len(parts) == 1:
            return parts[0]
        frames = np.concatenate([f for f, _, _ in parts])
        proximity = np.asfortranarray(np.concatenate([p for _, p, _ in parts]))
        poses = {oid: np.concatenate([p[oid] for _, _, p in parts]) for oid in parts[0][2]}
        return frames, proximity, poses

    def chunks(self, size: int = CHUNK_SAMPLES, halo: int = 1) -> Iterator["Chunk"]:
        """The motion in consecutive chunks of ``size`` samples (a multiple of :data:`CHUNK_ALIGN`), each with
        ``halo`` samples of its neighbours on either side (for differences over time).

        A trajectory of at most ``size`` samples is one chunk: itself. Otherwise each :class:`Chunk` holds a
        trajectory of samples ``lo..hi-1`` (frames and proximity made for it when compact) of which samples
        ``start..stop-1`` are its own; reductions over the own samples of every chunk see each sample once.
        """
        if size < 1 or size % CHUNK_ALIGN:
            raise TrajectoryError(f"a chunk size is a positive multiple of {CHUNK_ALIGN} samples, got {size}")
        T = len(self)
        if T <= size:
            yield Chunk(0, T, 0, self, {})
            return
        for start in range(0, T, size):
            stop = min(start + size, T)
            lo, hi = max(start - halo, 0), min(stop + halo, T)
            piece, poses = self._window(lo, hi)
            yield Chunk(start, stop, lo, piece, poses)

    def _window(self, lo: int, hi: int) -> tuple["Trajectory", dict[str, np.ndarray]]:
        """Samples ``lo..hi-1`` as a stored trajectory, and the poses of the moving objects there (compact only)."""
        if self.geometry is None:
            return self.slice(lo, hi), {}
        frames, proximity, poses = self._computed(lo, hi)
        return self._sliced(lo, hi, frames, proximity), poses

    def frames_at(self, samples) -> np.ndarray:
        """``(len(samples), L, 4, 4)`` link poses at sample indices ``samples`` (a compact trajectory computes
        only those: forward kinematics is per sample, so they are the rows of :attr:`frames`)."""
        samples = np.asarray(samples, dtype=np.int64)
        if self.geometry is None:
            return self._frames[samples]
        return self.geometry.frames_at(samples)

    def object_poses(self, start: int = 0, stop: int | None = None) -> dict[str, np.ndarray]:
        """``{object id: (n, 4, 4)}`` poses of the objects the motion moves at samples ``start..stop-1`` of a
        compact trajectory (a stored one keeps none: see :attr:`robocritics.execution.Execution.object_poses`)."""
        if self.geometry is None:
            return {}
        stop = len(self) if stop is None else stop
        return self._computed(start, stop)[2]

    @property
    def positions(self) -> np.ndarray:
        """``(T, L, 3)`` m: every frame's origin in the base frame (``frames[:, :, :3, 3]``), one contiguous
        read-only copy made on first use and shared by every critic (a strided view is ~3x slower to scan)."""
        if self.geometry is not None:
            return np.ascontiguousarray(self.frames[:, :, :3, 3])
        cached = self.__dict__.get("_positions")
        if cached is None:
            cached = np.ascontiguousarray(self.frames[:, :, :3, 3])
            cached.setflags(write=False)
            self.__dict__["_positions"] = cached
        return cached

    @property
    def position_planes(self) -> np.ndarray:
        """``(3, L, T)`` m: :attr:`positions` as planes of x, y and z, each frame's samples contiguous
        (``planes[c, l, t] = positions[t, l, c]``): the layout the critics scan
        (:func:`robocritics.critic.derived.position_planes`). Gathered from ``frames`` in one pass (not through
        :attr:`positions`), one read-only copy made on first use, as :attr:`positions` (a compact trajectory:
        computed each time)."""
        if self.geometry is not None:
            return np.ascontiguousarray(self.frames[:, :, :3, 3].transpose(2, 1, 0))
        cached = self.__dict__.get("_position_planes")
        if cached is None:
            cached = np.ascontiguousarray(self._frames[:, :, :3, 3].transpose(2, 1, 0))
            cached.setflags(write=False)
            self.__dict__["_position_planes"] = cached
        return cached

    def __getstate__(self) -> dict:
        # the positions caches are derived from frames: not pickled (a batch ships trajectories between processes)
        state = dict(self.__dict__)
        state.pop("_positions", None)
        state.pop("_position_planes", None)
        state.pop("_content_hash", None)
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        for name in ("q", "time", "gripper_opening_m", "attached", "step"):  # unpickled arrays come writeable
            self.__dict__[name] = _frozen(self.__dict__[name])

    @property
    def tcp(self) -> np.ndarray:
        """``(T, 4, 4)`` poses of the TCP frame (``tcp_frame``, the robot's) in the base frame; column 2 of the
        rotation is the finger direction."""
        return self.frames[:, self.frame_index(self.tcp_frame)]

    def pair_mask(self, kind: str | None = None, group_a: str | None = None, group_b: str | None = None) -> np.ndarray:
        """Boolean ``(K,)`` selecting pairs by kind and groups."""
        return np.array(
            [
                (kind is None or p.kind == kind)
                and (group_a is None or p.group_a == group_a)
                and (group_b is None or p.group_b == group_b)
                for p in self.pairs
            ],
            dtype=bool,
        )

    def lines(self, samples: np.ndarray | None = None) -> list[int]:
        """Sorted distinct program lines that produced ``samples`` (all samples if None)."""
        if not self.steps:
            return []
        idx = self.step if samples is None else self.step[np.asarray(samples)]
        return sorted({self.steps[int(i)].line for i in unique_values(idx).tolist() if self.steps[int(i)].line > 0})

    def skills(self, samples: np.ndarray | None = None) -> list[str]:
        """Distinct skill names (in order of first use) that produced ``samples``."""
        if not self.steps:
            return []
        idx = self.step if samples is None else self.step[np.asarray(samples)]
        out: list[str] = []
        for i in unique_values(idx).tolist():
            s = self.steps[int(i)].skill
            if s not in out:
                out.append(s)
        return out

    @property
    def states(self) -> Iterator[State]:
        """Per-sample (J, F, P, tau) views, for readers of the paper (a compact trajectory's made chunk by chunk)."""
        if self.geometry is None:
            for t in range(len(self)):
                yield State(t, self.q[t], self._frames[t], self._proximity[t], float(self.time[t]))
            return
        for chunk in self.chunks(halo=0):
            # read once per chunk: a motion of one chunk is its own chunk, whose reads compute it whole
            frames, proximity = chunk.trajectory.frames, chunk.trajectory.proximity
            for i in range(len(frames)):
                t = chunk.lo + i
                yield State(t, self.q[t], frames[i], proximity[i], float(self.time[t]))

    # --- serialisation -------------------------------------------------------------

    def to_dict(self) -> dict:
        return {
            "robot_name": self.robot_name,
            "tcp_frame": self.tcp_frame,
            "kinematic_hash": self.kinematic_hash,
            "q": self.q.tolist(),
            "time": self.time.tolist(),
            "frames": self.frames.tolist(),
            "frame_names": list(self.frame_names),
            "proximity": self.proximity.tolist(),
            "pairs": [p.model_dump() for p in self.pairs],
            "gripper_opening_m": self.gripper_opening_m.tolist(),
            "attached": self.attached.tolist(),
            "step": self.step.tolist(),
            "steps": [s.model_dump() for s in self.steps],
            "limits": self.limits.model_dump(),
        }

    def to_json(self) -> str:
        """JSON text; floats are written with ``repr`` precision so the round trip is exact."""
        return json.dumps(self.to_dict())

    @classmethod
    def from_dict(cls, data: dict) -> "Trajectory":
        try:
            q = np.asarray(data["q"], dtype=float)
            frames = np.asarray(data["frames"], dtype=float).reshape(q.shape[0], len(data["frame_names"]), 4, 4)
            proximity = np.asarray(data["proximity"], dtype=float).reshape(q.shape[0], len(data["pairs"]))
            return cls(
                q=q,
                time=data["time"],
                frames=frames,
                frame_names=data["frame_names"],
                proximity=proximity,
                pairs=data["pairs"],
                gripper_opening_m=data["gripper_opening_m"],
                attached=data["attached"],
                step=data["step"],
                steps=data["steps"],
                limits=data["limits"],
                robot_name=data.get("robot_name", ""),
                tcp_frame=data.get("tcp_frame", "tcp"),
                kinematic_hash=data.get("kinematic_hash", ""),
            )
        except KeyError as exc:
            raise TrajectoryError(f"trajectory data lacks the field {exc.args[0]!r}") from None
        except (TypeError, ValueError) as exc:
            if isinstance(exc, TrajectoryError):
                raise
            raise TrajectoryError(f"malformed trajectory data: {str(exc)[:300]}") from None

    @classmethod
    def from_json(cls, text: str) -> "Trajectory":
        """The trajectory of :meth:`to_json` text; :class:`TrajectoryError` for text that is not one."""
        try:
            data = json.loads(text)
        except json.JSONDecodeError as exc:
            raise TrajectoryError(f"not valid JSON at line {exc.lineno}, column {exc.colno}: {exc.msg}") from None
        except (ValueError, RecursionError) as exc:  # a number Python cannot convert, or absurd nesting
            raise TrajectoryError(f"not trajectory JSON: {str(exc)[:200]}") from None
        if not isinstance(data, dict):
            raise TrajectoryError(f"trajectory JSON is an object, got {type(data).__name__}")
        return cls.from_dict(data)

    def content_hash(self, *, recompute: bool = False) -> str:
        """SHA-256 of the executed content (joint samples, time, gripper, attachment).

        Binds a :class:`~robocritics.critic.Report` to the exact motion it judged,
        so the deploy gate can refuse any other motion. Computed once (2 ms for 30,000 samples) and kept with the
        arrays it hashed: those are read-only and own their memory or view read-only memory (:func:`_frozen`), so
        only assigning another array or limits to the trajectory changes the content, and that is seen.
        ``recompute``: hash the arrays again whatever is kept (the deploy gate does: code that turns an array's
        write flag back on and writes to it changes the motion without assigning anything).
        """
        hashed = (self.q, self.time, self.gripper_opening_m, self.attached, self.limits)
        cached = self.__dict__.get("_content_hash")
        if not recompute and cached is not None and all(a is b for a, b in zip(cached[0], hashed)):
            return cached[1]
        digest = self._hash()
        self.__dict__["_content_hash"] = (hashed, digest)
        return digest

    def _hash(self) -> str:
        h = hashlib.sha256()
        for arr in (self.q, self.time, self.gripper_opening_m):
            h.update(np.ascontiguousarray(arr, dtype="<f8"))  # the buffer itself: no bytes copy
        # "\x00".join(attached), built from its runs (the held object changes a few times per program):
        # the same text as joining every sample's id, without a Python string per sample
        attached = self.attached
        if len(attached):
            start = run_starts(attached)
            count = np.diff(np.append(start, len(attached))).tolist()
            h.update("".join((v + "\x00") * n for v, n in zip(attached[start].tolist(), count))[:-1].encode())
        h.update(",".join(self.limits.joint_names).encode())
        return h.hexdigest()

    def slice(self, start: int, stop: int) -> "Trajectory":
        """Samples ``start:stop`` as a new trajectory (same pairs, steps, limits), stored whole (a compact
        trajectory's slice has its frames and proximity computed)."""
        if self.geometry is not None:
            start, stop, _ = slice(start, stop).indices(len(self))
            frames, proximity, _ = self._computed(start, max(stop, start))
            return self._sliced(start, stop, frames, proximity)
        return self._sliced(start, stop, self._frames[start:stop], self._proximity[start:stop])

    def _sliced(self, start: int, stop: int, frames: np.ndarray, proximity: np.ndarray) -> "Trajectory":
        sl = slice(start, stop)
        return Trajectory(
            q=self.q[sl],
            time=self.time[sl],
            frames=frames,
            frame_names=self.frame_names,
            proximity=proximity,
            pairs=self.pairs,
            gripper_opening_m=self.gripper_opening_m[sl],
            attached=self.attached[sl],
            step=self.step[sl],
            steps=self.steps,
            limits=self.limits,
            robot_name=self.robot_name,
            tcp_frame=self.tcp_frame,
            kinematic_hash=self.kinematic_hash,
        )

    def __repr__(self) -> str:
        return (
            f"Trajectory({len(self)} samples, {self.q.shape[1]} joints, {self.duration_s:.3f} s, "
            f"{len(self.frame_names)} frames, {len(self.pairs)} pairs, {len(self.steps)} steps)"
        )


@dataclass(frozen=True)
class Chunk:
    """One chunk of a trajectory (:meth:`Trajectory.chunks`): ``trajectory`` holds samples ``lo..lo+len-1`` of
    the whole, of which ``start..stop-1`` are this chunk's own (the others are its halo); ``object_poses`` are
    the moving objects' poses over ``trajectory`` (compact trajectories only; empty otherwise)."""

    start: int
    stop: int
    lo: int
    trajectory: Trajectory
    object_poses: dict

    @property
    def own(self) -> slice:
        """The chunk's own rows in ``trajectory``'s arrays."""
        return slice(self.start - self.lo, self.stop - self.lo)
