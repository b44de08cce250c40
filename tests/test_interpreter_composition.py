"""The sandbox interpreter is composed, not mixed: value operations, methods and builtins are objects of their
own, and everything they price is paid to the one Meter the interpreter is given."""

from __future__ import annotations

import ast
import sys
from collections import Counter
from pathlib import Path

from robocritics.program import Budget
from robocritics.program.builtins import Builtins
from robocritics.program.check import parse_program
from robocritics.program.interpreter import _Interpreter
from robocritics.program.methods import Methods
from robocritics.program.meter import Meter
from robocritics.program.operations import Operations
from robocritics.scene import Scene

SCENE = Scene.builtin("sorting")
BUDGET = Budget(clock=lambda: 0.0)

PROGRAM = """
xs = [3, 1, 2] * 20 + list(range(40))
ys = sorted(xs, key=lambda v: -v)
zs = xs.copy()
zs.append(len(ys))
text = ", ".join(str(v) for v in zs[:10])
d = {k: k * k for k in range(30)}
print(text, max(ys), sum(d.values()), 'x' * 40 in text)
"""


class CountingMeter(Meter):
    """A Meter that remembers which module asked it to pay, and how much."""

    def __init__(self, budget: Budget):
        super().__init__(budget)
        self.payers: Counter[str] = Counter()

    def _payer(self) -> None:
        self.payers[Path(sys._getframe(2).f_code.co_filename).name] += 1

    def spend(self, units: int) -> None:
        self._payer()
        super().spend(units)

    def spend_ops(self, ops: int) -> None:
        self._payer()
        super().spend_ops(ops)

    def spend_chars(self, chars: int) -> None:
        self._payer()
        super().spend_chars(chars)

    def allocate(self, nbytes: int) -> None:
        self._payer()
        super().allocate(nbytes)


def _run(meter: Meter | None) -> _Interpreter:
    interp = _Interpreter(PROGRAM, parse_program(PROGRAM, BUDGET), SCENE, BUDGET, meter=meter)
    interp.run()
    return interp


def test_the_interpreter_has_no_mixins_and_its_parts_are_separate_classes():
    assert _Interpreter.__bases__ == (object,)
    for part in (Operations, Methods, Builtins):
        assert part.__bases__ == (object,)
        assert not issubclass(_Interpreter, part)


def test_value_operations_methods_and_builtins_pay_the_one_meter_given():
    meter = CountingMeter(BUDGET)
    interp = _run(meter)
    assert interp.meter is meter
    assert interp.ops.meter is meter and interp.methods.meter is meter and interp.builtins.meter is meter
    assert interp.ops.keys.meter is meter
    # every composed part paid through it: operators and containers, list methods, builtins
    for module in ("operations.py", "methods.py", "builtins.py", "interpreter.py"):
        assert meter.payers[module] > 0, (module, meter.payers)
    # and nothing was paid elsewhere: counting changes no count
    plain = _run(None).meter
    assert (meter.work, meter.steps, meter.memory) == (plain.work, plain.steps, plain.memory)


def test_operations_alone_charge_their_meter_before_building():
    meter = CountingMeter(BUDGET)
    interp = _Interpreter("", parse_program("", BUDGET), SCENE, BUDGET)
    ops = Operations(meter, BUDGET, interp.ops.keys, interp.where, interp._call)
    node = ast.parse("x", mode="eval").body
    node.lineno, node.col_offset = 1, 0
    before = meter.work
    result = ops.binop(ast.Add, [1] * 100, [2] * 100, node)
    assert result == [1] * 100 + [2] * 100
    assert meter.payers["operations.py"] == 2  # the copy's element operations, then the new list's bytes
    assert meter.work - before == 1 + 200 // 32
    assert interp.meter.work == 0  # the interpreter's own meter was not touched
