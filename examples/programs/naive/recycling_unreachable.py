# Recycling: everything into the trash bin, approaching from a safe height.
# goals: coffee_cup in trash_bin; food_container in trash_bin; water_bottle in trash_bin
for item in objects:
    move_to(item.x, item.y, 0.65)
    move_linear(item.x, item.y, item.top - 0.02)
    close_gripper()
    move_up(0.25)
    move_to(trash_bin.x, trash_bin.y, 0.3)
    open_gripper()
home()
