# Recycle the bottle first, then the cup, then the food container.
# goals: water_bottle in trash_bin; coffee_cup in trash_bin; food_container in trash_bin
move_to(water_bottle.x, water_bottle.y, 0.25)
move_down(0.13)
close_gripper()
move_linear(trash_bin.x, trash_bin.y, 0.12)
open_gripper()

move_to(coffee_cup.x, coffee_cup.y, 0.25)
move_down(0.18)
close_gripper()
move_linear(trash_bin.x, trash_bin.y, 0.1)
open_gripper()

move_to(food_container.x, food_container.y, 0.25)
move_down(0.22)
close_gripper()
move_linear(trash_bin.x, trash_bin.y, 0.1)
open_gripper()
home()
