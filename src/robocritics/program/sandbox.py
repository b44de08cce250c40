"""Static validation and restricted execution of untrusted, LLM-written robot programs.

Design: an AST interpreter
--------------------------
The program is parsed with :mod:`ast`, checked against a whitelist of node
types (:func:`parse_program`, in :mod:`.check`), and then *interpreted* node by
node (:mod:`.interpreter`). It is never compiled to bytecode and never
``exec``'d, so the program never touches real builtins, real modules, frames
or code objects. We chose this over "compile after rewriting every attribute
access through a guard" because

* the whole attack surface is the interpreter's own dispatch: a name resolves
  only through the program's scopes and a fixed table of safe builtins, skills,
  ``lib``, ``math`` and the scene objects; an attribute resolves only through an
  explicit table (skill namespace members, ``math`` members, :class:`ObjectView`
  fields, a short list of list/dict/set/str/tuple methods). ``str.format``,
  ``__class__`` and friends are simply not in any table;
* the cost model covers everything a program can make Python do
  (:mod:`.meter`): every evaluated node and every step is paid in work units,
  and the clock is read every few hundred units, inside long expressions too;
  every operation Python runs in C (and so cannot interrupt) is priced from the
  sizes of its inputs *before* it runs and refused if the budget cannot pay:
  copying and searching by their lengths, comparing, hashing and sorting by
  the weight of the data they walk, printing by the characters written
  (:mod:`.render` writes ``repr`` piece by piece, never in one C call);
  memory is counted in bytes of every value made; dict keys and set elements
  go through :class:`~robocritics.program.keys.KeyGuard`, which bounds the keys
  that can share a hash, so crafted collisions cannot make a lookup walk
  thousands of keys (:mod:`.operations`, :mod:`.builtins`, :mod:`.methods`);
* runtime errors are caught at the node that raised them, so every error
  carries the line and column of the offending expression, and every value
  quoted in a message is cut to a few dozen characters
  (:func:`~robocritics.program.render.bounded_repr`), every message to
  :data:`~robocritics.program.render.MESSAGE_CHARS`.

The price is speed (a few microseconds per node), irrelevant for robot
programs of a few hundred steps. The interpreter recurses in Python for nested
calls and expressions; it never changes the process's recursion limit but
counts the frames it uses at every call and stops deep recursion itself, so
runs are independent (each has its own interpreter, scopes and counters) and
may happen in many threads at once.

What programs may use
---------------------
Statements: expressions, ``=`` (incl. tuple unpacking and ``*rest``), augmented
assignment, annotated assignment, ``if``/``elif``/``else``, ``for``/``while``
(with ``else``), ``break``, ``continue``, ``pass``, ``def`` (no decorators, no
``*args``/``**kwargs``; keyword-only parameters and defaults are fine; nested
functions see enclosing variables), ``return``, ``assert``, ``del`` of names and
items, ``import math`` / ``from math import ...`` and ``import lib`` (also
``robot_lib``, ``robocritics``, ``skills``: all name the skill namespace).
Expressions: literals, arithmetic, comparisons, boolean operators, conditional
expressions, ``lambda``, list/dict/set comprehensions and generator expressions
(evaluated eagerly to a list), subscripts and slices, f-strings (format specs
like ``{x:.2f}`` work; ``str.format`` and ``%`` formatting do not exist), calls.
Builtins, methods and ``math`` members: exactly those of
:mod:`robocritics.program.language` (``SAFE_BUILTINS``, ``SAFE_METHODS``,
``MATH_NAMES``), the one list shared with the LLM prompt and the docs.

Not available (rejected before running, with the line and a fix hint): other
imports, names or attributes starting with ``_``, ``class``, ``try``,
``raise``, ``with``, ``async``/``await``, ``yield``, ``global``/``nonlocal``,
``match``, ``:=``, ``@``, attribute assignment, ``**`` in calls and dicts,
``eval``/``exec``/``open``/``getattr``/``type``/``globals``/... .
"""

from __future__ import annotations

from ..errors import SceneError
from ..scene import Scene
from .budget import Budget, BudgetError
from .check import FORBIDDEN_NAMES as _FORBIDDEN_NAMES  # noqa: F401  (read here by tests and tools)
from .check import parse_program
from .interpreter import _Interpreter
from .plan import Plan

__all__ = ["Budget", "BudgetError", "run_program", "parse_program"]


def run_program(source: str, scene: Scene | None = None, budget: Budget | None = None) -> Plan:
    """Check and run an untrusted robot program against ``scene``; return the recorded :class:`Plan`.

    Nothing moves: skills record calls. Any rejection, budget stop or runtime
    error raises :class:`~robocritics.errors.ProgramError` (a :class:`BudgetError`
    for a budget stop) with the line and column.
    """
    b = budget or Budget()
    tree = parse_program(source, b)
    scene = scene if scene is not None else Scene()
    if not isinstance(scene, Scene):
        raise SceneError(
            f"run_program() needs a Scene, got {type(scene).__name__}; load one with "
            "Scene.builtin('sorting') or Scene.resolve(name_or_path)"
        )
    return _Interpreter(source, tree, scene, b).run()

