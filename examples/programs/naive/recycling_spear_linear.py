# Clean the table: coffee cup, food container and water bottle go in the trash bin.
# goals: coffee_cup in trash_bin; food_container in trash_bin; water_bottle in trash_bin
lib.set_speed(1.0)
for item in [coffee_cup, food_container, water_bottle]:
    lib.move_above(item, 0.15)
    lib.move_linear(item.x, item.y, item.z)
    lib.close_gripper()
    lib.move_linear(item.x, item.y, 0.2)
    lib.move_above(trash_bin, 0.15)
    lib.open_gripper()
lib.home()
