# Shared workbench, written the way an LLM often writes it first: the operator is ignored,
# full speed everywhere, swinging the parts into the tray right in front of them.
for part, dx in [(bracket, -0.065), (spacer, 0.065)]:
    open_gripper()
    move_to(part.x, part.y, part.z + 0.1)
    move_down(0.1)
    close_gripper()
    move_up(0.1)
    move_to(tray.x + dx, tray.y, tray.top + 0.08)
    move_down(0.06)
    open_gripper()
    move_up(0.1)
home()
