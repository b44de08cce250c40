# Discard the objects in the trash bin.
# goals: coffee_cup in trash_bin; food_container in trash_bin; water_bottle in trash_bin
for item in [coffee_cup, food_container, water_bottle]:
    move_above(item, 0.15)
    move_linear(item.x, item.y, item.top - 0.02)
    close_gripper()
    move_up(0.15)
    move_above(trash_bin, 0.2)
    open_gripper()
home()
