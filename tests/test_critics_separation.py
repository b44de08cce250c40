"""separation: ISO/TS 15066 5.5.4 protective separation distance, worked by hand and on real UR3e motion."""

from __future__ import annotations

import pytest
from cobot_sweep import execution

from robocritics.critic import Flag, critique
from robocritics.critic.builtin.separation import Params, protective_separation
from robocritics.robot.arms import UR3E


def _separation(report):
    return next(v for v in report.verdicts if v.critic == "separation")


def test_protective_separation_worked_by_hand():
    # S_p = v_h (T_r + T_s) + v_r T_r + v_r T_s + C + Z_d + Z_r, with the defaults and the UR3e's data:
    # v_h 1.6 m/s, T_r 0.1 s, T_s 0.159 s (the worst of joints 0-2), C 0.208 m, Z_d 0.1 m, Z_r 0.00003 m
    t_s = max(UR3E.stopping_time_s)
    assert t_s == 0.159 and UR3E.pose_repeatability_m == 0.00003
    s_p = protective_separation(1.0, Params(), t_s, 0.00003)
    assert s_p == pytest.approx(1.6 * 0.259 + 0.1 + 0.159 + 0.208 + 0.1 + 0.00003, abs=1e-12)  # 0.98143 m
    assert protective_separation(0.0, Params(), t_s, 0.00003) == pytest.approx(0.4144 + 0.30803, abs=1e-12)


def test_a_fast_sweep_next_to_the_operator_is_an_error_naming_the_distances():
    verdict = _separation(critique(execution(1.0), critics=["separation"]))
    assert verdict.flag is Flag.ERROR
    d = verdict.details
    assert d["separation_m"] < d["protective_separation_m"] and d["robot_speed_m_s"] > 0.25
    assert verdict.value == d["separation_m"] and verdict.threshold == d["protective_separation_m"]
    assert "operator" in verdict.message and verdict.evidence.samples_flagged > 0


def test_the_same_sweep_slow_or_with_the_operator_far_away_keeps_the_distance():
    slow = critique(execution(0.025), critics=["separation"])
    assert [v.flag for v in slow.verdicts] == [Flag.OK, Flag.OK]
    far = _separation(critique(execution(1.0, distance_m=2.5), critics=["separation"]))
    assert far.flag is Flag.OK and far.value > far.threshold


def test_a_longer_reaction_time_widens_the_distance():
    run = execution(1.0, distance_m=1.9)
    quick = critique(run, critics=["separation"], params={"separation": {"reaction_time_s": 0.0}})
    slow = critique(run, critics=["separation"], params={"separation": {"reaction_time_s": 1.0}})
    q, s = _separation(quick), _separation(slow)
    assert s.threshold > q.threshold + 1.5
    assert q.flag is Flag.OK and s.flag is Flag.ERROR


@pytest.mark.parametrize("speed, distance", [(1.0, None), (0.5, 0.9), (1.0, 2.5)])
def test_pruned_distances_equal_the_full_computation(speed, distance):
    """The bounding-sphere pruning of contact_speed and separation against every pair computed exactly."""
    import numpy as np

    from robocritics.critic.builtin.cobot import part_body_distances, part_body_nearest, robot_parts
    from robocritics.humans import scene_bodies

    run = execution(speed, distance_m=distance)
    parts = robot_parts(run)
    body = scene_bodies(run.scene)[0]
    full = part_body_distances(parts, body)
    assert np.allclose(part_body_nearest(parts, body), full.min(axis=2), rtol=0, atol=1e-12)
    for within in (0.0, 0.1, 0.5):
        pruned = part_body_distances(parts, body, within_m=within)
        exact = (full <= within) | np.vstack([(full <= within)[1:], np.zeros((1,) + full.shape[1:], bool)])
        assert np.allclose(pruned[exact], full[exact], rtol=0, atol=1e-12)
        assert np.all(pruned[~exact] > within) and np.all(pruned <= full + 1e-12)  # a lower bound elsewhere


def test_the_repair_slows_the_flagged_moves_of_the_naive_workbench_program_out_of_error():
    from pathlib import Path

    from robocritics.repair import repair
    from robocritics.scene import Scene

    program = (Path(__file__).parent.parent / "examples" / "programs" / "workbench_naive.py").read_text()
    result = repair(program, Scene.builtin("workbench"))
    assert not result.report.has_errors, result.report.summary()
    kept = [c for c in result.changes if c.critic in ("separation", "contact_speed")]
    assert kept and "set_speed(" in result.program
    assert _separation(result.report).flag is Flag.OK
