"""One simulated run as replay data: what the 3-D replay (``static/replay.js``) draws, as plain JSON.

:func:`replay_data` turns an :class:`~robocritics.execution.Execution` (and the
:class:`~robocritics.critic.report.Report` of its critics) into a JSON-serialisable dict
that the replay component renders in a browser, the same for the studio, a
notebook and an offline HTML file:

* the time axis ``time_s`` [s] of the *frames* drawn: the trajectory's samples
  thinned to at most :data:`MAX_FRAME_RATE_HZ`, always keeping the first and last
  sample and every verdict's worst sample and window bounds, so the moment a
  critic points at is drawn exactly; a long motion is thinned further to about
  :data:`MAX_REPLAY_FRAMES` frames, its flagged windows kept at the full frame rate;
* the robot as capsules: per frame the two end points (m, base frame) of every
  collision capsule (fingers included, so the gripper opens and closes), and
  each capsule's radius [m];
* the scene: table and container boxes (static), objects with their shape, size
  [m] and colour (a mesh fixture with its triangles, at most :data:`MAX_SHOWN_TRIANGLES`), and per frame the pose of every object the program moved
  (carried objects move with the gripper); the people in the cell as the capsules
  of their ISO/TS 15066 body regions (static; :mod:`robocritics.humans`);
* provenance: per frame the program step, and the steps' skills and source lines;
* the verdicts: flag, message, hint, measured value and threshold, flagged time
  windows [s], worst time [s], the links and objects of the evidence, and for
  collision and pinch-point findings the closest-points segment at the worst
  sample (m, base frame), computed with coal.

Float arrays are little-endian float32, base64-encoded (``{"dtype", "shape",
"data"}``): a minute of motion is a few hundred kB.
"""

from __future__ import annotations

import base64
import math
from typing import TYPE_CHECKING, Any

import numpy as np

from .._arrays import unique_values
from ..geometry.pairs import capsule_pose, closest_points

if TYPE_CHECKING:  # pragma: no cover
    from ..critic.report import Report

__all__ = ["replay_data", "REPLAY_FORMAT", "MAX_FRAME_RATE_HZ", "MAX_REPLAY_FRAMES"]

#: The run a replay draws: an :class:`~robocritics.execution.Execution`. Not imported, not even for type hints:
#: ``Execution.show`` imports this package, and the import would close a cycle.
Run = Any

#: Version tag of the replay data, checked by ``replay.js``.
REPLAY_FORMAT = "robocritics-replay/1"

#: Frames drawn per second of motion at most [Hz]: smooth playback, small files.
MAX_FRAME_RATE_HZ = 30.0
#: Most frames of one replay (5 min at MAX_FRAME_RATE_HZ, some 4 MB): a longer motion keeps its flagged windows at
#: that rate and is thinned elsewhere (see :func:`_frame_samples`).
MAX_REPLAY_FRAMES = 9_000

# Colours of the scene's `colour` attributes; anything else gets a palette colour.
_NAMED_COLOURS = {
    "red": "#d63a2f", "green": "#4caf50", "yellow": "#f2c12e", "blue": "#3b73d9", "white": "#f4f4f0",
    "black": "#2b2b2b", "silver": "#c0c6cc", "grey": "#9aa0a6", "gray": "#9aa0a6", "brown": "#8d6e4c",
    "orange": "#f08a24", "purple": "#8e5cc2", "pink": "#e57ea8", "beige": "#e8dcc0",
}  # fmt: skip
_PALETTE = ("#5c8fd6", "#d6895c", "#6fbf73", "#c76fbf", "#bfae6f", "#6fbfb4")
_FLAG_COLOURS = {"OK": "#2e9d4a", "WARNING": "#e0a100", "ERROR": "#d33a2c"}


def _f32(array: np.ndarray) -> dict[str, Any]:
    a = np.ascontiguousarray(array, dtype="<f4")
    return {"dtype": "float32", "shape": list(a.shape), "data": base64.b64encode(a.tobytes()).decode("ascii")}


MAX_SHOWN_TRIANGLES = 20_000
"""Most triangles of one mesh object sent to the browser (float32, 36 bytes each): larger meshes are decimated."""


def shown_triangles(vertices: np.ndarray, triangles: np.ndarray, limit: int = MAX_SHOWN_TRIANGLES) -> np.ndarray:
    """The corners ``(F', 3, 3)`` (m, the mesh's frame) of at most ``limit`` triangles showing the mesh: all of
    them if few enough, else vertex clustering (vertices snapped to a grid whose cell doubles until the
    triangles left, those with three distinct corners, are few enough: the outline stays, small detail goes)."""
    corners = vertices[triangles]
    extent = float(np.ptp(vertices, axis=0).max()) or 1.0
    cell = extent / 512
    while len(corners) > limit:
        snapped = np.round(vertices / cell).astype(np.int64)
        _, ids = np.unique(snapped, axis=0, return_inverse=True)
        ids = ids.reshape(-1)
        keys = ids[triangles]
        keep = (keys[:, 0] != keys[:, 1]) & (keys[:, 1] != keys[:, 2]) & (keys[:, 0] != keys[:, 2])
        centres = np.zeros((ids.max() + 1, 3))
        np.add.at(centres, ids, vertices)
        centres /= np.bincount(ids)[:, None]
        # one triangle per distinct corner set (clustering folds neighbours onto each other)
        unique_keys = np.unique(np.sort(keys[keep], axis=1), axis=0)
        corners = centres[unique_keys]
        cell *= 2
    return corners


def _colour(attributes: dict, index: int) -> str:
    name = str(attributes.get("colour", attributes.get("color", ""))).lower()
    return _NAMED_COLOURS.get(name, _PALETTE[index % len(_PALETTE)])


def _pose12(pose: np.ndarray) -> list[float]:
    """The top 3x4 of a homogeneous pose, row-major (what three.js ``Matrix4.set`` needs, plus 0 0 0 1)."""
    return [round(float(v), 6) for v in np.asarray(pose, float)[:3, :4].reshape(-1)]


def _frame_samples(time_s: np.ndarray, keep: list[int], windows: list[tuple[int, int]] = ()) -> np.ndarray:
    """Sample indices drawn as frames: every k-th sample (at most MAX_FRAME_RATE_HZ) plus ``keep`` and the last.

    A motion longer than :data:`MAX_REPLAY_FRAMES` frames at that rate (a long program) keeps the flagged
    ``windows`` (inclusive sample ranges) whole at that rate, in up to half the frames (thinned evenly beyond), and
    the rest of the motion evenly thinned to the frames left: the replay's size is bounded, not its length.
    """
    T = len(time_s)
    if T == 1:
        return np.zeros(1, dtype=np.int64)
    rate_hz = (T - 1) / max(float(time_s[-1] - time_s[0]), 1e-9)
    stride = max(1, int(math.ceil(rate_hz / MAX_FRAME_RATE_HZ - 1e-9)))
    base = np.arange(0, T, stride)
    if len(base) > MAX_REPLAY_FRAMES:
        # the regular frames inside the windows (the same grid as a short replay's)
        flagged = [base[np.searchsorted(base, a) : np.searchsorted(base, b, side="right")] for a, b in windows]
        flagged = unique_values(np.concatenate(flagged or [np.zeros(0, dtype=np.int64)]).astype(np.int64))
        if len(flagged) > MAX_REPLAY_FRAMES // 2:
            flagged = flagged[:: -(-len(flagged) // (MAX_REPLAY_FRAMES // 2))]
        left = max(MAX_REPLAY_FRAMES - len(flagged), 2)
        base = np.concatenate([np.arange(0, T, -(-T // left)), flagged])
    picked = np.concatenate([base, np.asarray(keep, dtype=np.int64), [T - 1]])
    return unique_values(picked[(picked >= 0) & (picked < T)])  # (np.unique would load numpy.ma)


def _segment(execution: Run, pair_name: str, sample: int) -> list[list[float]] | None:
    """The closest-points segment of proximity pair ``pair_name`` at ``sample`` (m, base frame), or None."""
    trajectory, robot = execution.trajectory, execution.robot
    pair = next((p for p in trajectory.pairs if p.name == pair_name), None)
    if pair is None:
        return None
    p0, p1 = robot.capsule_segments(trajectory.frames_at([sample]))
    capsule_index = {name: i for i, name in enumerate(robot.capsule_names)}

    def shapes_of(name: str) -> list[tuple[str, Any, np.ndarray]]:
        if name in capsule_index:
            i = capsule_index[name]
            pose, length = capsule_pose(p0[0, i], p1[0, i])
            return [("capsule", (robot.capsule_radii[i], length), pose)]
        moved = name in execution.object_poses or None
        return [
            (s.kind, s.size if s.mesh is None else s.mesh, s.pose if moved is None else _poses_at(execution, name, [sample])[0])
            for s in execution.scene.shapes()
            if s.owner == name
        ]

    best = None
    for a in shapes_of(pair.a):
        for b in shapes_of(pair.b_entity or pair.b):
            pa, pb, d = closest_points(a[0], a[1], a[2], b[0], b[1], b[2])
            if best is None or d < best[2]:
                best = (pa, pb, d)
    if best is None:
        return None
    return [[round(float(v), 6) for v in best[0]], [round(float(v), 6) for v in best[1]]]



def _finite(x: float | None) -> float | None:
    """A number JSON can carry: a plugin critic's NaN or infinity is shown as no value."""
    return float(x) if x is not None and math.isfinite(x) else None


def _verdicts(execution: Run, report: Report, time_s: np.ndarray) -> list[dict[str, Any]]:
    out = []
    for v in report.verdicts:
        ev = v.evidence
        windows = [[float(time_s[a]), float(time_s[b])] for a, b in ev.sample_ranges if 0 <= a <= b < len(time_s)]
        if not windows and ev.time_window_s is not None and all(map(math.isfinite, ev.time_window_s)):
            windows = [[float(ev.time_window_s[0]), float(ev.time_window_s[1])]]
        segment = None
        pair = v.details.get("closest_pair") if isinstance(v.details, dict) else None
        if pair and ev.worst_sample is not None and 0 <= ev.worst_sample < len(time_s):
            segment = _segment(execution, str(pair), int(ev.worst_sample))
        out.append(
            {
                "critic": v.critic,
                "flag": v.flag.value,
                "colour": _FLAG_COLOURS[v.flag.value],
                "message": v.message,
                "hint": v.hint,
                "value": _finite(v.value),
                "threshold": _finite(v.threshold),
                "unit": v.unit,
                "windows_s": [] if v.flag.value == "OK" else windows,
                "worst_time_s": _finite(ev.worst_time_s),
                "links": list(ev.links),
                "objects": list(ev.objects) + _people_involved(v.details),
                "lines": list(ev.lines),
                "segment": segment,
            }
        )
    return out


def _people_involved(details: Any) -> list[str]:
    """The person (``"operator"``) and body capsule (``"operator.abdomen"``) a verdict's details name, if any."""
    if not isinstance(details, dict) or not isinstance(details.get("human"), str):
        return []
    human = details["human"]
    capsule = details.get("body_capsule")
    return [f"{human}.{capsule}"] if isinstance(capsule, str) else [human]


def _humans(scene: Any) -> list[dict[str, Any]]:
    """Every person's body-region capsules (m, base frame) for drawing."""
    from ..humans import scene_bodies

    return [
        {
            "id": body.human,
            "capsules": [
                {"name": f"{body.human}.{name}", "region": region, "p0": body.p0[i].tolist(),
                 "p1": body.p1[i].tolist(), "radius_m": float(body.radius_m[i])}
                for i, (name, region) in enumerate(zip(body.names, body.regions))
            ],
        }
        for body in scene_bodies(scene)
    ]


def _flagged_windows(report: Report | None) -> list[tuple[int, int]]:
    """The sample ranges (inclusive) of the verdicts that are not OK."""
    return [r for v in (report.verdicts if report is not None else ()) if v.flag != "OK" for r in v.evidence.sample_ranges]


def _keep_samples(report: Report | None) -> list[int]:
    keep: list[int] = []
    for v in report.verdicts if report is not None else ():
        ev = v.evidence
        keep += [s for s in (ev.worst_sample, ev.first_sample, ev.last_sample) if s is not None]
        for a, b in ev.sample_ranges:
            keep += [a, b]
    return keep


def replay_data(execution: Run, report: Report | None = None, *, title: str | None = None) -> dict[str, Any]:
    """The replay of ``execution`` (with the verdicts of ``report``, if given) as a JSON-serialisable dict.

    See the module docstring for what it holds; ``robocritics.viz.replay_html``
    and the studio render it with ``static/replay.js``.
    """
    # duck-typed: importing simulate here would make a cycle with Execution.show
    if not all(hasattr(execution, a) for a in ("trajectory", "robot", "scene", "object_poses")):
        raise TypeError(f"replay_data() needs the Execution that simulate() returns, got {type(execution).__name__}")
    trajectory, robot, scene = execution.trajectory, execution.robot, execution.scene
    workspace = scene.workspace or robot.workspace  # a scene without one follows its robot
    time_all = np.asarray(trajectory.time, float)
    frames = _frame_samples(time_all, _keep_samples(report), _flagged_windows(report))
    p0, p1 = robot.capsule_segments(trajectory.frames_at(frames))  # only the shown samples (a long run's too)
    capsule_ends = np.concatenate([p0, p1], axis=2)  # (F, C, 6)

    objects = []
    for i, o in enumerate(scene.objects):
        shape = o.shapes()[0]
        entry = {
            "id": o.id,
            "shape": o.shape,
            "size": [float(s) for s in o.size],
            "colour": _colour(o.attributes, i),
            "pose": _pose12(shape.pose),
        }
        if shape.mesh is not None:
            entry["triangles"] = _f32(shown_triangles(*shape.mesh).reshape(-1, 9))
        if o.id in execution.object_poses:
            entry["poses"] = _f32(_poses_at(execution, o.id, frames)[:, :3, :4].reshape(len(frames), 12))
        objects.append(entry)
    boxes = []
    for c in scene.containers:
        colour = _colour(c.attributes, len(boxes)) if c.attributes else "#b08a5a"
        boxes += [{"owner": c.id, "kind": "container", "size": list(s.size), "pose": _pose12(s.pose), "colour": colour}
                  for s in c.shapes()]  # fmt: skip
    boxes += [{"owner": "table", "kind": "table", "size": list(s.size), "pose": _pose12(s.pose), "colour": "#d9cbb3"}
              for s in scene.table.shapes()]  # fmt: skip
    attached_ids = sorted({a for a in trajectory.attached[frames] if a})
    steps = [{"skill": s.skill, "line": s.line, "args": s.args} for s in trajectory.steps]
    data: dict[str, Any] = {
        "format": REPLAY_FORMAT,
        "title": title or f"{scene.name}: {len(trajectory)} samples, {trajectory.duration_s:.2f} s",
        "robot": trajectory.robot_name or robot.name,
        "scene": scene.name,
        "duration_s": float(time_all[-1] - time_all[0]),
        "time_s": _f32(time_all[frames] - time_all[0]),
        "capsules": [
            {"name": c.name, "group": c.group, "radius_m": float(c.radius_m)} for c in robot.capsules
        ],
        "capsule_ends": _f32(capsule_ends),
        "gripper_opening_m": _f32(np.asarray(trajectory.gripper_opening_m)[frames]),
        "attached": [attached_ids.index(a) if a else -1 for a in trajectory.attached[frames]],
        "attached_ids": attached_ids,
        "step": [int(s) for s in trajectory.step[frames]],
        "steps": steps,
        "objects": objects,
        "boxes": boxes,
        "humans": _humans(scene),
        "workspace": {"center": list(workspace.center), "radius_m": float(workspace.radius_m)},
        "verdicts": [],
        "score_text": None,
    }
    if report is not None:
        data["verdicts"] = _verdicts(execution, report, time_all - time_all[0])
        data["score_text"] = report.score_text
        data["summary"] = report.summary()
    return data


def _poses_at(execution: Run, obj_id: str, samples) -> np.ndarray:
    """``(n, 4, 4)`` poses of moving object ``obj_id`` at ``samples``, without a long run's whole ``(T, 4, 4)``."""
    poses = execution.object_poses
    at = getattr(poses, "at", None)
    return at(obj_id, samples) if at is not None else np.asarray(poses[obj_id])[np.asarray(samples)]
