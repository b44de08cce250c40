"""URScript: the parser and interpreter (hostile scripts too), UR's timing formulas, the subset's semantics."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from robocritics import Robot, Scene, critique
from robocritics.errors import PlanningError
from robocritics.formats.urscript import ArmOptions, UnsupportedURScript, URScriptError, parse, run_urscript
from robocritics.formats.urscript import poses as P
from robocritics.formats.urscript.timing import trapezoid_duration

ROBOT = Robot.ur3e()
SCENE = ROBOT.scene_for(Scene())
HOME = "[0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]"


def run(source: str, **kw):
    options = kw.pop("options", None)
    return run_urscript(source, ROBOT, SCENE, options, **kw)


# ------------------------------------------------------------------ timing against the hand-worked formulas


def test_movej_trapezoid_duration_matches_the_formula_within_1_percent():
    # base joint 1.0 rad, a = 1.4 rad/s², v = 1.05 rad/s: 1.0 >= v²/a = 0.7875, so T = d/v + v/a = 0.95238 + 0.75
    q0 = ROBOT.home_q
    q1 = q0 + np.array([1.0, 0.3, -0.2, 0, 0, 0])
    e = run(f"movej({q1.tolist()}, a=1.4, v=1.05)")
    expected = 1.0 / 1.05 + 1.05 / 1.4
    assert e.duration_s == pytest.approx(expected, rel=0.01)
    # every joint starts and stops together: at half time each has covered half its travel
    half = np.argmin(np.abs(e.trajectory.time - expected / 2))
    np.testing.assert_allclose(e.trajectory.q[half] - q0, (q1 - q0) / 2, atol=0.01)
    np.testing.assert_allclose(e.trajectory.q[-1], q1, atol=1e-9)


def test_movej_triangular_profile_and_the_time_argument():
    q0 = ROBOT.home_q
    short = (q0 + [0.2, 0, 0, 0, 0, 0]).tolist()  # 0.2 < v²/a: never reaches v, T = 2 sqrt(d / a)
    assert run(f"movej({short}, a=1.4, v=1.05)").duration_s == pytest.approx(2 * math.sqrt(0.2 / 1.4), rel=0.01)
    assert run(f"movej({short}, a=1.4, v=1.05, t=3.0)").duration_s == pytest.approx(3.0, rel=0.01)
    # t too short for `a`: the acceleration rises to fit; the duration is still t
    assert run(f"movej({short}, a=0.1, v=1.05, t=0.5)").duration_s == pytest.approx(0.5, rel=0.01)


def test_movel_is_trapezoidal_along_a_straight_tool_path():
    start = P.matrix_pose(ROBOT.tcp_pose(ROBOT.home_q))
    e = run(f"movel(pose_add(get_actual_tcp_pose(), p[0, 0.1, 0, 0, 0, 0]), a=1.2, v=0.25)")
    # 0.1 m >= v²/a = 0.052: T = 0.1 / 0.25 + 0.25 / 1.2
    assert e.duration_s == pytest.approx(0.1 / 0.25 + 0.25 / 1.2, rel=0.01)
    tcp = e.trajectory.tcp[:, :3, 3]
    np.testing.assert_allclose(tcp[:, [0, 2]], np.broadcast_to(np.array(start)[[0, 2]], (len(tcp), 2)), atol=1e-5)
    speed = np.linalg.norm(np.diff(tcp, axis=0), axis=1) / np.diff(e.trajectory.time)
    assert speed.max() == pytest.approx(0.25, rel=0.02)


def test_blend_radius_shortens_the_motion_and_keeps_it_continuous():
    a = "[0.3, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]"
    b = "[0.6, -1.3708, 1.3708, -1.5708, -1.5708, 0.0]"
    stop = run(f"movej({HOME})\nmovej({a})\nmovej({b})")
    blended = run(f"movej({HOME})\nmovej({a}, r=0.05)\nmovej({b})")
    assert blended.duration_s < stop.duration_s - 0.1
    np.testing.assert_allclose(blended.trajectory.q[-1], stop.trajectory.q[-1], atol=1e-9)
    speed = np.abs(np.diff(blended.trajectory.q, axis=0)) / np.diff(blended.trajectory.time)[:, None]
    assert speed.max() <= 1.05 * 1.05 + 1e-6  # superposed, never faster than both moves together


def test_servoj_follows_its_targets_with_their_timing():
    e = run(
        f"movej({HOME})\nq = get_actual_joint_positions()\ni = 0\nwhile i < 250:\n  q[0] = q[0] + 0.002\n"
        "  servoj(q, t=0.008, lookahead_time=0.1, gain=300)\n  i = i + 1\nend\n"
    )
    servo = [s for s in e.trajectory.steps if s.skill == "servoj"]
    assert [s.line for s in servo] == [6]
    t_servo = e.trajectory.time[e.trajectory.step == e.trajectory.steps.index(servo[0])]
    assert t_servo[-1] - t_servo[0] == pytest.approx(250 * 0.008, abs=0.3)  # plus the settling at the end
    assert e.trajectory.q[-1, 0] == pytest.approx(0.5, abs=1e-4)


# ------------------------------------------------------------------ semantics


def test_evidence_names_the_script_lines():
    e = run(f"movej({HOME})\nsleep(0.2)\nmovel(pose_add(get_actual_tcp_pose(), p[0, 0, -0.05, 0, 0, 0]))\n")
    assert [(s.skill, s.line) for s in e.trajectory.steps] == [("movej", 1), ("sleep", 2), ("movel", 3)]
    last = len(e.trajectory) - 1
    assert e.trajectory.lines([last]) == [3] and e.trajectory.lines([0]) == [1]
    assert e.plan is None and e.source.startswith("URScript")


def test_a_file_that_is_one_def_runs_it_and_an_endless_loop_is_judged_for_the_passes_asked():
    src = f"def prog():\n  while (True):\n    movej({HOME})\n    movej([0.3, -1.5708, 1.5708, -1.5708, -1.5708, 0.0])\n  end\nend\n"
    one, three = run(src), run(src, passes=3)
    assert "loops forever; judged 1 pass" in one.source and "judged 3 pass" in three.source
    a_pass = run(f"movej([0.3, -1.5708, 1.5708, -1.5708, -1.5708, 0.0])\nmovej({HOME})\nmovej([0.3, -1.5708, 1.5708, -1.5708, -1.5708, 0.0])\n")
    lap = a_pass.duration_s - run("movej([0.3, -1.5708, 1.5708, -1.5708, -1.5708, 0.0])\n").duration_s
    assert three.duration_s == pytest.approx(one.duration_s + 2 * lap, rel=0.01)


def test_threads_counting_are_ignored_and_a_moving_thread_is_refused_with_its_line():
    counting = f"global n = 0\nthread count():\n  while True:\n    n = n + 1\n    sync()\n  end\nend\nrun count()\nmovej({HOME})\n"
    assert "thread count commands no motion" in run(counting).source
    unused = f"thread mover():\n  movej({HOME})\nend\nmovej({HOME})\n"
    assert run(unused).duration_s >= 0  # defined, never run: never refused
    moving = unused + "t = run mover()\n"
    with pytest.raises(UnsupportedURScript, match=r"thread mover commanding motion \(movej at line 2\)") as info:
        run(moving)
    assert info.value.line == 5


def test_switch_case_if_elif_for_and_functions():
    src = (
        "def pick(i):\n  if i == 0:\n    return 0.1\n  elif i == 1:\n    return 0.2\n  else:\n    return 0.3\n  end\nend\n"
        "total = 0\nfor i in range(0, 3):\n  total = total + pick(i)\nend\nx = 2\nswitch x:\n  case 1:\n    total = 0\n"
        "  case 2:\n    total = total * 2\n  default:\n    total = -1\nend\n"
        "movej([total, -1.5708, 1.5708, -1.5708, -1.5708, 0.0])\n"
    )
    assert run(src).trajectory.q[-1, 0] == pytest.approx(1.2)


def test_gripper_calls_and_the_gripper_output():
    e = run(f"movej({HOME})\nrq_close_and_wait()\nrq_move_and_wait(128)\nrq_open()\n")
    g = e.trajectory.gripper_opening_m
    assert g[0] == pytest.approx(ROBOT.max_opening_m) and g.min() == pytest.approx(0.0)
    assert g[-1] == pytest.approx(ROBOT.max_opening_m)
    io = "movej(%s)\nset_digital_out(2, True)\nsleep(0.1)\n" % HOME
    assert run(io).trajectory.gripper_opening_m[-1] == pytest.approx(ROBOT.max_opening_m)  # no --gripper-io
    closed = run(io, options=ArmOptions(gripper_io=2)).trajectory.gripper_opening_m[-1]
    assert closed == pytest.approx(0.0)


def test_set_tcp_in_the_script_wins_over_the_installation_tcp():
    src = "movej(get_inverse_kin(p[-0.25, -0.1, 0.2, 0, 3.14159, 0]))\n"
    flange_tcp = run(src, options=ArmOptions(tcp=(0, 0, 0, 0, 0, 0)))
    long_tcp = run("set_tcp(p[0, 0, 0.1, 0, 0, 0])\n" + src, options=ArmOptions(tcp=(0, 0, 0, 0, 0, 0)))
    flange = lambda e: ROBOT.tcp_pose(e.trajectory.q[-1]) @ np.linalg.inv(ROBOT.tcp_in_flange)  # noqa: E731
    np.testing.assert_allclose(flange(flange_tcp)[:3, 3], [-0.25, -0.1, 0.2], atol=1e-6)
    np.testing.assert_allclose(flange(long_tcp)[:3, 3], [-0.25, -0.1, 0.3], atol=1e-6)  # TCP 0.1 m below


def test_queries_read_the_simulated_state():
    e = run(
        f"movej({HOME})\nq = get_actual_joint_positions()\nx = get_forward_kin(q)\nq2 = get_inverse_kin(x, qnear=q)\n"
        "if pose_dist(x, get_actual_tcp_pose()) < 1e-9 and norm(q2[0] - q[0]) < 1e-4:\n  movej([0.4, -1.5708, 1.5708, -1.5708, -1.5708, 0.0])\nend\n"
    )
    assert e.trajectory.q[-1, 0] == pytest.approx(0.4)


def test_an_unreachable_target_is_a_planning_error_with_its_line():
    with pytest.raises(PlanningError) as info:
        run(f"movej({HOME})\nmovel(p[0.9, 0, 0.2, 0, 3.14, 0])\n")
    assert info.value.line == 2


@pytest.mark.parametrize(
    "source, construct, line",
    [
        ("movej(%s)\nforce_mode(p[0,0,0,0,0,0], [0,0,1,0,0,0], [0,0,5,0,0,0], 2, [1,1,1,1,1,1])\n" % HOME, "force_mode()", 2),
        ("x = 1\n\nspeedl([0, 0, 0.1, 0, 0, 0], 0.5, 1)\n", "speedl()", 3),
        ("movej(%s)\nr = my_urcap_call(3)\n" % HOME, "my_urcap_call()", 2),
        ("a = camera()\n", "camera()", 1),
        ("x = p[0,0,0,0,0,0]\ny = x.pose\n", "struct field access", 2),
        ("for i in list:\n  sleep(1)\nend\n", "for loop over", 1),
    ],
)
def test_constructs_outside_the_subset_are_refused_with_their_line(source, construct, line):
    with pytest.raises(UnsupportedURScript) as info:
        run(source)
    assert construct in str(info.value) and info.value.line == line


# ------------------------------------------------------------------ hostile scripts: every cost bounded


def test_deep_nesting_is_a_typed_error_not_a_recursion_error():
    deep = "".join(f"{' ' * i}if True:\n" for i in range(200)) + "sleep(1)\n" + "end\n" * 200
    with pytest.raises(URScriptError, match="nest more than"):
        parse(deep)
    with pytest.raises(URScriptError, match="nest more than"):
        parse("x = " + "(" * 5000 + "1" + ")" * 5000 + "\n")
    with pytest.raises(URScriptError, match="nest more than"):
        parse("x = " + "-" * 5000 + "1\n")


def test_an_endless_loop_without_motion_hits_the_step_budget_naming_the_loop():
    with pytest.raises(URScriptError, match=r"did not finish within .* steps \(in the loop at line 2\)"):
        run(f"x = 0\nwhile x >= 0:\n  x = x + 1\nend\nmovej({HOME})\n", max_steps=20_000)


def test_recursion_is_bounded():
    with pytest.raises(URScriptError, match="calls nest more than"):
        run(f"def f(n):\n  return f(n + 1)\nend\nf(0)\nmovej({HOME})\n")
    # recursion through deeply nested blocks: bounded before Python's own recursion limit
    deep = "".join(" " * i + "if True:\n" for i in range(60)) + "f()\n" + "end\n" * 60
    with pytest.raises(URScriptError, match="nest more than"):
        run("def f():\n" + deep + f"end\nf()\nmovej({HOME})\n")
    # a thread reaching motion through a long chain of functions is found without recursion
    n = 3000
    chain = "".join(f"def f{i}():\n  f{i + 1}()\nend\n" for i in range(n)) + f"def f{n}():\n  movej({HOME})\nend\n"
    with pytest.raises(UnsupportedURScript, match=f"movej at line {3 * n + 2}"):
        run(chain + "thread t():\n  f0()\nend\nrun t()\n")


def test_huge_lists_and_strings_are_bounded():
    with pytest.raises(URScriptError, match="list"):
        run("x = make_list(100000000, 0)\n")
    with pytest.raises(URScriptError, match="list literal with more than"):
        parse("x = [" + ",".join(["1"] * 20_000) + "]\n")
    with pytest.raises(URScriptError, match="string longer"):
        run('s = "x"\nwhile True:\n  s = str_cat(s, s)\nend\n', passes=100)


def test_too_much_motion_is_refused_before_its_samples_are_made():
    with pytest.raises(URScriptError, match="takes the motion beyond the 300 s"):
        run("i = 0\nwhile i < 1000:\n  sleep(1.0)\n  i = i + 1\nend\n")


@pytest.mark.parametrize(
    "source, message",
    [
        ("movej([1e308, 0, 0, 0, 0, 0])\n", "finite joint angles"),
        ("movej([9.0, 0, 0, 0, 0, 0])\n", r"joint 0 \(shoulder_pan_joint\) = 9.0000 rad is outside its limits"),
        ("x = 1e308 * 10\n", "overflows"),
        ("x = 1e999\n", "out of range"),
        ('x = to_num("nan")\n', "not a finite number"),
        ("movej(%s, t=1e9)\n" % HOME, "beyond the 300 s one check"),
        ("sleep(1e300)\n", "beyond the 300 s one check"),
        ("movel(p[1e10, 0, 0, 0, 0, 0])\n", "beyond the 300 s one check"),
        ("movej(%s, a=1e-12)\n" % HOME.replace("0.0]", "1.0]"), "beyond the 300 s one check"),
        ("i = 0\nwhile i < 100000:\n  servoj(%s, t=0.1)\n  i = i + 1\nend\n" % HOME, "servo stream lasts more"),
        ("set_tcp(p[1e300, 0, 0, 0, 0, 0])\n", "within 2 m"),
        ("movej(%s, a=0)\n" % HOME, "a must be positive"),
    ],
)
def test_hostile_numbers_are_typed_errors_before_any_sample_is_made(source, message):
    with pytest.raises(URScriptError, match=message):
        run(source)


def test_syntax_errors_name_the_line():
    with pytest.raises(URScriptError) as info:
        run(f"movej({HOME})\nif x\n  sleep(1)\nend\n")
    assert info.value.line == 2
    with pytest.raises(URScriptError, match="ends inside a block"):
        parse("def f():\n  sleep(1)\n")
    with pytest.raises(URScriptError, match="no motion"):
        run("textmsg(1)\n")


def test_integers_wrap_like_the_controllers_32_bit_ints():
    e = run(f"x = 2147483647\nx = x + 1\nif x < 0:\n  movej({HOME})\nend\n")
    assert len(e.trajectory) > 1


# ------------------------------------------------------------------ pose arithmetic


poses_strategy = st.lists(st.floats(-1.0, 1.0), min_size=6, max_size=6).map(P.Pose)


@settings(max_examples=60, deadline=None)
@given(poses_strategy, poses_strategy)
def test_pose_functions_follow_their_matrix_definitions(a, b):
    Ta, Tb = P.pose_matrix(a), P.pose_matrix(b)
    np.testing.assert_allclose(P.pose_matrix(P.pose_trans(a, b)), Ta @ Tb, atol=1e-9)
    np.testing.assert_allclose(P.pose_matrix(P.pose_inv(a)), np.linalg.inv(Ta), atol=1e-9)
    added = P.pose_matrix(P.pose_add(a, b))
    np.testing.assert_allclose(added[:3, 3], Ta[:3, 3] + Tb[:3, 3], atol=1e-12)
    np.testing.assert_allclose(added[:3, :3], Ta[:3, :3] @ Tb[:3, :3], atol=1e-9)
    np.testing.assert_allclose(P.pose_matrix(P.pose_add(P.pose_sub(a, b), b)), Ta, atol=1e-9)


@settings(max_examples=60, deadline=None)
@given(st.floats(-3.0, 3.0), st.floats(-1.5, 1.5), st.floats(-3.0, 3.0))
def test_rpy_and_rotation_vectors_round_trip(roll, pitch, yaw):
    R = P.rotvec_to_matrix(P.rpy2rotvec([roll, pitch, yaw]))
    c = math.cos
    s = math.sin
    Rx = np.array([[1, 0, 0], [0, c(roll), -s(roll)], [0, s(roll), c(roll)]])
    Ry = np.array([[c(pitch), 0, s(pitch)], [0, 1, 0], [-s(pitch), 0, c(pitch)]])
    Rz = np.array([[c(yaw), -s(yaw), 0], [s(yaw), c(yaw), 0], [0, 0, 1]])
    np.testing.assert_allclose(R, Rz @ Ry @ Rx, atol=1e-9)
    np.testing.assert_allclose(P.rotvec_to_matrix(P.rpy2rotvec(P.rotvec2rpy(P.matrix_to_rotvec(R)))), R, atol=1e-9)


def test_trapezoid_duration_formula():
    assert trapezoid_duration(2.0, 1.0, 2.0) == pytest.approx(2.0 / 1.0 + 1.0 / 2.0)
    assert trapezoid_duration(0.1, 1.0, 2.0) == pytest.approx(2 * math.sqrt(0.1 / 2.0))
    assert trapezoid_duration(0.0, 1.0, 2.0) == 0.0


def test_a_script_is_judged_by_the_critics():
    report = critique(run(f"movej({HOME}, a=10, v=3.0)\n"))
    assert report.source.startswith("URScript") and "motion from URScript" in report.to_text()
    speed = next(v for v in report.verdicts if v.critic == "joint_speed")
    assert speed.flag.value != "OK" and speed.evidence.lines == [1]


TOKENS = [
    "movej(", "movel(", "servoj(", "sleep(", "p[", "[", "]", "(", ")", ",", ":", "\n", "def f():", "end", "if ", "elif ",
    "else:", "while ", "for i in range(3):", "switch x:", "case 1:", "default:", "return ", "break", "x", "y", " = ",
    "1", "0.2", "-", "+", "*", "/", "%", " and ", " or ", " not ", "True", "False", '"s"', "global ", "local ",
    "thread t():", "run t()", "get_actual_joint_positions()", "get_actual_tcp_pose()", "pose_trans(", "halt",
    "$ 1 \"m\"", "#c", "a=", "t=", "r=", "x[0]", ".", "rq_close()", "textmsg(", "make_list(", "str_cat(",
]  # fmt: skip


@settings(max_examples=300, deadline=None)
@given(st.lists(st.sampled_from(TOKENS), max_size=60))
def test_any_token_soup_is_judged_or_a_typed_error(tokens):
    source = "".join(tokens)
    try:
        run(source, max_steps=5_000)
    except (URScriptError, PlanningError):
        pass
