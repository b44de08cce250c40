"""contact_speed: the ISO/TS 15066 transient-contact limits on real UR3e motion past an operator."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from cobot_sweep import execution

from robocritics.critic import Flag, critique
from robocritics.critic.builtin.contact_speed import ContactSpeedCritic, Params, contact_speeds
from robocritics.scene import Scene
from robocritics.pipeline import simulate

PAPER = ["joint_speed", "space_usage", "collision", "end_effector_pose", "pinch_point"]
EXAMPLES = Path(__file__).parent.parent / "examples" / "programs"


@pytest.fixture(scope="module")
def fast():
    return execution(1.0)


def test_a_sweep_past_the_abdomen_at_1_m_s_passes_the_paper_critics_but_is_flagged(fast):
    report = critique(fast, critics=PAPER + ["contact_speed"])
    flags = {v.critic: v.flag for v in report.verdicts}
    assert all(flags[c] is Flag.OK for c in PAPER), report.summary()
    verdict = next(v for v in report.verdicts if v.critic == "contact_speed")
    assert verdict.flag is Flag.ERROR
    assert not report.passed and report.score == 10  # beside the score, not in it; it fails the run
    # the evidence names the region, the part, the speed and the limit
    d = verdict.details
    assert d["human"] == "operator" and d["region"] in {"chest", "abdomen", "pelvis"} and d["part"]
    assert d["speed_m_s"] > d["limit_m_s"] and d["region"].split("_")[0] in verdict.message
    assert f"{d['limit_m_s']:.3f} m/s" in verdict.message and verdict.evidence.links == [d["part"]]
    # and the abdomen itself is approached at more than the warning fraction of its own limit
    (body, speed, limit, _), = contact_speeds(fast, Params())
    k = body.names.index("abdomen")
    assert speed[:, :, k].max() > 0.75 * limit[:, k].min()


def test_the_same_sweep_at_25_mm_s_or_far_away_is_not_flagged():
    for run in (execution(0.025), execution(1.0, distance_m=2.5)):
        report = critique(run, critics=["contact_speed"])
        assert report.critics == ["contact_speed", "separation"]  # both asked for by a scene with people
        assert report.passed, report.summary()


def test_closing_in_on_the_head_is_an_error_at_any_speed(fast):
    # put the robot's sweep at the operator's head height: lower the person by the head-abdomen height difference
    scene = fast.scene
    op = scene.humans[0]
    low = op.model_copy(update={"floor_z_m": op.floor_z_m - (0.94 - 0.60) * op.height_m})
    slow = execution(0.025, distance_m=op.position[0])
    moved = Scene(humans=[low])
    from dataclasses import replace

    verdict = ContactSpeedCritic().check(replace(slow, scene=moved, final_scene=moved), Params())
    assert verdict.flag is Flag.ERROR and verdict.threshold == 0.0
    assert verdict.details["region"] in {"skull_forehead", "face"}, verdict.message


def test_a_reference_loop_over_samples_gives_the_same_worst_contact(fast):
    from robocritics.critic.builtin.cobot import part_body_distances, part_speeds, robot_parts
    from robocritics.humans import scene_bodies

    (body, speed, _, _), = contact_speeds(fast, Params())
    parts = robot_parts(fast)
    d = part_body_distances(parts, scene_bodies(fast.scene)[0])
    v = part_speeds(parts, fast.trajectory.time)
    ref = np.zeros_like(speed)
    for t in range(1, len(d)):
        for p in range(d.shape[1]):
            for k in range(d.shape[2]):
                if d[t, p, k] < d[t - 1, p, k] and d[t, p, k] <= 0.1:
                    ref[t, p, k] = v[t, p]
    assert np.array_equal(ref, speed)


def test_no_people_nothing_to_check_and_not_requested_by_default():
    run = simulate("home()\n", Scene.builtin("sorting"))
    assert "contact_speed" not in critique(run).critics
    verdict = critique(run, critics=["contact_speed"]).verdicts[0]
    assert verdict.flag is Flag.OK and "nothing to check" in verdict.message


def test_the_workbench_examples_are_judged_as_intended():
    scene = Scene.builtin("workbench")
    careful = critique(simulate((EXAMPLES / "workbench_collaborative.py").read_text(), scene))
    naive = critique(simulate((EXAMPLES / "workbench_naive.py").read_text(), scene))
    assert {"contact_speed", "separation", "payload"} <= set(careful.critics)
    assert careful.passed, careful.summary()
    assert not naive.passed and naive.has_errors
    assert {v.critic for v in naive.verdicts if v.flag is not Flag.OK} & {"contact_speed", "separation"}
