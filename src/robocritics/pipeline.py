"""The pipeline: :func:`simulate` (a robot program to a critic-ready run) and :func:`check` (a program or a run to
its report), the one composition of the stages that the CLI, the loop, repairs, the studio, batch and deploy call.

:func:`simulate`, one stage after another (each a plain function of its inputs):

1. the program runs in the sandbox (:func:`robocritics.program.run_program`) to a
   :class:`~robocritics.program.plan.Plan`: skill calls with their source lines;
2. the planner (:class:`robocritics.planning.planner.Planner`) turns each call into
   timed joint samples (IK, obstacle routing, jerk-limited timing, grasps);
3. the robot model (:meth:`robocritics.Robot.trajectory`) adds link frames and
   proximities, giving the :class:`~robocritics.trajectory.Trajectory` the critics
   read and the deploy gate streams.

:func:`check` then runs the critics on the :class:`~robocritics.execution.Execution`
(:func:`robocritics.critic.critique`); a program that cannot run gets the ``runtime`` verdict instead.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Iterable, Iterator, Mapping, Optional

from .errors import CriticError, PlanningError, ProgramError, RobotModelError, RoboCriticsError, SceneError
from .execution import Execution, MovedPoses
from .trajectory import CHUNK_SAMPLES

if TYPE_CHECKING:  # pragma: no cover
    from .critic import Critic
    from .goals import Goal
    from .program.plan import Plan
    from .critic.report import Report
    from .robot.model import Robot
    from .planning.planner import PlannerSettings
    from .scene import Scene

__all__ = ["simulate", "check", "Checked", "check_scene_ids"]


#: Names the interpreter binds in every program besides skills, builtins and modules (it has no public list).
_PROGRAM_LISTS = {"objects": "the list of the scene's objects", "containers": "the list of its containers"}


def check_scene_ids(scene: Scene) -> None:
    """Refuse a scene whose object or container ids are names of the skill API.

    In a program an object is a variable named by its id, so an object named
    ``home`` would hide the skill ``home()``, one named ``lib`` the ``lib`` module,
    and one named ``open`` could not be used at all (programs may not say ``open``).
    :class:`~robocritics.Scene` itself refuses the names of the program language
    (:func:`robocritics.scene.reserved_names`); the skill API is built on scenes, so
    its names are checked here, where a scene meets it: the skills
    (:data:`robocritics.program.skills.SKILLS`), the modules a program can import
    (:data:`robocritics.program.check.MODULE_ALIASES`), the names programs may not
    use (:data:`robocritics.program.check.FORBIDDEN_NAMES`) and the ``objects`` and
    ``containers`` lists. Raises :class:`SceneError` naming the field (``objects[2].id``).
    """
    from .program.check import FORBIDDEN_NAMES, MODULE_ALIASES
    from .program.skills import SKILLS

    for group in ("objects", "containers"):
        for i, item in enumerate(getattr(scene, group)):
            name = item.id
            if name in SKILLS:
                what = "a skill in robot programs; an object named so would hide it"
            elif name in MODULE_ALIASES:
                what = f"the module {MODULE_ALIASES[name]!r} of robot programs; an object named so would hide it"
            elif name in _PROGRAM_LISTS:
                what = f"{_PROGRAM_LISTS[name]} in robot programs; an object named so would hide it"
            elif name in FORBIDDEN_NAMES:
                what = "a name robot programs may not use, so they could not refer to this object"
            else:
                continue
            raise SceneError(
                f"{name!r} is {what}; choose another id (e.g. '{name}_1')",
                path=f"{group}[{i}].id",
            )


def simulate(
    program: str | Plan,
    scene: Scene,
    robot: Robot | None = None,
    sample_rate_hz: float = 125.0,
    settings: PlannerSettings | None = None,
    start_q=None,
) -> Execution:
    """Run ``program`` (source text or a Plan) in ``scene`` and build its timed :class:`Trajectory`.

    The motion starts at ``start_q`` (joint angles, rad; e.g. where a real arm is
    now, ``URArm.actual_q()``) or, by default, at the robot's home pose
    ``robot.home_q``. ``sample_rate_hz`` is the trajectory's sample rate [Hz], in
    [25, 500] (:data:`~robocritics.planning.timing.MIN_SAMPLE_RATE_HZ`,
    :data:`~robocritics.planning.timing.MAX_SAMPLE_RATE_HZ`: sparser sampling hides
    fast motion from the critics, denser is more than a controller executes).

    Raises :class:`SceneError` for a scene whose ids are names of the skill API (:func:`check_scene_ids`),
    :class:`ProgramError` for a program the sandbox rejects and
    :class:`PlanningError` (with the program line) for a motion that cannot be
    planned, such as an unreachable target, a speed below 1 % or a sample rate
    out of range. A motion beyond the budget of ``settings`` (1,000,000 samples, 1 GB estimated, 100,000
    IK solutions by default; see :class:`PlannerSettings`; a long motion is stored compactly) raises
    :class:`MotionBudgetError`, a PlanningError, before its samples are made.
    """
    from .program.plan import Plan
    from .program.sandbox import run_program
    from .robot.model import Robot, default_robot
    from .planning.timing import check_sample_rate
    from .planning.planner import Planner, PlannerSettings
    from .scene import Scene

    if not isinstance(scene, Scene):
        raise SceneError(
            f"simulate() needs a Scene, got {type(scene).__name__}; load one with "
            "Scene.builtin('sorting') or Scene.resolve(name_or_path)"
        )
    if robot is not None and not isinstance(robot, Robot):
        raise RobotModelError(f"simulate() needs a Robot (e.g. Robot.ur3e()), got {type(robot).__name__}")
    sample_rate_hz = check_sample_rate(sample_rate_hz)
    if not isinstance(program, Plan):  # a program refers to objects by id
        check_scene_ids(scene)
    robot = robot or default_robot()
    if scene.robot and scene.robot != robot.name:
        raise SceneError(
            f"the scene {scene.name!r} was made for the {scene.robot}, not the {robot.name}: its objects are placed "
            f"for that arm's reach; simulate it with that robot, or copy the scene for this one",
            path="robot",
        )
    scene = robot.scene_for(scene)  # a scene without its own workspace is judged by this robot's reach
    plan = program if isinstance(program, Plan) else run_program(program, scene)
    planner = Planner(scene, robot, sample_rate_hz, settings or PlannerSettings(), start_q=start_q)
    planner.run(plan)
    if not planner.steps:
        first_code_line = next(  # not a comment or blank line at the top of the program
            (i for i, text in enumerate(program.splitlines(), 1) if text.strip() and not text.lstrip().startswith("#")),
            1,
        ) if isinstance(program, str) else 1  # fmt: skip
        raise ProgramError("the program made no skill calls, so there is no motion to check", line=first_code_line)
    q, t, opening, attached, step = planner.finish()
    if len(q) > CHUNK_SAMPLES:  # a long motion: frames, proximity and object poses made chunk by chunk, on demand
        from .planning.trace import build_compact_trajectory, pose_schedules

        trajectory = build_compact_trajectory(
            robot, scene, q, t, gripper_opening_m=opening, attached=attached, step=step, steps=planner.steps,
            schedules=pose_schedules(planner.world, q, opening, robot),
        )  # fmt: skip
        object_poses = MovedPoses(trajectory)
    else:
        # frames and capsule endpoints in one FK pass (the endpoints straight from the frames' time series)
        frames, p0, p1 = robot.forward_with_capsules(q, opening)
        object_poses = planner.world.object_poses(frames[:, robot.tcp_index])
        trajectory = robot.trajectory(
            q=q,
            time=t,
            scene=scene,
            gripper_opening_m=opening,
            attached=attached,
            step=step,
            steps=planner.steps,
            object_poses=object_poses,
            frames=frames,
            segments=(p0, p1),
        )
        for poses in object_poses.values():
            poses.setflags(write=False)
    final_scene = scene.model_copy(update={"objects": [planner.world.objects[o.id] for o in scene.objects]})
    return Execution(
        trajectory, plan, planner.events, final_scene, scene, robot, dict(planner.world.resting_on),
        object_poses if isinstance(object_poses, MovedPoses) else dict(object_poses),
    )



@dataclass(frozen=True)
class Checked:
    """What :func:`check` returns: the run (None when the program did not run), its report, and the error that
    stopped the program (None when it ran). Unpacks as ``execution, report = check(...)``."""

    execution: Optional[Execution]
    report: Report
    #: The ProgramError or PlanningError of a program that did not run (its report is the ``runtime`` verdict).
    error: Optional[RoboCriticsError] = None

    def __iter__(self) -> Iterator[Any]:
        return iter((self.execution, self.report))


def check(
    program: str | Plan | Execution,
    scene: Scene | None = None,
    *,
    robot: Robot | None = None,
    goals: Iterable[str | Goal] | str | Goal | None = None,
    critics: Iterable[str | Critic] | str | None = None,
    params: Mapping[str, Any] | None = None,
    sample_rate_hz: float = 125.0,
    settings: PlannerSettings | None = None,
    start_q=None,
) -> Checked:
    """Simulate ``program`` in ``scene`` (:func:`simulate`) and critique the run (:func:`robocritics.critique`).

    ``program`` is source text, a Plan, or an :class:`Execution` already simulated (or imported from another
    tool), which is only critiqued (``scene`` then defaults to its own). ``goals``, ``critics`` and ``params`` are
    as in :func:`~robocritics.critic.critique`; ``robot``, ``sample_rate_hz``, ``settings`` and ``start_q`` as in
    :func:`simulate`.

    A program the sandbox rejects (:class:`~robocritics.errors.ProgramError`) or whose motion cannot be planned
    (:class:`~robocritics.errors.PlanningError`, the motion budget included) gives ``Checked(None, report, error)``
    whose report is one ERROR verdict of the ``runtime`` critic naming the line
    (:func:`~robocritics.critic.runtime_report`; score 0), so callers treat it like any failing report. Bad input
    of the caller (unknown critics or params: :class:`CriticError`; malformed goals:
    :class:`~robocritics.errors.GoalError`; a bad scene) raises, before simulating; so does a critic that fails
    (its CriticError's ``execution`` is the run it could not judge).
    """
    from .critic import critique, runtime_report, select_critics
    from .goals import parse_goals

    if isinstance(program, Execution):
        return Checked(program, critique(program, scene, critics, params, goals=goals, robot=robot))
    if scene is None:
        raise SceneError("check() needs the scene the program runs in: check(program, scene)")
    goals = parse_goals(goals, scene)
    select_critics(critics, params)  # fail fast, before a slow simulation
    try:
        execution = simulate(program, scene, robot, sample_rate_hz, settings, start_q)
    except (ProgramError, PlanningError) as exc:
        return Checked(None, runtime_report(exc), exc)
    try:
        return Checked(execution, critique(execution, critics=critics, params=params, goals=goals))
    except CriticError as exc:  # a critic could not judge the run: the error carries the run (its motion is shown)
        exc.execution = execution
        raise
