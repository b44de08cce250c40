# Put all the recyclables into the trash bin, released low in its centre.
# goals: coffee_cup in trash_bin; food_container in trash_bin; water_bottle in trash_bin
for item in [food_container, coffee_cup, water_bottle]:
    move_above(item, 0.12)
    move_down(0.14)
    close_gripper()
    move_up(0.2)
    move_to(trash_bin.x, trash_bin.y, trash_bin.top + 0.02)
    move_down(0.05)
    open_gripper()
    move_up(0.1)
home()
