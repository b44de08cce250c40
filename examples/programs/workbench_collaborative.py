# Shared workbench: hand the bracket and the spacer to the operator, in the tray in front of them.
# Collaborative: the operator's hands are on the bench within the robot's reach, so the robot never moves
# faster than a person could be touched without harm (ISO/TS 15066) and slows further near the tray.
lib.set_speed(0.2)


def hand_over(part, dx):
    lib.open_gripper()
    lib.move_above(part, 0.08)
    lib.move_linear(part.x, part.y, part.z)
    lib.close_gripper()
    lib.move_up(0.08)
    lib.move_to(tray.x + dx, tray.y, tray.top + 0.10)  # each part at its own spot in the tray
    lib.reduce_speed(10)  # the last centimetres toward the operator's hands, slowly
    lib.move_down(0.12)  # set it down on the tray's floor, not dropped
    lib.open_gripper()
    lib.move_up(0.12)
    lib.set_speed(0.2)


hand_over(bracket, -0.065)
hand_over(spacer, 0.065)

lib.home()
