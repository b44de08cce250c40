"""The cycle-time example plugin's repair through the robocritics_repairs hook, verified by the other critics."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from robocritics.critic import get_critics
from robocritics.critic.plugins import pm
from robocritics.repair import repair
from robocritics.critic.verdict import Flag

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "examples" / "plugins" / "robocritics-cycle-time" / "src"))
import robocritics_cycle_time as cycle  # noqa: E402

PARAMS = {"cycle_time": {"target_cycle_time_s": 20.0, "max_cycle_time_s": 50.0}}


@pytest.fixture
def cycle_plugin():
    # the example module is the plugin: registered as its entry point would be, both hooks at once
    pm.register(cycle, name="test-cycle-time")
    try:
        yield
    finally:
        pm.unregister(cycle)


def test_cycle_time_repair_speeds_up_the_slowest_steps_without_new_flags(cycle_plugin):
    src = (ROOT / "examples" / "programs" / "sorting_careful.py").read_text()
    r = repair(src, "sorting", params=PARAMS, goal="green_apple in white_box")
    assert "cycle_time" in get_critics()
    assert r.changes, "the plugin's repair was not applied"
    assert all(c.critic == "cycle_time" for c in r.changes)
    assert all(c.cost_s < 0 for c in r.changes)  # faster
    cycle_verdict = next(v for v in r.report.verdicts if v.critic == "cycle_time")
    assert cycle_verdict.flag != Flag.ERROR and cycle_verdict.value <= 50.0
    assert all(v.flag == Flag.OK for v in r.report.verdicts if v.critic not in ("cycle_time",))
    assert r.execution.object_inside("green_apple", "white_box")
    assert f"line {r.changes[0].line}" in r.changes[0].what


class _BrokenRepairs:
    """A third-party plugin whose repair hook raises."""

    from robocritics.critic.hookspecs import hookimpl

    @staticmethod
    @hookimpl
    def robocritics_repairs(verdict, execution, program):
        raise RuntimeError("this plugin is broken")


def test_a_plugin_repair_that_raises_is_skipped_and_named(cycle_plugin, caplog):
    pm.register(_BrokenRepairs, name="broken-repairs")
    try:
        src = (ROOT / "examples" / "programs" / "sorting_careful.py").read_text()
        with caplog.at_level("WARNING", logger="robocritics.repair"):
            r = repair(src, "sorting", params=PARAMS, goal="green_apple in white_box")
    finally:
        pm.unregister(_BrokenRepairs)
    assert r.changes and all(c.critic == "cycle_time" for c in r.changes)  # the working plugin still repaired
    assert "broken-repairs" in caplog.text and "this plugin is broken" in caplog.text
