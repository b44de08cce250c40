# Recycling, as an LLM might first write it: full speed, a fast plunge onto
# each object, and a straight dash to the bin.
for item in [coffee_cup, food_container, water_bottle]:
    move_to(item.x, item.y, item.top + 0.15)
    move_down(0.18)
    close_gripper()
    move_to(trash_bin.x, trash_bin.y, trash_bin.top)
    open_gripper()
home()
