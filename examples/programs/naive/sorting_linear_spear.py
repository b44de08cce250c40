# Apple jam: ripe apples to the brown box, the unripe one to the white box.
# goals: red_apple_1 in brown_box; red_apple_2 in brown_box; green_apple in white_box
lib.set_speed(1.0)
for apple in objects:
    lib.move_to(apple.x, apple.y, 0.22)
    lib.move_linear(apple.x, apple.y, apple.z)
    lib.close_gripper()
    lib.move_linear(apple.x, apple.y, 0.22)
    target = brown_box if apple.ripeness == "ripe" else white_box
    lib.move_to(target.x, target.y, 0.22)
    lib.move_linear(target.x, target.y, target.top + 0.01)
    lib.open_gripper()
    lib.move_linear(target.x, target.y, 0.22)
lib.home()
