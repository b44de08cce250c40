# Sorting: the green apple goes to the white box, the red ones to the brown box.
# goals: green_apple in white_box; red_apple_1 in brown_box; red_apple_2 in brown_box
# red_apple_2 is carried past the green apple straight to the box at low height
move_to(red_apple_2.x, red_apple_2.y, 0.2)
move_down(0.165)
close_gripper()
move_to(red_apple_2.x, red_apple_2.y, 0.08)
move_to(brown_box.x, brown_box.y, 0.08)
open_gripper()

move_to(green_apple.x, green_apple.y, 0.2)
move_down(0.165)
close_gripper()
move_linear(white_box.x, white_box.y, 0.07)
open_gripper()

move_to(red_apple_1.x, red_apple_1.y, 0.2)
move_down(0.165)
close_gripper()
move_linear(brown_box.x, brown_box.y, 0.07)
open_gripper()
home()
