# Breakfast, as an LLM might first write it: full speed, long plunges along
# the fingers, and the apple grabbed while the cupcake still sits on it.
move_to(fork.x, fork.y, 0.2)
move_down(0.18)
close_gripper()
move_to(trash_bin.x, trash_bin.y, 0.12)
open_gripper()

move_to(apple.x, apple.y, 0.25)
move_down(0.21)
close_gripper()
move_to(plate.x, plate.y + 0.045, 0.06)
open_gripper()

move_to(cupcake.x, cupcake.y, 0.25)
move_down(0.15)
close_gripper()
move_to(plate.x, plate.y - 0.045, 0.05)
open_gripper()
home()
