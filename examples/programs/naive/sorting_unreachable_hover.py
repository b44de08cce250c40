# Sort the apples into the boxes by colour, hovering high above everything for safety.
# goals: red_apple_1 in brown_box; red_apple_2 in brown_box; green_apple in white_box
for apple in objects:
    move_to(apple.x, apple.y, 0.62)
    move_linear(apple.x, apple.y, apple.z)
    close_gripper()
    move_up(0.3)
    if apple.colour == "red":
        move_to(brown_box.x, brown_box.y, 0.2)
    else:
        move_to(white_box.x, white_box.y, 0.2)
    move_down(0.1)
    open_gripper()
home()
