"""Report: score arithmetic, JSON round trip, feedback text, terminal text, notebook HTML."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from robocritics.critic import ALL_PASSED, BUILTIN_CRITICS, Evidence, Flag, Report, Verdict, critique, make_signal
from robocritics.errors import CriticError
from robocritics.critic.report import format_score
from robocritics.scene import Scene
from robocritics.trajectory import Step
from synth import FRAME_NAMES, line_motion, make_trajectory, realistic_trajectory


def verdict(name, flag, message="m", hint="", **kw):
    return Verdict(critic=name, flag=flag, message=message, hint=hint, **kw)


def report_of(flags, names=BUILTIN_CRITICS):
    return Report(verdicts=[verdict(n, f) for n, f in zip(names, flags)], trajectory_hash="0" * 64)


def test_flag_scores():
    assert (Flag.OK.score, Flag.WARNING.score, Flag.ERROR.score) == (2, 1, 0)
    assert Flag.worst([Flag.OK, Flag.ERROR, Flag.WARNING]) is Flag.ERROR


@pytest.mark.parametrize(
    "flags, score",
    [
        ([Flag.OK] * 5, 10),
        ([Flag.ERROR] * 5, 0),
        ([Flag.OK, Flag.WARNING, Flag.ERROR, Flag.OK, Flag.OK], 7),
        ([Flag.WARNING] * 5, 5),
    ],
)
def test_score_of_the_five_builtins_is_the_sum(flags, score):
    r = report_of(flags)
    assert r.score == score
    assert r.has_errors == (Flag.ERROR in flags)


def test_score_is_the_motion_critics_index_and_other_critics_stand_beside_it():
    five = [Flag.OK, Flag.WARNING, Flag.OK, Flag.OK, Flag.OK]  # 9/10
    r = report_of(five + [Flag.ERROR, Flag.WARNING], names=[*BUILTIN_CRITICS, "cycle_time", "noise"])
    assert r.score == 9  # the plugins' verdicts do not move the index ...
    assert [v.critic for v in r.other_verdicts] == ["cycle_time", "noise"]
    assert [v.critic for v in r.scored_verdicts] == list(BUILTIN_CRITICS)
    assert r.has_errors and not r.passed  # ... but they count toward pass/fail
    assert r.summary().startswith("RoboCritics report: score 9/10 (1 error, 2 warnings); beside the score: cycle_time Error, noise Warning;")
    assert report_of(five).other_verdicts == [] and not report_of(five).has_errors
    assert report_of([Flag.OK] * 5).passed and not report_of(five).passed


def test_score_of_some_of_the_five_is_scaled_to_ten():
    r = report_of([Flag.OK, Flag.WARNING, Flag.ERROR])  # space_usage, collision, joint_speed: 3 of 6 points
    assert r.score == pytest.approx(5.0)
    r = report_of([Flag.WARNING, Flag.OK, Flag.ERROR], names=["joint_speed", "cycle_time", "pinch_point"])
    assert r.score == pytest.approx(2.5)  # 1 of 4 points; cycle_time OK beside it
    assert [v.critic for v in r.other_verdicts] == ["cycle_time"]


def test_a_report_without_the_five_scores_its_own_critics():
    r = report_of([Flag.OK, Flag.WARNING, Flag.ERROR], names=["a", "b", "c"])
    assert r.score == pytest.approx(5.0)  # 3 of 6 points
    assert r.other_verdicts == [] and "beside the score" not in r.summary()
    r = report_of([Flag.OK, Flag.WARNING, Flag.OK, Flag.OK, Flag.OK, Flag.WARNING], names=list("abcdef"))
    assert r.score == pytest.approx(10 * 10 / 12, abs=0.01)
    assert report_of([Flag.WARNING], names=["a"]).score == 5.0
    assert Report(verdicts=[], trajectory_hash="h").score == 10.0


@pytest.mark.parametrize("score, text", [(10.0, "10/10"), (7, "7/10"), (8.33, "8.3/10"), (0.0, "0/10"), (None, "-")])
def test_one_score_format(score, text):
    assert format_score(score) == text


def test_score_text_is_the_formatted_score():
    assert report_of([Flag.OK, Flag.WARNING, Flag.ERROR, Flag.OK, Flag.OK]).score_text == "7/10"
    assert report_of([Flag.OK, Flag.WARNING, Flag.WARNING]).score_text == "6.7/10"


def test_lists_and_lookup():
    r = report_of([Flag.OK, Flag.WARNING, Flag.ERROR, Flag.OK, Flag.WARNING])
    assert [v.critic for v in r.errors] == ["joint_speed"]
    assert [v.critic for v in r.warnings] == ["collision", "pinch_point"]
    assert r.flag_of("collision") is Flag.WARNING
    assert r.flag is Flag.ERROR
    with pytest.raises(CriticError, match=r"no verdict of critic 'colision' in this report; did you mean 'collision'\? \(critics that ran: space_usage, "):
        r.flag_of("colision")
    with pytest.raises(CriticError, match=r"no verdict of critic 'cycle_time' in this report \(critics that ran: space_usage, "):
        r.verdict("cycle_time")


def sorting_like_report():
    steps = [Step(skill="home", line=1), Step(skill="move_to", line=4), Step(skill="move_down", line=5), Step(skill="move_to", line=6)]
    time, pos = line_motion(1.2, rate_hz=125)
    T = len(time)
    positions = np.tile(np.array([0.1, 0.0, 0.2]), (T, len(FRAME_NAMES), 1))
    positions[:, FRAME_NAMES.index("wrist_3_link")] = pos[:, 0]
    step = np.clip(np.arange(T) * 4 // T, 1, 3)
    step[0] = 0
    traj = make_trajectory(time, positions, steps=steps, step=step)
    return traj, critique(traj, Scene(), critics=BUILTIN_CRITICS)


def test_report_binds_the_trajectory_and_records_params():
    traj, r = sorting_like_report()
    assert r.trajectory_hash == traj.content_hash()
    assert r.samples == len(traj) and r.duration_s == pytest.approx(traj.duration_s)
    assert r.critics == list(BUILTIN_CRITICS)
    assert r.params["joint_speed"]["warn_speed_m_s"] == 1.0


def test_feedback_in_the_papers_style_with_lines_and_skills():
    traj, r = sorting_like_report()
    assert r.flag_of("joint_speed") is Flag.WARNING
    text = r.feedback()
    line = next(l for l in text.splitlines() if "Joint speed" in l)
    assert line.startswith("Warning: Joint speed is higher than the recommended value of 1 m/s (1.20 m/s at the wrist_3_link")
    assert "during [move_to, move_down] actions on lines 4-6" in line
    assert line.endswith("This potentially increases the cycle time of the program.")
    assert r.feedback(["joint_speed"]) == line
    assert r.feedback(["pinch_point"]) == ALL_PASSED
    with pytest.raises(CriticError, match="did you mean 'joint_speed'"):
        r.feedback(["joint_sped"])


def test_feedback_lists_errors_first_and_only_non_ok():
    r = Report(
        verdicts=[
            verdict("a", Flag.WARNING, "warned.", "fix a."),
            verdict("b", Flag.OK, "fine."),
            verdict("c", Flag.ERROR, "broken.", "fix c."),
        ],
        trajectory_hash="x",
    )
    assert r.feedback() == "Error: broken. fix c.\nWarning: warned. fix a."
    assert report_of([Flag.OK] * 5).feedback() == ALL_PASSED


def test_json_round_trip():
    traj, r = sorting_like_report()
    text = r.to_json()
    data = json.loads(text)
    assert data["score"] == r.score and data["trajectory_hash"] == traj.content_hash()
    back = Report.from_json(text)
    assert back == r
    assert back.score == r.score and back.feedback() == r.feedback()
    assert back.verdicts[0].signal == r.verdicts[0].signal
    with pytest.raises(CriticError, match="not a robocritics report"):
        Report.from_json("{}")


def test_text_rendering_names_every_critic_and_the_score():
    traj, r = sorting_like_report()
    text = str(r)
    assert text == r.to_text()
    assert text.splitlines()[0].startswith(f"RoboCritics report: score 7/10 (1 error, 1 warning); {len(traj)} samples")
    for name in BUILTIN_CRITICS:
        assert name in text
    assert "Hint: To minimize joint speed" in text


def test_html_has_a_table_and_an_svg_per_signal():
    r = critique(realistic_trajectory(duration_s=4.0, rate_hz=250.0, n_waypoints=3), Scene.builtin("sorting"), critics=BUILTIN_CRITICS)
    html = r._repr_html_()
    assert "<table" in html and html.count("<svg") == sum(v.signal is not None for v in r.verdicts) >= 4
    assert "<polyline" in html and "stroke-dasharray" in html
    for v in r.verdicts:
        assert v.critic in html


def test_svg_escapes_text_and_handles_gaps():
    sig = make_signal(np.arange(5.0), np.array([1.0, np.nan, 0.5, 0.2, np.inf]), label="<d>", unit="m", warning=0.3, worse="below")
    assert sig.value[1] is None and sig.value[4] is None
    r = Report(verdicts=[verdict("x", Flag.OK, signal=sig)], trajectory_hash="h")
    html = r._repr_html_()
    assert "&lt;d&gt;" in html and "<d>" not in html


def test_signal_downsampling_keeps_extremes():
    t = np.arange(10_000) / 500.0
    v = np.sin(t)
    v[1234] = 5.0
    v[8765] = -5.0
    hi = make_signal(t, v, label="s", unit="m/s")
    lo = make_signal(t, v, label="d", unit="m", worse="below")
    assert len(hi.value) <= 400 and len(lo.value) <= 400
    assert max(hi.value) == 5.0 and t[1234] in hi.time_s
    assert min(lo.value) == -5.0
    assert hi.time_s[0] == t[0] and hi.time_s[-1] == t[-1]


def test_evidence_defaults_are_empty():
    e = Evidence()
    assert e.lines == [] and e.worst_sample is None


@settings(max_examples=200, deadline=None, derandomize=True)
@given(
    values=hnp.arrays(np.float64, st.integers(1, 900), elements=st.floats(allow_nan=True, allow_infinity=True)),
    worse=st.sampled_from(["above", "below"]),
)
def test_signal_lists_are_the_per_sample_python_floats(values, worse):
    """make_signal converts with tolist(): the same Python floats as float(x) per sample, None where not finite."""
    t = np.cumsum(np.full(len(values), 0.002))
    sig = make_signal(t, values, label="x", unit="m", worse=worse)
    if len(values) <= 400:
        kept_t, kept_v = t, values
    else:  # the picks are the samples whose times survived
        pick = np.searchsorted(t, sig.time_s)
        kept_t, kept_v = t[pick], values[pick]
    assert sig.time_s == [float(x) for x in kept_t]
    assert all(type(x) is float for x in sig.time_s)
    want = [float(v) if np.isfinite(v) else None for v in kept_v]
    assert sig.value == want
    assert all(v is None or type(v) is float for v in sig.value)
