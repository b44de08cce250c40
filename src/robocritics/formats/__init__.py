"""Motion from other tools, judged by the same critics: URScript programs, recorded trajectories, rosbag2 files;
and the export of a checked trajectory to URScript, JointTrajectory JSON or CSV.

:func:`load_motion` turns a file into the :class:`~robocritics.simulate.Execution` the critics read
(``plan`` is None, ``source`` says where the motion came from); then :func:`robocritics.critique` as usual::

    from robocritics import Robot, Scene, critique
    from robocritics.formats import load_motion

    execution = load_motion("pick.script", robot=Robot.ur3e(), scene=Scene.builtin("sorting"))
    print(critique(execution).to_text())
"""

from __future__ import annotations

from .load import MOTION_SUFFIXES, URSCRIPT_SUFFIXES, load_motion, motion_kind

__all__ = ["load_motion", "motion_kind", "MOTION_SUFFIXES", "URSCRIPT_SUFFIXES"]
