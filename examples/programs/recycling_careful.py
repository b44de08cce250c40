# Recycling: put the coffee cup, the food container and the water bottle in
# the trash bin behind the table, without hitting anything on the way.
# Careful: each object is grasped just below its top, lifted straight up until
# it clears the bin's rim, carried at a moderate speed and released just above
# the bin.
lib.set_speed(0.3)


def discard(obj, dx, dy):
    height = 2 * (obj.top - obj.z)
    lib.open_gripper()
    lib.move_above(obj, 0.08)
    lib.reduce_speed(15)
    lib.move_linear(obj.x, obj.y, obj.top - 0.03)
    lib.close_gripper()
    # lift until the bottom of the object is 6 cm above the bin's rim
    lib.move_linear(obj.x, obj.y, trash_bin.top + 0.06 + height - 0.03)
    lib.set_speed(0.3)
    # release with the object's bottom 6 cm above the rim, each at its own spot
    lib.move_to(trash_bin.x + dx, trash_bin.y + dy, trash_bin.top + height + 0.03)
    lib.open_gripper()


# the tall bottle is released highest, so it gets the spot nearest the robot
discard(coffee_cup, -0.065, 0.05)
discard(food_container, 0.065, 0.05)
discard(water_bottle, 0.0, -0.06)

lib.home()
