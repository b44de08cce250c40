# Recycling: put the coffee cup, the food container and the water bottle in
# the trash bin behind the table, without hitting anything on the way.
# Careful: each object is grasped just below its top, lifted straight up until
# it clears the bin's rim, carried at a moderate speed and released just above
# the bin.
lib.set_speed(0.3)


def discard(obj):
    height = 2 * (obj.top - obj.z)
    lib.open_gripper()
    lib.move_above(obj, 0.08)
    lib.reduce_speed(15)
    lib.move_linear(obj.x, obj.y, obj.top - 0.03)
    lib.close_gripper()
    # lift until the bottom of the object is 5 cm above the bin's rim
    lib.move_linear(obj.x, obj.y, trash_bin.top + 0.05 + height - 0.03)
    lib.set_speed(0.3)
    lib.move_above(trash_bin, height)
    lib.open_gripper()


for item in [coffee_cup, food_container, water_bottle]:
    discard(item)

lib.home()
