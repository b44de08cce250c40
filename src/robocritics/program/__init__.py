"""Robot programs: the skill API the LLM writes against, the sandbox that checks and runs them, the Plan they produce.

>>> from robocritics.program import run_program
>>> from robocritics.scene import Scene
>>> plan = run_program("move_above(green_apple)\\nclose_gripper()", Scene.builtin("sorting"))
>>> [c.describe() for c in plan.calls]
['move_above(green_apple, height=0.1)', 'close_gripper()']
"""

from .budget import Budget, BudgetError
from .language import SAFE_BUILTINS
from .plan import FrozenArgs, Plan, SkillCall
from .sandbox import parse_program, run_program
from .skills import SKILLS, ObjectView, api_reference, recording

__all__ = [
    "Plan",
    "SkillCall",
    "FrozenArgs",
    "Budget",
    "BudgetError",
    "run_program",
    "parse_program",
    "SAFE_BUILTINS",
    "SKILLS",
    "ObjectView",
    "api_reference",
    "recording",
]
