"""The motion budget: legal programs that ask for impossible motion get a typed error naming the line, before
any sample is made; speed fractions and sample rates have documented ranges.

Memory is measured with tracemalloc (allocation counts, not wall-clock time), so these tests hold on a loaded
machine.
"""

from __future__ import annotations

import math
import pickle
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from robocritics import PlanningError, ProgramError, Robot, Scene, simulate
from robocritics.program import Budget, run_program
from robocritics.critic import BUILTIN_CRITICS, critique
from robocritics.program.plan import Plan, SkillCall
from robocritics.planning import planner as planner_module
from robocritics.robot.arms import UR3E
from robocritics.planning.timing import (
    MAX_SAMPLE_RATE_HZ,
    MIN_SAMPLE_RATE_HZ,
    MIN_SPEED_FRACTION,
    check_sample_rate,
    sample_times,
)
from robocritics.planning.planner import (
    MotionBudgetError,
    Planner,
    PlannerSettings,
    plan_approach,
    trajectory_bytes,
    trajectory_bytes_per_sample,
)
from robocritics.trajectory import CHUNK_SAMPLES

SORTING = Scene.builtin("sorting")
EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "programs"
#: A duration budget of 5 min, for the tests of max_motion_s (the default budget bounds samples, not duration).
FIVE_MINUTES = PlannerSettings(max_motion_s=300.0)


def peak_bytes(fn):
    """(result or exception, peak bytes allocated while ``fn`` ran), measured by tracemalloc."""
    tracemalloc.start()
    try:
        try:
            result = fn()
        except Exception as exc:  # noqa: BLE001 - returned for the caller to check
            result = exc
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    return result, peak


# --- the cases ------------------------------------------------------------------------


def test_the_default_budget_bounds_samples_not_duration():
    # 2000 waits of 10 s are 5.6 h: the default budget refuses them at the call that passes a million samples
    # (2.2 h at 125 Hz), before its samples are made; a duration budget is the caller's choice
    program = run_program("for i in range(2000):\n    wait(10)\n", SORTING, Budget(clock=lambda: 0.0))
    error, peak = peak_bytes(lambda: simulate(program, SORTING))
    assert isinstance(error, MotionBudgetError) and error.limit == "max_samples" and error.line == 2, error
    assert "needs more than 1,000,000 samples" in str(error) and "2.2 h of motion at 125 Hz" in str(error)
    assert peak < 250e6, peak  # the 1,000,000 samples made: q, time and opening in the planner's parts
    defaults = PlannerSettings()
    assert (defaults.max_samples, defaults.max_motion_s) == (1_000_000, 86_400.0)


def test_two_thousand_waits_are_refused_with_the_whole_duration_and_little_memory():
    # the sandbox runs on a stopped clock: on a loaded machine its 0.5 s wall-clock budget could end the
    # 2000-iteration loop first, and this test is about the planner's motion budget
    program = run_program("for i in range(2000):\n    wait(10)\n", SORTING, Budget(clock=lambda: 0.0))
    error, peak = peak_bytes(lambda: simulate(program, SORTING, settings=FIVE_MINUTES))
    assert isinstance(error, MotionBudgetError), error
    assert error.limit == "max_motion_s" and error.line == 2
    assert str(error).startswith(
        "line 2: wait(seconds=10): the program's motion lasts 5.6 h; the limit is 5 min (PlannerSettings.max_motion_s)"
    )
    assert "Its waits alone add up to 5.6 h: wait less." in str(error)
    # the 5 min planned before the limit are 37,500 joint samples (~3 MB); the 5.6 h are never sampled
    assert peak < 60e6, peak


@pytest.mark.parametrize(
    "program, words",
    [
        ("reduce_speed(0.01)\nmove_to(0.3, 0.1, 0.2)\n", "reduce_speed: percent must be in 1 <= percent <= 100, got 0.01"),
        ("set_speed(1e-9)\nmove_to(0.3, 0.1, 0.2)\n", "set_speed: fraction must be in 0.01 <= fraction <= 1, got 1e-09"),
        ("set_speed(0.009)\nmove_to(0.3, 0.1, 0.2)\n", "set_speed: fraction must be in 0.01 <= fraction <= 1, got 0.009"),
    ],
)
def test_speeds_below_one_percent_are_refused_at_their_line(program, words):
    # the skill refuses them as the program runs (the planner refuses them too, for hand-built Plans)
    error, peak = peak_bytes(lambda: simulate(program, SORTING))
    assert type(error) is ProgramError and error.line == 1, error
    assert words in str(error)
    assert peak < 20e6


def test_the_slowest_speed_plans_and_its_long_motion_is_named():
    # 1 % is allowed; a hundred moves at 1 % are 100 min of motion: refused at the move that passes 5 min,
    # with the whole duration (every move timed, none sampled) and the speed as the hint
    program = "reduce_speed(1)\nfor i in range(50):\n    move_to(0.3, 0.1, 0.2)\n    move_to(0.3, -0.1, 0.2)\n"
    error, peak = peak_bytes(lambda: simulate(program, SORTING, settings=FIVE_MINUTES))
    assert isinstance(error, MotionBudgetError) and error.limit == "max_motion_s", error
    assert error.line == 3
    text = str(error)
    assert text.startswith("line 3: move_to(x=0.3, y=0.1, z=0.2): the program's motion lasts 10")  # 100-110 min
    assert " min; the limit is 5 min" in text and "at least" not in text
    assert "moves at 1 % of full speed here: raise the speed" in text
    assert peak < 60e6
    one_percent = simulate("reduce_speed(1)\nmove_to(0.3, 0.1, 0.2)\n", SORTING)
    full = simulate("move_to(0.3, 0.1, 0.2)\n", SORTING)
    assert one_percent.duration_s == pytest.approx(100 * full.duration_s, rel=1e-6)


@pytest.mark.parametrize("rate", [2, 24.99, 500.01, 1e7, math.nan, math.inf, -125, 0])
def test_sample_rates_outside_25_to_500_hz_are_refused(rate):
    error, peak = peak_bytes(lambda: simulate("move_to(0.3, 0.1, 0.2)\n", SORTING, sample_rate_hz=rate))
    assert type(error) is PlanningError, error
    assert "sample_rate_hz must lie in [25, 500] Hz" in str(error)
    assert peak < 20e6


def test_the_range_ends_are_allowed_and_documented():
    assert (MIN_SAMPLE_RATE_HZ, MAX_SAMPLE_RATE_HZ, MIN_SPEED_FRACTION) == (25.0, 500.0, 0.01)
    assert MAX_SAMPLE_RATE_HZ == UR3E.control_rate_hz
    for rate in (25, 500):
        assert len(simulate("move_to(0.3, 0.1, 0.2)\n", SORTING, sample_rate_hz=rate).trajectory) > 1
    with pytest.raises(PlanningError, match=r"a number of Hz"):
        check_sample_rate("fast")
    assert "sparser sampling hides fast motion" in str(pytest.raises(PlanningError, check_sample_rate, 2).value)


@pytest.mark.parametrize("program", ["sorting_naive.py", "recycling_naive.py", "breakfast_naive.py"])
def test_the_slowest_rate_gives_the_verdicts_of_the_fastest(program):
    # why 25 Hz is the floor: the example programs' flags are those at 500 Hz and peak link speeds agree to 1 %
    # (at 2 Hz the sorting example's end-effector Error vanished)
    scene = Scene.builtin(program.split("_")[0])
    source = (EXAMPLES / program).read_text()
    reports = [
        critique(simulate(source, scene, sample_rate_hz=rate), critics=list(BUILTIN_CRITICS)) for rate in (25, 500)
    ]
    slow, fast = ([v.flag for v in r.verdicts] for r in reports)
    assert slow == fast
    speed = [next(v.value for v in r.verdicts if v.critic == "joint_speed") for r in reports]
    assert speed[0] == pytest.approx(speed[1], rel=0.01)


# --- each limit names its field and its line ----------------------------------------------------


def test_the_sample_limit_is_checked_before_sampling():
    settings = PlannerSettings(max_samples=1_500)
    error, peak = peak_bytes(lambda: simulate("wait(5)\nwait(10)\nwait(5)\n", SORTING, settings=settings))
    assert isinstance(error, MotionBudgetError) and error.limit == "max_samples", error
    assert error.line == 2  # 625 + 1,250 samples pass 1,500 at the second wait
    assert "needs more than 1,500 samples (1,876 by the end of this call" in str(error)
    assert "the limit is 1,500 (PlannerSettings.max_samples)" in str(error)
    assert peak < 20e6


def test_the_memory_limit_is_checked_before_sampling_and_counts_the_scene():
    per_sample = trajectory_bytes_per_sample(Robot.ur3e(), SORTING)
    settings = PlannerSettings(max_trajectory_bytes=1_000 * per_sample)
    error = pytest.raises(MotionBudgetError, simulate, "wait(5)\nwait(5)\n", SORTING, settings=settings).value
    assert error.limit == "max_trajectory_bytes" and error.line == 2
    assert "for 14 scene shapes); the limit is" in str(error) and "(PlannerSettings.max_trajectory_bytes)" in str(error)
    # the same motion in an empty scene fits: each sample costs less
    empty = trajectory_bytes_per_sample(Robot.ur3e(), Scene())
    assert empty < per_sample
    assert simulate("wait(3)\n", Scene(), settings=PlannerSettings(max_trajectory_bytes=1_000 * per_sample))


def test_a_long_motion_costs_a_chunk_and_a_compact_sample_each():
    # beyond a chunk the estimate grows by the compact trajectory's bytes per sample, not the whole build's
    robot, scene = Robot.ur3e(), crowded_scene()
    per_sample = trajectory_bytes_per_sample(robot, scene)
    assert trajectory_bytes(robot, scene, 1000) == 1000 * per_sample
    n = CHUNK_SAMPLES * 10
    slope = trajectory_bytes(robot, scene, n + 1000) - trajectory_bytes(robot, scene, n)
    assert 0 < slope < 1000 * per_sample / 10
    # a memory limit below the estimate still refuses, before the samples are made
    program = "for i in range(40):\n    wait(10)\n"
    settings = PlannerSettings(max_trajectory_bytes=trajectory_bytes(robot, scene, 100_000))
    error, peak = peak_bytes(lambda: simulate(program, scene, sample_rate_hz=500, settings=settings))
    assert isinstance(error, MotionBudgetError) and error.limit == "max_trajectory_bytes", error
    assert f"{CHUNK_SAMPLES:,} at a time" in str(error)
    assert peak < 60e6


@pytest.mark.parametrize("exact_everywhere", [False, True])
def test_the_memory_estimate_is_above_the_measured_peak(monkeypatch, exact_everywhere):
    # the planner refuses on the estimate, so the estimate must not be below what simulate really takes. The
    # worst case is every pair measured exactly (far pairs otherwise get cheap lower bounds, planning.trace): there
    # the estimate must also be tight; with the far-pair bounds the peak is only lower
    if exact_everywhere:
        import math

        import robocritics.planning.trace as trace

        monkeypatch.setattr(trace, "EXACT_WITHIN_M", math.inf)
    robot = Robot.ur3e()
    carry = (
        "move_above(red_apple_1, 0.1)\nmove_to(red_apple_1)\nclose_gripper()\nmove_up(0.1)\n"
        "wait(10)\nmove_to(0.3, -0.1, 0.2)\nwait(10)\n"
    )
    boxes = Scene.model_validate(
        {
            "containers": [
                {"id": f"box_{i}", "size": [0.05, 0.05, 0.05], "position": [-0.6 + 0.06 * i, 0.5, 0.025]}
                for i in range(20)
            ]
        }
    )
    for scene, program, carried in ((SORTING, carry, 1), (boxes, "move_to(0.3, 0.1, 0.2)\nwait(10)\nwait(10)\n", 0)):
        simulate("move_to(0.3, 0.1, 0.2)\n", scene)  # imports and caches outside the measurement
        execution, peak = peak_bytes(lambda program=program, scene=scene: simulate(program, scene))
        assert not isinstance(execution, Exception), execution
        estimate = trajectory_bytes_per_sample(robot, scene, carried) * len(execution.trajectory)
        assert peak < estimate, (scene.name, peak, estimate)
        if exact_everywhere:
            assert estimate < 1.6 * peak, (scene.name, peak, estimate)


def test_a_program_far_over_budget_is_timed_within_a_bounded_amount_of_work(monkeypatch):
    # 1,800 lines at 1 % speed: once the budget is passed the rest is only timed, and that timing stops after
    # a fixed amount of work, so the message says "at least"
    monkeypatch.setattr(planner_module, "_TIMING_WORK", 300)
    program = "reduce_speed(1)\nfor i in range(900):\n    move_linear(0.3, -0.1, 0.2)\n    move_linear(0.3, 0.1, 0.2)\n"
    seen = []
    original = Planner.count_timing_work

    def counting(self, units=1):
        seen.append(units)
        original(self, units)

    monkeypatch.setattr(Planner, "count_timing_work", counting)
    error = pytest.raises(MotionBudgetError, simulate, program, SORTING, settings=FIVE_MINUTES).value
    assert error.limit == "max_motion_s" and error.line in (3, 4)
    assert "the program's motion lasts at least " in str(error)
    assert 300 < sum(seen) <= 300 + max(seen)  # the work that passes 300 units stops the timing


def test_ik_work_is_capped_before_solving(monkeypatch):
    # a straight line is solved every 5 mm: the count is checked before a line's grid is solved
    solves = []
    original, original_line = Robot.ik, Robot.ik_line

    def counting(self, *args, **kwargs):
        solves.append(1)
        return original(self, *args, **kwargs)

    def counting_line(self, positions, *args, **kwargs):  # a line's grid in one call: count its points
        solves.extend([1] * len(positions))
        return original_line(self, positions, *args, **kwargs)

    monkeypatch.setattr(Robot, "ik", counting)
    monkeypatch.setattr(Robot, "ik_line", counting_line)
    # lines of 0.203 m: 42 grid points each, whatever the last digit of the start pose
    program = "move_to(0.3, 0.1, 0.2)\nmove_linear(0.3, -0.103, 0.2)\nmove_linear(0.3, 0.1, 0.2)\n"
    error = pytest.raises(MotionBudgetError, simulate, program, SORTING, settings=PlannerSettings(max_ik_solves=60)).value
    assert error.limit == "max_ik_solves" and error.line == 3
    assert "needs more than 60 inverse-kinematics solutions by this call (85; straight lines are solved every 5 mm)" in str(error)
    assert 43 <= len(solves) < 60  # the move_to and the first line's 42 grid points; none of the second line's 42
    assert PlannerSettings().max_ik_solves == 100_000


def test_motion_budget_errors_survive_a_process_boundary():
    error = MotionBudgetError("too long", line=7, limit="max_motion_s")
    copy = pickle.loads(pickle.dumps(error))
    assert (type(copy), copy.line, copy.limit, str(copy)) == (MotionBudgetError, 7, "max_motion_s", "line 7: too long")
    assert isinstance(copy, PlanningError)


@pytest.mark.parametrize("field", ["max_motion_s", "max_samples", "max_trajectory_bytes", "gripper_time_s"])
@pytest.mark.parametrize("value", [0, -1, math.nan, math.inf, True, "10"])
def test_planner_settings_are_validated(field, value):
    with pytest.raises(ValueError, match=f"PlannerSettings.{field} must be a positive finite number"):
        PlannerSettings(**{field: value})


# --- plans built by trusted code go through the same checks --------------------------------------


@pytest.mark.parametrize(
    "call, error_type, words",
    [
        (SkillCall("wait", {"seconds": 1e12}, 5), MotionBudgetError, "wait(seconds=1e+12): the program's motion lasts"),
        (SkillCall("wait", {"seconds": math.nan}, 5), PlanningError, "seconds must be a number"),
        (SkillCall("set_speed", {"fraction": 0.0}, 5), PlanningError, "speed fraction must lie in [0.01, 1]"),
        (SkillCall("move_linear", {"target": (1e300, 0.0, 0.2)}, 5), PlanningError, "is out of reach"),
        (SkillCall("move_linear", {"target": (math.inf, 0.0, 0.2)}, 5), PlanningError, "is out of reach"),
    ],
)
def test_hostile_plans_are_refused_at_their_line(call, error_type, words):
    plan = Plan(source="", calls=[SkillCall("move_to", {"target": (0.3, 0.1, 0.2)}, 4), call], output=[])
    error, peak = peak_bytes(lambda: simulate(plan, SORTING))
    assert type(error) is error_type and error.line == 5, error
    assert words in str(error)
    assert peak < 20e6


def test_sample_times_refuses_before_allocating():
    error, peak = peak_bytes(lambda: sample_times(1e9, 500.0))
    assert isinstance(error, PlanningError) and "takes 500,000,000,000 samples; the limit is 1,000,000" in str(error)
    assert peak < 1e6
    assert np.array_equal(sample_times(0.02, 125.0), np.arange(3) * (1 / 125.0))


def test_the_approach_move_has_the_same_ranges_and_budget():
    robot = Robot.ur3e()
    goal = robot.home_q + 0.5
    with pytest.raises(PlanningError, match=r"speed_fraction must lie in \[0\.01, 1\]"):
        plan_approach(robot, robot.home_q, goal, speed_fraction=1e-9)
    with pytest.raises(PlanningError, match=r"sample_rate_hz must lie in \[25, 500\] Hz"):
        plan_approach(robot, robot.home_q, goal, sample_rate_hz=1e7)
    error = pytest.raises(
        MotionBudgetError, plan_approach, robot, robot.home_q, goal, speed_fraction=0.01, settings=PlannerSettings(max_motion_s=10)
    ).value
    assert error.limit == "max_motion_s" and "the approach lasts" in str(error) and "at 1 % of full speed" in str(error)
    q, t = plan_approach(robot, robot.home_q, goal)
    assert np.allclose(q[-1], goal) and np.all(np.diff(t) > 0)


def test_budget_checks_hold_in_eight_threads_at_once():
    # the planner keeps no global state: concurrent runs each get their own verdict
    from concurrent.futures import ThreadPoolExecutor

    programs = [
        ("for i in range(2000):\n    wait(10)\n", "max_motion_s"),
        ("set_speed(1e-9)\nmove_to(0.3, 0.1, 0.2)\n", "speed"),
        ("move_to(0.3, 0.1, 0.2)\nmove_to(0.3, -0.1, 0.2)\n", None),
        ("reduce_speed(1)\nfor i in range(20):\n    move_to(0.3, 0.1, 0.2)\n    move_to(0.3, -0.1, 0.2)\n", "max_motion_s"),
    ] * 2

    def one(case):
        program, expected = case
        try:
            return len(simulate(program, SORTING, settings=FIVE_MINUTES).trajectory) > 1, expected
        except MotionBudgetError as exc:
            return exc.limit, expected
        except (PlanningError, ProgramError) as exc:
            return "speed" if "0.01 <= fraction <= 1" in str(exc) else str(exc), expected

    with ThreadPoolExecutor(max_workers=8) as pool:
        results = list(pool.map(one, programs))
    for got, expected in results:
        assert got == (True if expected is None else expected)


def crowded_scene() -> Scene:
    """The sorting scene with 60 more boxes (as shapes: each box a floor and four walls)."""
    boxes = [
        {"id": f"box_{i}", "size": [0.05, 0.05, 0.05], "position": [-0.6 + 0.06 * (i % 20), 0.45 + 0.06 * (i // 20), 0.025]}
        for i in range(12)
    ]
    return SORTING.model_copy(update={"containers": list(SORTING.containers) + [Scene.model_validate({"containers": boxes}).containers[i] for i in range(12)]})
