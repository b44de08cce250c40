# Sort the apples: red (ripe) ones into the brown box, the green one into the white box.
# goals: red_apple_1 in brown_box; red_apple_2 in brown_box; green_apple in white_box
set_speed(1.0)
for apple in objects:
    box = brown_box if apple.colour == "red" else white_box
    move_to(apple.x, apple.y, apple.z + 0.18)
    move_down(0.18)
    close_gripper()
    move_up(0.18)
    move_to(box.x, box.y, box.top)
    open_gripper()
home()
