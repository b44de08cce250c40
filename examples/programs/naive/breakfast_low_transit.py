# Serve breakfast: fork in the bin, cupcake and apple on the plate.
# goals: fork in trash_bin; cupcake on plate; apple on plate
rotate_gripper(1.5708)
move_above(fork, 0.1)
move_linear(fork.x, fork.y, fork.z)
close_gripper()
move_to(trash_bin.x, trash_bin.y, 0.1)
open_gripper()
rotate_gripper(0)

move_above(cupcake, 0.1)
move_linear(cupcake.x, cupcake.y, cupcake.z)
close_gripper()
move_to(plate.x, plate.y - 0.06, 0.05)
open_gripper()

move_above(apple, 0.1)
move_linear(apple.x, apple.y, apple.z)
close_gripper()
move_linear(plate.x, plate.y + 0.06, 0.06)
open_gripper()
home()
