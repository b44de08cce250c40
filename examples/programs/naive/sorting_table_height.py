# Put the green apple in the white box and the red apples in the brown box.
# goals: green_apple in white_box; red_apple_1 in brown_box; red_apple_2 in brown_box
move_to(green_apple.x, green_apple.y, 0.15)
move_down(0.115)
close_gripper()
move_to(white_box.x, white_box.y, 0.06)
open_gripper()

for apple in [red_apple_1, red_apple_2]:
    move_to(apple.x, apple.y, 0.15)
    move_down(0.115)
    close_gripper()
    move_linear(brown_box.x, brown_box.y, 0.05)
    open_gripper()
    move_up(0.1)
home()
