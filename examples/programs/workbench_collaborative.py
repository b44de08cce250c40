# Shared workbench: hand the bracket and the spacer to the operator, in the tray in front of them.
# Collaborative: the operator's hands are on the bench within the robot's reach, so the robot never moves
# faster than a person could be touched without harm (ISO/TS 15066) and slows further near the tray.
lib.set_speed(0.08)


def hand_over(part):
    lib.open_gripper()
    lib.move_above(part, 0.08)
    lib.move_linear(part.x, part.y, part.z)
    lib.close_gripper()
    lib.move_up(0.08)
    lib.move_above(tray, 0.10)
    lib.reduce_speed(4)  # the last centimetres toward the operator's hands, slowly
    lib.move_down(0.08)
    lib.open_gripper()
    lib.move_up(0.08)
    lib.set_speed(0.08)


for part in [bracket, spacer]:
    hand_over(part)

lib.home()
