# Preparing breakfast: throw the fork into the trash bin, then serve the
# cupcake and the apple side by side on the plate. The cupcake sits on top of
# the apple inside the brown box, so it has to come off first.
import math

lib.set_speed(0.3)


def pick(obj, grasp_z, lift):
    lib.open_gripper()
    lib.move_above(obj, 0.08)
    lib.reduce_speed(15)
    lib.move_linear(obj.x, obj.y, grasp_z)
    lib.close_gripper()
    lib.move_up(lift)
    lib.set_speed(0.3)


def place(x, y, tcp_z):
    lib.move_to(x, y, tcp_z + 0.08)
    lib.reduce_speed(15)
    lib.move_down(0.08)
    lib.open_gripper()
    lib.move_up(0.08)
    lib.set_speed(0.3)


# 1. the fork: turn the fingers across its handle, then drop it in the bin
lib.rotate_gripper(math.pi / 2)
pick(fork, fork.z, 0.12)
lib.move_above(trash_bin, 0.05)
lib.open_gripper()
lib.rotate_gripper(0)

# 2. the cupcake, lifted off the apple, to the plate's right half
cupcake_half = cupcake.top - cupcake.z
pick(cupcake, cupcake.z, 0.10)
place(plate.x, plate.y - 0.065, plate.top + cupcake_half + 0.005)

# 3. the apple, out of the box (clear the rim), to the plate's left half;
#    fingers turned so that neither passes next to the cupcake
apple_half = apple.top - apple.z
pick(apple, apple.z, 0.14)
lib.rotate_gripper(math.pi / 2)
place(plate.x, plate.y + 0.065, plate.top + apple_half + 0.005)

lib.home()
