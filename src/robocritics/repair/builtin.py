"""Repairs offered by the built-in critics, registered through the ``robocritics_repairs`` hook.

Each repair is derived from the verdict's evidence (program lines, measured
value against threshold, objects) and is only a *candidate*: :func:`robocritics.repair.repair`
re-simulates it and keeps it only when it removes the flag without adding another.
"""

from __future__ import annotations

from ..hookspecs import hookimpl
import ast
import math

from .edit import Edit, Insert, MoveBlock, ReplaceText, ScaleNumbers, paragraphs

#: Headroom under a speed threshold a slowdown aims for (fraction of the threshold).
SPEED_MARGIN = 0.85
#: Factors tried on hover/transit heights that leave the workspace.
HEIGHT_FACTORS = (0.5,)
_MOVES = {"move_to", "move_linear", "move_above", "move_down", "move_up", "home"}



def _move_lines(verdict, execution) -> list[int]:
    skills = {c.line: c.skill for c in execution.plan.calls}
    return [ln for ln in verdict.evidence.lines if skills.get(ln) in _MOVES]


def _slowdowns(verdict, execution) -> list[Edit]:
    """The smallest speed fraction on the offending moves that brings the peak under the threshold.

    Speed scales linearly with the speed fraction, so ``threshold / value`` (with
    :data:`SPEED_MARGIN`) of the speed in effect on each line is enough; a second,
    stronger candidate covers moves whose peak is set by acceleration limits.
    """
    if not verdict.value or not verdict.threshold or verdict.value <= verdict.threshold:
        return []
    lines = _move_lines(verdict, execution)
    edits = []
    for margin in (SPEED_MARGIN, SPEED_MARGIN**2, SPEED_MARGIN**4):
        ops, parts = [], []
        for ln in lines:
            prev = execution.plan.speed_at(ln)
            f = max(0.01, round(prev * margin * verdict.threshold / verdict.value, 2))
            ops.append(Insert(ln, before=(f"set_speed({f:g})",), after=(f"set_speed({prev:g})",)))
            parts.append(f"line {ln}: speed {prev:g} -> {f:g}")
        if ops:
            edits.append(
                Edit(
                    verdict.critic,
                    lines[0],
                    "; ".join(parts) + " (restored after the move)",
                    f"peak {verdict.value:.3g} {verdict.unit} over the {verdict.threshold:g} {verdict.unit} limit",
                    ops,
                )
            )
    return edits


def _avoid(verdict, execution) -> list[Edit]:
    """``avoid_collision(obj)`` before the first offending line for each object the robot hits."""
    pair = str(verdict.details.get("closest_pair", "")).split("|")
    ids = {o.id for o in execution.scene.objects} | {c.id for c in execution.scene.containers}
    names = [n for n in [*pair, *verdict.evidence.objects] if n in ids]
    first = min((c.line for c in execution.plan.calls), default=1)
    edits = []
    for name in dict.fromkeys(reversed(names)):
        edits.append(
            Edit(
                verdict.critic,
                first,
                f"avoid_collision({name}) before line {first}",
                f"the robot comes within {verdict.value:.3g} m of {name}",
                [Insert(first, before=(f"avoid_collision({name})",))],
            )
        )
    return edits


def _lower_heights(verdict, execution) -> list[Edit]:
    """Lower the hover/transit heights (float literals) on the offending move lines."""
    lines = [ln for ln in _move_lines(verdict, execution)]
    return [
        Edit(
            verdict.critic,
            lines[0],
            f"heights on lines {', '.join(map(str, lines))} scaled by {f:g}",
            f"the {verdict.evidence.links[0] if verdict.evidence.links else 'robot'} leaves the workspace "
            f"by {verdict.value:.3g} m",
            [ScaleNumbers(ln, f) for ln in lines],
        )
        for f in HEIGHT_FACTORS
        if lines
    ]


def _pick_first(verdict, execution, program) -> list[Edit]:
    """Pick the object the gripper hits first: move the paragraph that picks it above the offending one.

    E.g. the apple grabbed while the cupcake sits on it: the gripper hits the
    cupcake, so the cupcake's paragraph goes first (only a forward move of a
    top-level paragraph that names the object in its first line).
    """
    if not verdict.evidence.lines:
        return []
    groups = paragraphs(program)
    text = program.splitlines()
    line = verdict.evidence.lines[0]
    here = next((g for g in groups if g[0] <= line <= g[1]), None)
    edits = []
    for name in dict.fromkeys([*str(verdict.details.get("closest_pair", "")).split("|"), *verdict.evidence.objects]):
        if not name or here is None:
            continue
        group = next((g for g in groups if g[0] > here[1] and f"{name}." in text[g[0] - 1]), None)
        if group and text[group[1] - 1].strip() == "home()" and group[1] > group[0]:
            group = (group[0], group[1] - 1)  # the program still ends at home
        if group:
            edits.append(
                Edit(
                    verdict.critic,
                    here[0],
                    f"lines {group[0]}-{group[1]} (picking {name}) moved above line {here[0]}",
                    f"the robot hits {name} during lines {', '.join(map(str, verdict.evidence.lines))}",
                    [MoveBlock(here[0], *group)],
                )
            )
    return edits


#: Fraction of a container's inner half-width at which released objects are spread.
SPREAD_RADIUS = 0.55


def _loop_variable(tree: ast.Module, line: int) -> str | None:
    """The target name of the innermost ``for NAME in ...`` loop around ``line``."""
    found = None
    for node in ast.walk(tree):
        if isinstance(node, ast.For) and isinstance(node.target, ast.Name):
            if node.lineno < line <= (node.end_lineno or node.lineno):
                if found is None or node.lineno > found[0]:
                    found = (node.lineno, node.target.id)
    return found[1] if found else None


def _spread(verdict, execution, program) -> list[Edit]:
    """Objects released at the same spot of a container collide: give each its own spot inside it.

    The release move of a loop (``move_to(bin.x, bin.y, ...)``) gets a per-object
    offset, on a circle of :data:`SPREAD_RADIUS` of the container's inner half-width.
    """
    final = execution.final_scene
    ids = {o.id for o in final.objects}
    pair = [p for p in str(verdict.details.get("closest_pair", "")).split("|") if p in ids]
    if verdict.critic == "task_outcome":  # an object that ended on another instead of inside the container
        pair = [o for o in verdict.evidence.objects if execution.resting_on.get(o) in ids]
        pair = [pair[0], execution.resting_on[pair[0]]] if pair else []
    if len(pair) != 2:
        return []
    holder = final.container_holding(pair[1])
    if holder is None or (verdict.critic != "task_outcome" and final.container_holding(pair[0]) != holder):
        return []
    box = holder
    inside = [o.id for o in final.objects if (h := final.container_holding(o.id)) is not None and h.id == box.id]
    inside += [p for p in pair if p not in inside]
    radius = SPREAD_RADIUS * (min(box.size[0], box.size[1]) / 2 - box.wall_m)
    spots = {
        oid: (round(radius * math.cos(2 * math.pi * k / len(inside)), 3), round(radius * math.sin(2 * math.pi * k / len(inside)), 3))
        for k, oid in enumerate(inside)
    }
    tree = ast.parse(program)
    text = program.splitlines()
    ops: list = []
    lines = sorted({c.line for c in execution.plan.calls if c.skill in ("move_to", "move_linear")})
    for ln in lines:
        if f"{box.id}.x" not in text[ln - 1] or f"{box.id}.y" not in text[ln - 1]:
            continue
        var = _loop_variable(tree, ln)
        if var is None:
            continue
        ops += [
            ReplaceText(ln, f"{box.id}.x", f"{box.id}.x + release_spots[{var}.id][0]"),
        ]
        ops.append(ReplaceText(ln, f"{box.id}.y", f"{box.id}.y + release_spots[{var}.id][1]"))
    if not ops:
        return []
    first = min(c.line for c in execution.plan.calls)
    top = next(s for s in tree.body if s.lineno <= first <= (s.end_lineno or s.lineno))
    ops.append(Insert(top.lineno, before=(f"release_spots = {spots!r}  # each object at its own spot in {box.id}",)))
    return [
        Edit(
            verdict.critic,
            ops[0].line,
            f"release at its own spot in {box.id} on line {ops[0].line} (spots {spots})",
            f"{pair[0]} and {pair[1]} are released at the same spot of {box.id}",
            ops,
        )
    ]


#: Clearance added above a release point beyond the measured penetration, m.
RELEASE_CLEARANCE_M = 0.05


def _release_higher(verdict, execution, program) -> list[Edit]:
    """The gripper hits what it just released: release higher, by the penetration plus a clearance.

    For a collision flagged on an ``open_gripper()`` line, the z argument of the
    move just before it becomes ``z + d`` with ``d = penetration + RELEASE_CLEARANCE_M``.
    """
    if verdict.value is None or verdict.value >= 0:
        return []
    calls = execution.plan.calls
    skills = {c.line: c.skill for c in calls}
    tree = ast.parse(program)
    text = program.splitlines()
    edits = []
    for ln in verdict.evidence.lines:
        releases = {c.line for c in calls if c.skill == "open_gripper"}
        if skills.get(ln) in ("move_to", "move_linear") and any(r > ln for r in releases):
            move = ln  # the release move itself
        elif skills.get(ln) == "open_gripper":
            moves = [c.line for c in calls if c.line < ln and c.skill in ("move_to", "move_linear")]
            if not moves:
                continue
            move = max(moves)
        else:
            continue
        call = next((n for n in ast.walk(tree) if isinstance(n, ast.Call) and n.lineno == move and len(n.args) == 3), None)
        if call is None or call.args[2].lineno != call.args[2].end_lineno:
            continue
        z = ast.get_source_segment(program, call.args[2]) or ""
        d = round(-verdict.value + RELEASE_CLEARANCE_M, 2)
        edits.append(
            Edit(
                verdict.critic,
                move,
                f"release {d:g} m higher on line {move} ({z} -> {z} + {d:g})",
                f"the gripper penetrates what it releases by {-verdict.value:.3g} m on line {ln}",
                [ReplaceText(move, f", {z})", f", {z} + {d:g})")],
            )
        )
    return edits


_BY_CRITIC = {
    "joint_speed": [_slowdowns],
    "end_effector_pose": [_slowdowns],
    "collision": [_spread, _release_higher, _avoid, _pick_first, _slowdowns],
    "space_usage": [_lower_heights],
    "task_outcome": [_spread],
}


@hookimpl
def robocritics_repairs(verdict, execution, program):  # type: ignore[no-untyped-def]
    makers = _BY_CRITIC.get(verdict.critic, [])
    return [e for make in makers for e in (make(verdict, execution, program) if make in (_pick_first, _spread, _release_higher) else make(verdict, execution))]
