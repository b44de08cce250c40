# Put both red apples in the brown box, one on top of the other, and the green apple in the white box.
# goals: red_apple_1 in brown_box; red_apple_2 in brown_box; green_apple in white_box
move_above(red_apple_1, 0.15)
move_down(0.15)
close_gripper()
move_up(0.15)
move_to(brown_box.x, brown_box.y, brown_box.top)
open_gripper()

move_above(red_apple_2, 0.15)
move_down(0.15)
close_gripper()
move_up(0.15)
move_to(brown_box.x, brown_box.y, brown_box.top + 0.02)
open_gripper()

move_above(green_apple, 0.15)
move_down(0.15)
close_gripper()
move_up(0.15)
move_to(white_box.x, white_box.y, white_box.top)
open_gripper()
home()
