# Recycling: put every item in the trash bin.
# goals: coffee_cup in trash_bin; food_container in trash_bin; water_bottle in trash_bin
set_speed(1.0)
for item in objects:
    move_to(item.x, item.y, item.top + 0.12)
    move_down(0.14)
    close_gripper()
    move_up(0.15)
    move_to(trash_bin.x, trash_bin.y, trash_bin.top + 0.05)
    open_gripper()
home()
