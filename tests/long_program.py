"""A palletising-like robot program of any length for the sorting scene: an apple carried from the table into
the brown box and back, ``repeats`` times (about 15.35 s of motion each at speed 0.5). Used by
tests/test_long_motion.py and benchmarks/bench_long.py."""

from __future__ import annotations

LOOP = """\
lib.set_speed(0.5)
apple = objects[0]
home_x, home_y, home_z = apple.x, apple.y, apple.z
for i in range({repeats}):
    lib.open_gripper()
    lib.move_above(apple, 0.10)
    lib.move_linear(apple.x, apple.y, apple.z)
    lib.close_gripper()
    lib.move_up(0.15)
    lib.move_to(brown_box.x, brown_box.y, brown_box.top + 0.12)
    lib.move_down(0.10)
    lib.open_gripper()
    lib.move_up(0.10)
    lib.move_above(apple, 0.10)
    lib.move_linear(apple.x, apple.y, apple.z)
    lib.close_gripper()
    lib.move_up(0.15)
    lib.move_to(home_x, home_y, home_z + 0.15)
    lib.move_down(0.15)
    lib.open_gripper()
    lib.move_up(0.10)
lib.home()
"""


def repeated_sorting(repeats: int) -> str:
    """The program source with its loop run ``repeats`` times."""
    return LOOP.format(repeats=int(repeats))
