# Throw the coffee cup, the food container and the water bottle in the trash bin.
# goals: coffee_cup in trash_bin; food_container in trash_bin; water_bottle in trash_bin
# each item is grasped and carried straight over to the bin
for item in [water_bottle, food_container, coffee_cup]:
    move_above(item, 0.1)
    move_down(0.1 + 0.02)
    close_gripper()
    move_to(trash_bin.x, trash_bin.y, 0.2)
    open_gripper()
home()
