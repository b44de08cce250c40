# Sorting ("apple jam"): ripe (red) apples go to the brown box for jam,
# the unripe green apple goes to the white box.
# Careful: moderate speed in free space, slow straight approaches along the
# fingers, grasp at the apple's centre, release low inside the box.
lib.set_speed(0.3)


def pick(obj):
    lib.open_gripper()
    lib.move_above(obj, 0.10)
    lib.reduce_speed(15)
    lib.move_linear(obj.x, obj.y, obj.z)
    lib.close_gripper()
    lib.move_up(0.15)
    lib.set_speed(0.3)


def place_in(box, spot):
    # release low inside the box, each apple at its own spot
    dx, dy = spot
    lib.move_to(box.x + dx, box.y + dy, box.top + 0.12)
    lib.reduce_speed(15)
    lib.move_down(0.12)
    lib.open_gripper()
    lib.move_up(0.12)
    lib.set_speed(0.3)


spots = {"brown_box": [(-0.05, -0.05), (0.05, 0.05)], "white_box": [(0.0, 0.0)]}
for apple in objects:
    pick(apple)
    box = brown_box if apple.ripeness == "ripe" else white_box
    place_in(box, spots[box.id].pop())

lib.home()
