"""Loop.fix applies the critics' own repairs before asking the model (issue 13, item 2).

Against the real loopback OpenAI-compatible server (tests/llm_server.py): every
model call is a recorded HTTP request, so "no model call" is asserted on what
the server saw. Programs are really simulated and critiqued; what the repairs
achieve is not assumed but compared with :func:`robocritics.repair.repair`
run on its own (the reference), so the tests hold however good the repairs get.

The sorting naive program leaves the workspace (a space_usage Error the repairs
fix). ``DurationBudget`` is a critic no repair knows: an Error the model must fix.
"""

# ruff: noqa: F811  (pytest fixtures imported from llm_fixtures are parameters here)

from __future__ import annotations

from pathlib import Path

import pytest
from llm_fixtures import clean_llm_env, llm_server, make_client  # noqa: F401

from robocritics.critic import CriticParams, critique
from robocritics.errors import RoboCriticsError
from robocritics.llm.loop import Loop
from robocritics.llm.memory import InteractionMemory
from robocritics.repair import repair
from robocritics.scene import Scene
from robocritics.pipeline import simulate
from robocritics.critic.verdict import Flag, Verdict

pytestmark = pytest.mark.usefixtures("clean_llm_env")

PROGRAMS = Path(__file__).resolve().parent.parent / "examples" / "programs"
NAIVE = (PROGRAMS / "sorting_naive.py").read_text()
TASK = "sort the apples by ripeness: red apples into the brown box, the green apple into the white box"
#: The critic whose Error in the naive program the repairs fix (checked against repair() in `reference`).
REPAIRABLE = "space_usage"


class DurationBudget:
    """A plugin-style critic with no repair: Error when the motion lasts longer than a budget."""

    name = "duration_budget"
    description = "The whole motion must finish within a time budget."

    class Params(CriticParams):
        budget_s: float = 1.0  # far below any pick-and-place motion: always an Error here

    def check(self, trajectory, scene, params):
        duration_s = float(trajectory.time[-1] - trajectory.time[0])
        flag = Flag.ERROR if duration_s > params.budget_s else Flag.OK
        return Verdict(critic=self.name, flag=flag, message=f"The motion lasts {duration_s:.2f} s, over the "
                       f"{params.budget_s:g} s budget.", hint="Remove moves that are not needed.",
                       value=duration_s, threshold=params.budget_s, unit="s")  # fmt: skip


def fenced(program: str) -> str:
    return f"Here is the program:\n\n```python\n{program}```\n"


@pytest.fixture(scope="module")
def sorting() -> Scene:
    return Scene.builtin("sorting")


@pytest.fixture(scope="module")
def reference(sorting):
    """repair() on its own, with the critics the loops below use; the tests' precondition is checked here."""
    fixed = repair(NAIVE, sorting, critics=[REPAIRABLE])
    assert fixed.changes and fixed.report.verdict(REPAIRABLE).ok, "the repairs should fix the naive space_usage Error"
    return fixed


def test_faults_the_repairs_fix_are_fixed_without_a_model_call(llm_server, make_client, sorting, reference):
    llm_server.reply(fenced(NAIVE))
    seen = []
    loop = Loop(make_client(), sorting, critics=[REPAIRABLE], on_attempt=seen.append)
    first = loop.request(TASK)
    assert first.source == "llm" and first.report.verdict(REPAIRABLE).flag == Flag.ERROR
    fixed = loop.fix()
    assert len(llm_server.chat_requests()) == 1  # the task only: the Fix made no model call
    assert fixed.kind == "repair" and fixed.source == "repair" and fixed.index == 2 and fixed.approved is None
    assert fixed.prompt == "" and fixed.reply == ""
    assert fixed.program == reference.program and fixed.changes == reference.changes
    assert all(c.critic == REPAIRABLE for c in fixed.changes)
    assert fixed.diff.startswith("--- attempt 1\n+++ attempt 2 (critic repairs)\n")
    assert fixed.passed and loop.current is fixed and loop.attempts == [first, fixed] and seen == [first, fixed]
    assert "critic repair" in fixed.summary()
    # The attempt's report is the repaired program's, re-simulated and re-critiqued from scratch.
    again = critique(simulate(fixed.program, sorting), critics=[REPAIRABLE])
    assert again.score == fixed.score and again.verdict(REPAIRABLE).flag == fixed.report.verdict(REPAIRABLE).flag
    cost_s = sum(c.cost_s for c in fixed.changes)  # each change's cycle-time cost adds up to the whole
    assert fixed.execution.duration_s == pytest.approx(first.execution.duration_s + cost_s)


def test_what_the_repairs_leave_is_all_the_model_is_sent(llm_server, make_client, sorting, tmp_path):
    llm_server.reply(fenced(NAIVE), fenced(NAIVE))
    with InteractionMemory(tmp_path / "memory.sqlite") as memory:
        loop = Loop(make_client(), sorting, critics=[REPAIRABLE, DurationBudget()], memory=memory)
        first = loop.request(TASK)
        assert {v.critic for v in first.report.verdicts if v.flag == Flag.ERROR} == {REPAIRABLE, "duration_budget"}
        revision = loop.fix()
        requests = llm_server.chat_requests()
        assert len(requests) == 2  # the task, then one Fix request
        repaired = loop.attempts[1]
        assert [a.source for a in loop.attempts] == ["llm", "repair", "llm"] and revision is loop.attempts[2]
        assert revision.kind == "fix" and revision.changes == []
        assert repaired.report.verdict(REPAIRABLE).ok  # the repairs did their part (as in test 1) ...
        left = [v for v in repaired.report.verdicts if not v.ok]
        assert [v.critic for v in left] == ["duration_budget"]  # ... and left one Error no repair knows

        sent = requests[1].messages[-1]["content"]
        assert revision.prompt == sent
        for verdict in left:  # the remaining feedback, measured on the repaired program
            assert verdict.feedback() in sent
        before = first.report.verdict(REPAIRABLE)
        assert before.message not in sent and before.feedback() not in sent  # the repaired critic is not sent
        assert "Automatic repairs were applied" in sent  # the model is told its program changed ...
        for line in repaired.program.splitlines():  # ... and shown the repaired program, numbered
            if line.strip():
                assert line in sent

        rows = memory.history(loop.session)
        assert [r.source for r in rows] == ["llm", "repair", "llm"]
        assert [r.id for r in rows] == [a.memory_id for a in loop.attempts]
        assert rows[1].program == repaired.program and rows[1].score == repaired.score


def test_manual_approval_rejected_leaves_the_program_unchanged(llm_server, make_client, sorting, reference):
    llm_server.reply(fenced(NAIVE))
    asked: list[tuple[str, str]] = []

    def reject(program: str, diff: str) -> bool:
        asked.append((program, diff))
        return False

    memory = InteractionMemory(":memory:")
    loop = Loop(make_client(), sorting, critics=[REPAIRABLE], automation="manual", approve=reject, memory=memory)
    first = loop.request(TASK)
    rejected = loop.fix()
    assert asked == [(reference.program, rejected.diff)] and "(critic repairs)" in rejected.diff
    assert rejected.source == "repair" and rejected.approved is False
    assert rejected.report is None and rejected.execution is None and rejected.memory_id is None
    assert loop.current is first and loop.current.program == NAIVE  # the program in effect is unchanged
    assert "repair rejected" in rejected.summary()
    assert len(llm_server.chat_requests()) == 1  # manual: the model is never asked to fix
    assert [r.source for r in memory.history(loop.session)] == ["llm"]  # a rejected repair is not stored


def test_manual_fix_applies_approved_repairs_and_refuses_when_there_are_none(llm_server, make_client, sorting,
                                                                            reference):  # fmt: skip
    llm_server.reply(fenced(NAIVE))
    loop = Loop(make_client(), sorting, critics=[REPAIRABLE, DurationBudget()], automation="manual",
                approve=lambda program, diff: True)  # fmt: skip
    loop.request(TASK)
    fixed = loop.fix()
    assert fixed.source == "repair" and fixed.approved is True and loop.current is fixed
    assert fixed.report.verdict("duration_budget").flag == Flag.ERROR  # left, and not sent to the model
    with pytest.raises(RoboCriticsError, match="manual"):  # nothing left that a repair can change
        loop.fix()
    assert len(llm_server.chat_requests()) == 1
    off = Loop(make_client(), sorting, critics=[REPAIRABLE], automation="manual", repairs=False)
    llm_server.reply(fenced(NAIVE))
    off.request(TASK)
    with pytest.raises(RoboCriticsError, match="repairs are off"):
        off.fix()


def test_a_rejected_repair_in_guided_mode_sends_the_unrepaired_feedback(llm_server, make_client, sorting):
    llm_server.reply(fenced(NAIVE), "I cannot improve it.")
    decisions = iter([False])
    loop = Loop(make_client(), sorting, critics=[REPAIRABLE], approve=lambda p, d: next(decisions))
    first = loop.request(TASK)
    loop.fix()
    assert [a.source for a in loop.attempts] == ["llm", "repair", "llm"] and loop.attempts[1].approved is False
    sent = llm_server.chat_requests()[1].messages[-1]["content"]
    assert first.report.verdict(REPAIRABLE).feedback() in sent  # as if there had been no repair
    assert "Automatic repairs were applied" not in sent


def test_repairs_off_sends_everything_to_the_model(llm_server, make_client, sorting):
    llm_server.reply(fenced(NAIVE), fenced(NAIVE))
    loop = Loop(make_client(), sorting, critics=[REPAIRABLE], repairs=False)
    first = loop.request(TASK)
    again = loop.fix()
    assert [a.source for a in loop.attempts] == ["llm", "llm"] and again.kind == "fix"
    assert first.report.verdict(REPAIRABLE).feedback() in llm_server.chat_requests()[1].messages[-1]["content"]


def test_run_repairs_each_round_and_counts_only_model_replies(llm_server, make_client, sorting, reference):
    llm_server.reply(fenced(NAIVE))
    loop = Loop(make_client(), sorting, critics=[REPAIRABLE])
    best = loop.run(TASK, max_attempts=2)
    assert [a.source for a in loop.last_run] == ["llm", "repair"]  # all OK after the repair: the run stops
    assert best is loop.last_run[-1] and best.passed and best.program == reference.program
    assert len(llm_server.chat_requests()) == 1


def test_a_simulate_hook_checks_the_repaired_program(llm_server, make_client, sorting, reference):
    checked: list[str] = []

    def elsewhere(program: str):
        checked.append(program)
        execution = simulate(program, sorting)
        return execution, critique(execution, critics=[REPAIRABLE])

    llm_server.reply(fenced(NAIVE))
    loop = Loop(make_client(), sorting, critics=[REPAIRABLE], simulate=elsewhere)
    loop.request(TASK)
    fixed = loop.fix()
    assert checked == [NAIVE, reference.program]  # the repaired program went through the hook too
    assert fixed.passed and fixed.report.score == reference.report.score


def test_an_endpoint_failure_after_the_repair_keeps_it_and_the_fix_can_be_repeated(llm_server, make_client,
                                                                                   sorting):  # fmt: skip
    from llm_server import Fail

    from robocritics.errors import LLMError

    llm_server.reply(fenced(NAIVE))
    loop = Loop(make_client(max_retries=0), sorting, critics=[REPAIRABLE, DurationBudget()])
    loop.request(TASK)
    llm_server.script(Fail(400, body='{"error": {"message": "model crashed"}}'))
    with pytest.raises(LLMError, match="model crashed"):
        loop.fix()
    repaired = loop.current
    assert repaired.source == "repair" and [a.source for a in loop.attempts] == ["llm", "repair"]
    llm_server.reply(fenced(NAIVE))
    revision = loop.fix()  # the repaired program's remaining Error goes to the model; nothing is repaired twice
    assert [a.source for a in loop.attempts] == ["llm", "repair", "llm"] and revision is loop.last
    sent = llm_server.chat_requests()[-1].messages[-1]["content"]
    assert sent.count("Automatic repairs were applied") == 1
    assert repaired.report.verdict("duration_budget").feedback() in sent


def test_approve_raising_on_a_repair_changes_nothing(llm_server, make_client, sorting):
    llm_server.reply(fenced(NAIVE))

    def broken(program: str, diff: str) -> bool:
        raise KeyboardInterrupt  # e.g. the user closed the approval dialog with Ctrl-C

    memory = InteractionMemory(":memory:")
    loop = Loop(make_client(), sorting, critics=[REPAIRABLE], approve=broken, memory=memory)
    first = loop.request(TASK)
    with pytest.raises(KeyboardInterrupt):
        loop.fix()
    assert loop.attempts == [first] and loop.current is first and len(memory) == 1
    assert len(llm_server.chat_requests()) == 1


UNREACHABLE = """move_above(green_apple, height=0.42)
move_down(0.42)
close_gripper()
move_up(0.12)
move_above(white_box, 0.1)
open_gripper()
home()
"""


def test_a_program_that_does_not_run_is_repaired_before_the_model_hears_of_its_error(llm_server, make_client):
    scene = Scene.builtin("sorting")
    reference = repair(UNREACHABLE, scene)
    assert reference.changes and reference.execution is not None  # the runtime Error's repair makes it run
    llm_server.reply(fenced(UNREACHABLE), fenced(UNREACHABLE.replace("0.42", "0.1")))
    loop = Loop(make_client(), scene)
    first = loop.request(TASK)
    assert first.report is None and "line 1" in first.error  # out of reach: it did not run
    loop.fix()
    repaired = loop.attempts[1]
    assert repaired.source == "repair" and repaired.program == reference.program
    assert repaired.error is None and repaired.report is not None and repaired.report.score == reference.report.score
    # the repairs leave nothing (issue 26: Warnings too): the model never hears of the runtime error, nor is asked
    assert reference.errors == [] and reference.warnings == []
    assert len(llm_server.chat_requests()) == 1


def test_a_program_no_repair_can_make_run_goes_to_the_model_with_its_error(llm_server, make_client):
    scene = Scene.builtin("sorting")
    broken = "move_to(2.0, 0.0, 0.2)\nhome()\n"  # 2 m away: no height reaches it
    assert repair(broken, scene).execution is None
    llm_server.reply(fenced(broken), fenced("home()\n"))
    loop = Loop(make_client(), scene)
    loop.request(TASK)
    loop.fix()
    assert [a.source for a in loop.attempts] == ["llm", "llm"]
    assert "line 1" in llm_server.chat_requests()[1].text  # the runtime feedback, as without repairs
