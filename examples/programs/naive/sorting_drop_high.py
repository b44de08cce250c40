# Sort apples by ripeness: ripe ones go in the brown box, unripe ones in the white box.
# goals: red_apple_1 in brown_box; red_apple_2 in brown_box; green_apple in white_box
for apple in objects:
    move_above(apple, 0.2)
    move_linear(apple.x, apple.y, apple.z)
    close_gripper()
    move_up(0.2)
    if apple.ripeness == "ripe":
        move_above(brown_box, 0.2)
    else:
        move_above(white_box, 0.2)
    open_gripper()
home()
