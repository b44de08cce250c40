"""Shared assertions for the critic tests."""

from __future__ import annotations

import math

import pytest

from robocritics.critic import Flag, get_critics


def critic(name: str):
    return get_critics()[name]


def run(name: str, traj, scene=None, **overrides):
    c = critic(name)
    params = c.Params(**overrides)
    return c.check(execution_of(traj, scene), params)


def execution_of(traj, scene=None):
    """The run a critic judges: ``traj`` in ``scene`` (default an empty scene), no plan, no robot."""
    from robocritics.critic import as_execution
    from robocritics.scene import Scene

    return as_execution(traj, scene or Scene())


def assert_matches_reference(verdict, ref, rel: float = 1e-9) -> None:
    """Same flag and worst value as the per-sample reference."""
    if ref["value"] is None:
        assert verdict.value is None
    else:
        assert verdict.value is not None and math.isfinite(verdict.value)
        assert verdict.value == pytest.approx(ref["value"], rel=rel, abs=1e-12)
    assert verdict.flag is ref["flag"], (verdict.flag, ref, verdict.message)


def assert_well_formed(verdict, name: str) -> None:
    """Every verdict names its critic, says something, and carries evidence for non-OK flags."""
    assert verdict.critic == name
    assert verdict.message
    if verdict.flag is not Flag.OK:
        assert verdict.hint
        assert verdict.value is not None and verdict.threshold is not None and verdict.unit
        ev = verdict.evidence
        assert ev.worst_sample is not None and ev.time_window_s is not None
        assert ev.first_sample is not None and ev.first_sample <= ev.worst_sample <= ev.last_sample
    if verdict.signal is not None:
        assert len(verdict.signal.time_s) == len(verdict.signal.value) <= 400
