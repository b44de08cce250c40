"""The one compiled part: robocritics.robot._ur_nearest, the UR closed-form IK's nearest-branch search in C.

Optional: if it does not build (no C compiler), ``robocritics.robot.ik_nearest`` runs the same search in Python,
which stays the reference. ``-ffp-contract=off``: no fused multiply-add, so each product is rounded as Python rounds
it; ``-fno-builtin``: libm's sin, cos and atan2, as Python's math module calls them (no sincos fusion).
"""

from setuptools import Extension, setup

setup(
    ext_modules=[
        Extension(
            "robocritics.robot._ur_nearest",
            ["src/robocritics/robot/_ur_nearest.c"],
            extra_compile_args=["-O2", "-ffp-contract=off", "-fno-builtin"],
            optional=True,
        )
    ]
)
