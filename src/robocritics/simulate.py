"""``simulate()``: a robot program to a physically timed, critic-ready trajectory.

The pipeline, one stage after another (each a plain function of its inputs):

1. the program runs in the sandbox (:func:`robocritics.program.run_program`) to a
   :class:`~robocritics.program.plan.Plan`: skill calls with their source lines;
2. the planner (:class:`robocritics.robot.planner.Planner`) turns each call into
   timed joint samples (IK, obstacle routing, jerk-limited timing, grasps);
3. the robot model (:meth:`robocritics.Robot.trajectory`) adds link frames and
   proximities, giving the :class:`~robocritics.trajectory.Trajectory` the critics
   read and the deploy gate streams.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from .errors import ProgramError, RobotModelError, SceneError
from .execution import Execution

if TYPE_CHECKING:  # pragma: no cover
    from .program.plan import Plan
    from .robot.model import Robot
    from .robot.planner import Event, MotionBudgetError, PlannerSettings
    from .scene import Scene
    from .trajectory import Trajectory

__all__ = ["simulate", "check_scene_ids", "Execution", "Event", "PlannerSettings", "MotionBudgetError"]


def __getattr__(name: str) -> Any:
    # The planner's types, re-exported without importing the planner (and Pinocchio)
    # when only `robocritics` is imported: `robocritics.simulate` is imported eagerly.
    if name in ("Event", "PlannerSettings", "MotionBudgetError"):
        from .robot import planner

        return getattr(planner, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


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
    [25, 500] (:data:`~robocritics.robot.motion.MIN_SAMPLE_RATE_HZ`,
    :data:`~robocritics.robot.motion.MAX_SAMPLE_RATE_HZ`: sparser sampling hides
    fast motion from the critics, denser is more than a controller executes).

    Raises :class:`SceneError` for a scene whose ids are names of the skill API (:func:`check_scene_ids`),
    :class:`ProgramError` for a program the sandbox rejects and
    :class:`PlanningError` (with the program line) for a motion that cannot be
    planned, such as an unreachable target, a speed below 1 % or a sample rate
    out of range. A motion beyond the budget of ``settings`` (5 min, 75,000
    samples, 400 MB by default; see :class:`PlannerSettings`) raises
    :class:`MotionBudgetError`, a PlanningError, before its samples are made.
    """
    from .program.plan import Plan
    from .program.sandbox import run_program
    from .robot.model import Robot
    from .robot.motion import check_sample_rate
    from .robot.planner import Planner, PlannerSettings
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
    robot = robot or Robot.ur3e()
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
    # frames and capsule endpoints in one FK pass (the endpoints straight from the frames' time series)
    frames, p0, p1 = robot.forward_with_capsules(q, opening)
    object_poses = planner.object_poses(frames[:, robot.tcp_index])
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
    final_scene = scene.model_copy(update={"objects": [planner.objects[o.id] for o in scene.objects]})
    for poses in object_poses.values():
        poses.setflags(write=False)
    return Execution(
        trajectory, plan, planner.events, final_scene, scene, robot, dict(planner.resting_on), dict(object_poses)
    )

