# Sorting, written the way an LLM often writes it first: full speed,
# long fast descents along the fingers, straight into the boxes over their walls.
for apple in [red_apple_1, red_apple_2]:
    move_to(apple.x, apple.y, apple.z + 0.2)
    move_down(0.2)
    close_gripper()
    move_up(0.2)
    move_to(brown_box.x, brown_box.y, 0.09)
    open_gripper()

move_to(green_apple.x, green_apple.y, green_apple.z + 0.2)
move_down(0.2)
close_gripper()
move_up(0.2)
move_to(white_box.x, white_box.y, 0.09)
open_gripper()
home()
