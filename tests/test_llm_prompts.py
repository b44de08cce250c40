"""Prompts: system prompt (API, scene, rules, embedded critic rules, memory), fix and runtime feedback."""

from __future__ import annotations

from pathlib import Path

import pytest

from robocritics.critic import critique, get_critics
from robocritics.errors import CriticError, PlanningError, ProgramError
from robocritics.llm.memory import InteractionMemory
from robocritics.llm.prompts import (
    COMPLETE_MARKER,
    REVIEW_INSTRUCTION,
    critic_rules,
    describe_scene,
    extract_code,
    fix_prompt,
    format_memory_examples,
    numbered_program,
    request_prompt,
    runtime_feedback,
    says_complete,
    system_prompt,
)
from robocritics.program.language import SAFE_BUILTINS
from robocritics.program.sandbox import run_program
from robocritics.pipeline import simulate
from robocritics.program.skills import SKILLS, api_reference
from robocritics.scene import Scene

PROGRAMS = Path(__file__).resolve().parent.parent / "examples" / "programs"
# The paper's five motion critics: pinned, so an installed plugin does not change what the tests expect.
MOTION_CRITICS = ["joint_speed", "end_effector_pose", "collision", "pinch_point", "space_usage"]


@pytest.fixture(scope="module")
def naive_sorting():
    """(program, report) of the naive sorting example: one simulation for the module."""
    scene = Scene.builtin("sorting")
    program = (PROGRAMS / "sorting_naive.py").read_text()
    execution = simulate(program, scene)
    return program, critique(execution.trajectory, scene, MOTION_CRITICS)


# --- system prompt --------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["sorting", "recycling", "breakfast"])
def test_system_prompt_lists_api_and_every_scene_entity(name):
    scene = Scene.builtin(name)
    text = system_prompt(scene)
    assert api_reference().strip() in text
    for skill in SKILLS:
        assert f"{skill}(" in text
    for obj in scene.objects:
        line = next(line for line in text.splitlines() if line.startswith(f"- {obj.id}:"))
        assert obj.shape in line
        for coordinate in obj.position:
            assert f"{coordinate:.3f}"[:5] in line  # millimetres (a fourth decimal may follow)
        assert f"top z = {obj.top:.3f}"[:13] in line
        for key, value in obj.attributes.items():
            assert f"{key}={value}" in line
        assert ("NOT graspable" in line) is (not obj.graspable)
    for container in scene.containers:
        line = next(line for line in text.splitlines() if line.startswith(f"- {container.id}:"))
        assert f"rim (top) z = {container.top:.3f}" in line
        assert f"inside floor z = {container.floor_top:.3f}"[:22] in line
        for key, value in container.attributes.items():
            assert f"{key}={value}" in line
    assert "Table: top surface at z = 0.000 m" in text
    assert "metres" in text and "robot base frame" in text
    assert "Allowed workspace" in text
    # the sandbox's own list of builtins, every one of them
    assert "the builtins " + ", ".join(SAFE_BUILTINS) + "." in " ".join(text.split())
    # the rules of the conversation
    assert "```python" in text
    assert COMPLETE_MARKER in text
    assert "no other imports" in text
    # no embedded rules or memory unless asked for
    assert REVIEW_INSTRUCTION not in text
    assert "past interaction" not in text.lower()


def test_describe_scene_mentions_rotation_yaw_and_empty_sections():
    scene = Scene.model_validate(
        {
            "name": "odd",
            "objects": [{"id": "block", "shape": "box", "size": [0.05, 0.05, 0.05], "position": [0.3, 0, 0.025], "rpy": [0, 0, 0.5]}],
            "containers": [],
        }
    )
    text = describe_scene(scene)
    assert "rotated rpy (0.000, 0.000, 0.500) rad" in text
    assert "Containers" in text and "- (none)" in text


def test_embedded_rules_come_from_the_critics_params():
    text = system_prompt(Scene.builtin("sorting"), embedded_rules=True)
    assert REVIEW_INSTRUCTION in text
    critics = get_critics()
    for name, critic in critics.items():
        assert f"- {name}: {critic.description}" in text
        defaults = critic.Params()
        for field in type(defaults).model_fields:
            value = getattr(defaults, field)
            if isinstance(value, (int, float)) and not isinstance(value, bool) and "tolerance" not in field:
                assert f"{field} = {value:g}" in text, (name, field)


def test_embedded_rules_follow_overrides_and_selection():
    text = critic_rules(["joint_speed"], {"joint_speed": {"warn_speed_m_s": 0.8}})
    assert "warn_speed_m_s = 0.8" in text
    assert "- joint_speed:" in text and "- collision:" not in text
    assert "(source:" not in text  # provenance notes are for people, not the model
    with pytest.raises(CriticError, match="did you mean 'joint_speed'"):
        critic_rules(["joint_sped"])


def test_memory_examples_are_compact(tmp_path):
    long_program = "\n".join(f"move_to(0.3, 0.0, 0.{i:02d})" for i in range(100)) + "\n"
    with InteractionMemory(tmp_path / "m.sqlite") as memory:
        memory.add("s", "sort the apples by ripeness", long_program, "Warning: " + "slow down " * 200, 7.0)
        memory.add("s", "put the cup away", "home()\n", "", None)
        examples = memory.search("sort the apples", k=3) + memory.search("cup", k=1)
    text = system_prompt(Scene.builtin("sorting"), memory_examples=examples)
    assert "# Relevant past interactions" in text
    assert "Request: sort the apples by ripeness" in text
    assert "Score: 7/10" in text and "Score: not scored" in text
    assert "move_to(0.3, 0.0, 0.00)" in text and "move_to(0.3, 0.0, 0.99)" not in text
    assert "# ... (60 more lines)" in text
    feedback_line = next(line for line in text.splitlines() if line.startswith("Critic feedback: Warning"))
    assert len(feedback_line) < 700 and feedback_line.endswith("...")
    # mappings work too; items without a program are skipped
    assert format_memory_examples([{"request": "r", "program": "", "feedback": "", "score": 1}]) == ""
    assert "Request: r" in format_memory_examples([{"request": "r", "program": "home()", "feedback": "", "score": 10}])


# --- user turns -----------------------------------------------------------------------------


def test_request_prompt():
    assert request_prompt("  put the green apple in the white box ") == (
        "Task: put the green apple in the white box\n\nWrite the complete program."
    )


def test_fix_prompt_carries_the_feedback_and_marks_the_lines(naive_sorting):
    program, report = naive_sorting
    flagged = [v for v in report.verdicts if not v.ok]
    assert flagged, "the naive example should be criticised"
    text = fix_prompt(report, program=program)
    assert report.feedback() in text
    lines = program.splitlines()
    for v in flagged:
        for n in v.evidence.lines:
            assert f">> {n:>2} | {lines[n - 1]}".rstrip() in text
    assert "complete revised program" in text
    # restricted to one critic: only its message, only its lines marked
    one = flagged[0]
    text = fix_prompt(report, [one.critic], program=program)
    assert one.message in text
    for other in flagged[1:]:
        assert other.message not in text
    marked = {int(line.split("|")[0].strip(" >")) for line in text.splitlines() if line.startswith(">>")}
    assert marked == set(one.evidence.lines)
    # without the program: the feedback only
    assert "Your program" not in fix_prompt(report)


def test_numbered_program_context():
    program = "\n".join(f"line{i}" for i in range(1, 21)) + "\n"
    text = numbered_program(program, [10], context=1)
    assert text.splitlines() == ["    9 | line9", ">> 10 | line10", "   11 | line11"]
    text = numbered_program(program, [3, 10], context=0)
    assert text.splitlines() == [">>  3 | line3", "    ...", ">> 10 | line10"]
    assert len(numbered_program(program).splitlines()) == 20


def test_runtime_feedback_for_a_sandbox_rejection():
    program = "move_to(0.3, 0.0, 0.2)\nimport os\nos.system('rm -rf /')\n"
    with pytest.raises(ProgramError) as info:
        run_program(program, Scene.builtin("sorting"))
    text = runtime_feedback(info.value, program=program)
    assert f"line {info.value.line}" in text
    assert info.value.reason in text
    assert "import os" in text  # the offending line is quoted
    assert "before the robot moved" in text
    assert "```python" in text


def test_runtime_feedback_for_an_unreachable_target():
    program = "move_to(0.3, 0.0, 0.2)\nmove_to(0.95, 0.0, 0.2)\n"
    with pytest.raises(PlanningError) as info:
        simulate(program, Scene.builtin("sorting"))
    assert info.value.line == 2
    text = runtime_feedback(info.value, program=program)
    assert "line 2" in text and info.value.reason in text
    assert ">> 2 | move_to(0.95, 0.0, 0.2)" in text
    assert "reach" in text


def test_runtime_feedback_for_a_reply_without_code():
    text = runtime_feedback(None, reply="I am sorry, but as a language model I cannot move robots. " * 10)
    assert "no Python program" in text
    assert 'your reply began: "I am sorry' in text
    assert len(text) < 600
    assert "```python" in text and COMPLETE_MARKER in text


def test_says_complete_and_extract_code():
    assert says_complete("PROGRAM COMPLETE")
    assert says_complete("I reviewed it. Program complete.")
    assert says_complete("program_complete")
    assert not says_complete("The program is complete enough?")
    assert not says_complete("")
    assert extract_code("```python\nhome()\n```") == "home()\n"
