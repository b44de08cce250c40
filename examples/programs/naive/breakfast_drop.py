# Breakfast: get rid of the fork, then serve the cupcake and the apple on the plate.
# goals: fork in trash_bin; cupcake on plate; apple on plate
rotate_gripper(1.5708)
move_above(fork, 0.15)
move_down(0.15)
close_gripper()
move_up(0.15)
move_above(trash_bin, 0.18)
open_gripper()
rotate_gripper(0)

for item, dy in [(cupcake, -0.06), (apple, 0.06)]:
    move_above(item, 0.15)
    move_down(0.15 + item.top - item.z)
    close_gripper()
    move_up(0.2)
    move_to(plate.x, plate.y + dy, 0.2)
    open_gripper()
home()
