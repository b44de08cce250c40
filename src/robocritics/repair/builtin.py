"""Repairs offered by the built-in critics, registered through the ``robocritics_repairs`` hook.

Each repair is derived from the verdict's evidence (program lines, measured
value against threshold, objects) and is only a *candidate*: :func:`robocritics.repair.repair`
re-simulates it and keeps it only when it removes the flag without adding another.
"""

from __future__ import annotations

import ast
import math
import re

from ..critic.hookspecs import hookimpl
from ..critic.verdict import Flag
from .edit import Edit, Insert, InsertText, MoveBlock, ReplaceSpan, ReplaceText, ScaleNumbers, paragraphs

#: Headroom under a speed threshold a slowdown aims for (fraction of the threshold).
SPEED_MARGIN = 0.85
#: Factors tried on hover/transit heights that leave the workspace (or sweep too much of it), mildest first.
HEIGHT_FACTORS = (0.8, 0.5)
#: Groups of lines lowered: all flagged lines together, then the first few alone.
MAX_HEIGHT_GROUPS = 4
_MOVES = {"move_to", "move_linear", "move_above", "move_down", "move_up", "home"}


def _move_lines(verdict, execution) -> list[int]:
    skills = {c.line: c.skill for c in execution.plan.calls}
    return [ln for ln in verdict.evidence.lines if skills.get(ln) in _MOVES]


_SET_SPEED = re.compile(r"(?:lib\.)?set_speed\([0-9.]+\)")


def _speed_wrapper(text: list[str], line: int) -> str | None:
    """The ``set_speed(f)`` call alone on the line above ``line`` when another ``set_speed`` is alone on the line
    below: a speed set for that one move (by an earlier slowdown), or None."""
    if not 1 < line < len(text):
        return None
    above, below = text[line - 2].strip(), text[line].strip()
    return above if _SET_SPEED.fullmatch(above) and _SET_SPEED.fullmatch(below) else None


def _slowdowns(verdict, execution, program) -> list[Edit]:
    """The smallest speed fraction on the offending moves that brings the peak under the threshold.

    Speed scales linearly with the speed fraction, so ``threshold / value`` (with
    :data:`SPEED_MARGIN`) of the speed in effect on each line is enough; a second,
    stronger candidate covers moves whose peak is set by acceleration limits.
    """
    if not verdict.value or not verdict.threshold or verdict.value <= verdict.threshold:
        return []
    lines = _move_lines(verdict, execution)
    text = program.splitlines()
    edits = []
    for margin in (SPEED_MARGIN, SPEED_MARGIN**2, SPEED_MARGIN**4):
        ops, parts = [], []
        for ln in lines:
            prev = execution.plan.speed_at(ln)
            f = max(0.01, round(prev * margin * verdict.threshold / verdict.value, 2))
            wrapper = _speed_wrapper(text, ln)
            if wrapper is not None:  # slowed before: change that speed instead of wrapping the move again
                ops.append(ReplaceText(ln - 1, wrapper, f"set_speed({f:g})"))
            else:
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


def _avoid(verdict, execution, program) -> list[Edit]:
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


def _lower_heights(verdict, execution, program) -> list[Edit]:
    """Lower the hover/transit heights (float literals) on the offending move lines: all together, then each alone.

    Each factor of :data:`HEIGHT_FACTORS` is offered, the mildest first: a lower move keeps
    the arm closer to the table (and the wrist inside the workspace) and is shorter.
    """
    lines = [ln for ln in _move_lines(verdict, execution)]
    groups = [lines] + ([[ln] for ln in lines] if len(lines) > 1 else [])
    part = verdict.evidence.links[0] if verdict.evidence.links else "robot"
    why = (
        f"the {part} leaves the workspace by {verdict.value:.3g} m"
        if verdict.flag == Flag.ERROR
        else f"the motion sweeps {verdict.value:.3g} {verdict.unit} (over {verdict.threshold:.3g} {verdict.unit})"
    )
    return [
        Edit(
            verdict.critic,
            group[0],
            f"heights on line{'s' if len(group) > 1 else ''} {', '.join(map(str, group))} scaled by {f:g}",
            why,
            [*(ScaleNumbers(ln, f) for ln in group), *_keep_descents(execution, program, group, f)],
        )
        for group in groups[:MAX_HEIGHT_GROUPS]
        for f in HEIGHT_FACTORS
        if group
    ]


def _keep_descents(execution, program: str, group: list[int], factor: float) -> list:
    """A hover lowered by ``factor`` with a ``move_down(dz)`` after it (on a line not scaled): the descent is
    shortened by as much, so it still ends where it did (at the grasp or the release)."""
    motion = [c for c in execution.plan.calls if c.skill not in _SETTINGS]
    tree = ast.parse(program)
    ops, done = [], set()
    for c, n in zip(motion, motion[1:]):
        if c.line not in group or n.skill != "move_down" or n.line in group or n.line in done:
            continue
        stmt = _call_named(tree, c.line, c.skill)
        literals = [x.value for x in ast.walk(stmt) if isinstance(x, ast.Constant) and type(x.value) is float
                    and x.value > 0] if stmt is not None else []  # fmt: skip
        down = _call_named(tree, n.line, "move_down")
        if len(literals) != 1 or down is None or not down.args:
            continue
        lowered = literals[0] - round(literals[0] * factor, 4)
        op = _shifted(program, down.args[0], -lowered, floor=0.0)
        if op is not None:
            ops.append(op)
            done.add(n.line)
    return ops


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
    # each paragraph with a flagged line, the latest first: the smallest reordering is offered first
    flagged = [g for g in groups if any(g[0] <= ln <= g[1] for ln in verdict.evidence.lines)]
    edits = []
    for here in reversed(flagged):
        for name in dict.fromkeys([*str(verdict.details.get("closest_pair", "")).split("|"), *verdict.evidence.objects]):
            if not name:
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


#: Skills that set how the next moves run without moving: they do not separate a move from the release after it.
_SETTINGS = {"set_speed", "reduce_speed", "avoid_collision"}


def _release_lines(execution, box) -> list[int]:
    """The lines of the moves that end above ``box`` with an ``open_gripper`` next (or after a straight descent):
    where objects are let go in it."""
    calls = [c for c in execution.plan.calls if c.skill not in _SETTINGS]
    lines = []
    for j, release in enumerate(calls):
        if release.skill != "open_gripper":
            continue
        i = j - 1
        while i >= 0 and calls[i].skill in ("move_down", "move_up"):
            i -= 1  # a straight descent onto the release point: the move before it sets where
        if i < 0 or calls[i].skill not in ("move_to", "move_linear", "move_above"):
            continue
        c = calls[i]
        if c.skill == "move_above":
            inside = c.args.get("object") == box.id
        else:
            x, y, _ = c.args["target"]
            inside = box.contains_point((x, y, box.floor_top + 1e-3))
        if inside and c.line not in lines:
            lines.append(c.line)
    return lines


def _offset_release(program: str, tree: ast.Module, line: int, dx: str, dy: str):
    """The ops that shift the release move on ``line`` by ``dx``, ``dy`` (expressions, m); None if not possible.

    ``move_to``/``move_linear(x, y, z)`` get ``x + dx``, ``y + dy``; ``move_above(box, h)`` becomes
    ``move_to(box.x + dx, box.y + dy, box.top + h)`` (the same point, shifted).
    """
    for skill in ("move_to", "move_linear"):
        call = _call_named(tree, line, skill)
        if call is not None and len(call.args) == 3 and all(a.lineno == a.end_lineno == line for a in call.args[:2]):
            x, y = (ast.get_source_segment(program, a) for a in call.args[:2])
            return [
                ReplaceSpan(line, call.args[1].col_offset, call.args[1].end_col_offset, f"{y} + {dy}"),
                ReplaceSpan(line, call.args[0].col_offset, call.args[0].end_col_offset, f"{x} + {dx}"),
            ]
    call = _call_named(tree, line, "move_above")
    if call is None or call.lineno != call.end_lineno or not call.args:
        return None
    height = next((k.value for k in call.keywords if k.arg == "height"), call.args[1] if len(call.args) > 1 else None)
    h = ast.get_source_segment(program, height) if height is not None else "0.1"
    obj = ast.get_source_segment(program, call.args[0])
    func = ast.get_source_segment(program, call.func).replace("move_above", "move_to")
    text = f"{func}({obj}.x + {dx}, {obj}.y + {dy}, {obj}.top + {h})"
    return [ReplaceSpan(line, call.col_offset, call.end_col_offset, text)]


def _spread(verdict, execution, program) -> list[Edit]:
    """Objects released at the same spot of a container collide: give each its own spot inside it.

    Every release move into that container (a move ending above it, then ``open_gripper``)
    gets an offset on a circle of :data:`SPREAD_RADIUS` of the container's inner
    half-width: in a ``for`` loop through a ``release_spots`` table keyed by the loop
    object's id, outside a loop one spot per release line.
    """
    final = execution.final_scene
    ids = {o.id for o in final.objects}
    pair = [p for p in str(verdict.details.get("closest_pair", "")).split("|") if p in ids]
    if verdict.critic == "task_outcome":  # an object that ended on another instead of inside the container
        pair = [o for o in verdict.evidence.objects if execution.resting_on.get(o) in ids]
        pair = [pair[0], execution.resting_on[pair[0]]] if pair else []
    if len(pair) != 2:
        return []
    box = final.container_holding(pair[1])  # what was hit lies in a container: the carried one goes there too
    if box is None:
        return []
    tree = ast.parse(program)
    if "release_spots" in program:
        return []  # spread once; a second spread would add offsets to offsets
    lines = _release_lines(execution, box)
    inside = [o.id for o in final.objects if (h := final.container_holding(o.id)) is not None and h.id == box.id]
    inside += [p for p in pair if p not in inside]
    loops = {ln: _loop_variable(tree, ln) for ln in lines}
    n = max(len(inside), sum(1 for v in loops.values() if v is None))
    radius = SPREAD_RADIUS * (min(box.size[0], box.size[1]) / 2 - box.wall_m)
    circle = [(round(radius * math.cos(2 * math.pi * k / n), 3), round(radius * math.sin(2 * math.pi * k / n), 3))
              for k in range(n)]  # fmt: skip
    spots = dict(zip(inside, circle))
    load = _load_per_step(execution.trajectory)
    carried = {load.get(i, "") for i, st in enumerate(execution.trajectory.steps) if st.line in lines}
    spots.update({oid: (0.0, 0.0) for oid in sorted(carried - set(spots) - {""})})  # e.g. released in another box
    ops: list = []
    free = iter(circle)
    for ln in lines:
        var = loops[ln]
        if var is not None:
            shift = _offset_release(program, tree, ln, f"release_spots[{var}.id][0]", f"release_spots[{var}.id][1]")
        else:
            dx, dy = next(free, (0.0, 0.0))
            shift = _offset_release(program, tree, ln, f"{dx:g}", f"{dy:g}")
        ops += shift or []
    if not ops:
        return []
    if any(v is not None for v in loops.values()):
        first = min(c.line for c in execution.plan.calls)
        top = next(s for s in tree.body if s.lineno <= first <= (s.end_lineno or s.lineno))
        ops.append(Insert(top.lineno, before=(f"release_spots = {spots!r}  # each object at its own spot in {box.id}",)))
    return [
        Edit(
            verdict.critic,
            lines[0],
            f"release at its own spot in {box.id} on line{'s' if len(lines) > 1 else ''} {', '.join(map(str, lines))}",
            f"{pair[0]} and {pair[1]} are released at the same spot of {box.id}",
            ops,
        )
    ]


#: Clearance left between what the robot carries (or its fingertips) and what it passed through, m.
RELEASE_CLEARANCE_M = 0.05
#: Name of the per-object raise table a loop's release move reads (one entry per object carried there).
RAISE_TABLE = "release_raise"


def _load_per_step(trajectory) -> dict[int, str]:
    """The object each step carries: held at its first sample, or (a release) just before it."""
    import numpy as np

    steps, first = np.unique(trajectory.step, return_index=True)  # each step's first sample
    held = trajectory.attached
    return {s: str(held[r]) or (str(held[r - 1]) if r > 0 else "") for s, r in zip(steps.tolist(), first.tolist())}


def _vertical_overlaps(execution, line: int) -> dict[str, float]:
    """Per carried object: how far (m, vertically) the robot's load sinks into what it penetrates on ``line``.

    For every counted collision sample of the gripper or the carried object
    against a scene object or container on ``line``, the overlap is
    ``top(b) - bottom(a)``: ``top(b)`` the entity's top at that sample (an object
    that moved has its pose from the execution), ``bottom(a)`` the carried
    object's lowest point, or the TCP (the fingertips, the gripper's lowest point
    with the fingers down). Keyed by the object carried during that step (``""``:
    nothing). Lifting the motion of ``line`` by that much clears the top of what
    it hit, whichever side the penetration depth itself points to.
    """
    import numpy as np

    from ..critic.builtin.collision import Counted

    traj = execution.trajectory
    steps = [i for i, s in enumerate(traj.steps) if s.line == line]
    rows = np.flatnonzero(np.isin(traj.step, steps))
    if rows.size == 0:
        return {}
    counted = Counted(traj)
    hit = counted.row_mask(rows) & (traj.proximity[rows] <= 0)
    load = _load_per_step(traj)
    tcp_z = traj.tcp[rows, 2, 3]
    objects = {o.id: o for o in execution.scene.objects}
    containers = {c.id: c for c in execution.scene.containers}
    out: dict[str, float] = {}
    for k in np.flatnonzero(hit.any(axis=0)):
        pair = traj.pairs[k]
        if pair.group_a not in ("gripper", "attached") or pair.group_b not in ("object", "container"):
            continue
        at = rows[hit[:, k]]
        b = pair.b_entity
        if b in containers:
            top = np.full(at.size, containers[b].top)
        elif b in execution.object_poses:
            top = execution.object_poses[b][at, 2, 3] + objects[b].half_height
        else:
            top = np.full(at.size, objects[b].top)
        if pair.group_a == "attached":
            bottom = execution.object_poses[pair.a][at, 2, 3] - objects[pair.a].half_height
        else:
            bottom = tcp_z[hit[:, k]]
        depth = np.maximum(top - bottom, -traj.proximity[at, k])
        for step, d in zip(traj.step[at].tolist(), depth.tolist()):
            key = load.get(step, "")
            out[key] = max(out.get(key, 0.0), d)
    return out


def _cm_up(x: float) -> float:
    """``x`` rounded up to the next centimetre, m (a program reads better in whole cm)."""
    return math.ceil(round(x * 100, 6)) / 100


def _raise_release(verdict, execution, program) -> list[Edit]:
    """The robot hits what is already where it releases (or what it just let go of): release higher.

    For a collision flagged on a release move (a ``move_to``/``move_linear`` followed
    by ``open_gripper``) or on the ``open_gripper`` itself, the z argument of that
    move is raised by the vertical overlap measured in the trace
    (:func:`_vertical_overlaps`) plus :data:`RELEASE_CLEARANCE_M`, rounded up to a
    centimetre. In a ``for`` loop over objects each object gets its own raise (a
    tall bottle needs more than a flat box), through a ``release_raise`` table keyed
    by the object's id; a second round adds to the raise already there.
    """
    if verdict.value is None or verdict.value > 0:
        return []
    calls = execution.plan.calls
    skills = {c.line: c.skill for c in calls}
    motion = [c for c in calls if c.skill not in _SETTINGS]
    release_moves = {c.line for c, n in zip(motion, motion[1:]) if c.skill in ("move_to", "move_linear")
                     and n.skill == "open_gripper"}  # fmt: skip
    tree = ast.parse(program)
    text = program.splitlines()
    needs: dict[int, dict[str, float]] = {}  # release move line -> per carried object, m
    for ln in verdict.evidence.lines:
        if ln in release_moves:
            move = ln
        elif skills.get(ln) == "open_gripper":
            moves = [c.line for c in calls if c.line < ln and c.skill in ("move_to", "move_linear")]
            if not moves:
                continue
            move = max(moves)
        else:
            continue
        for key, d in _vertical_overlaps(execution, ln).items():
            needs.setdefault(move, {})
            needs[move][key] = max(needs[move].get(key, 0.0), d)
    edits = []
    for move, need in sorted(needs.items()):
        call = next((n for n in ast.walk(tree) if isinstance(n, ast.Call) and n.lineno == move and len(n.args) == 3), None)
        if call is None or call.args[2].lineno != call.args[2].end_lineno or not need:
            continue
        z = ast.get_source_segment(program, call.args[2]) or ""
        raise_by = {key: _cm_up(d + RELEASE_CLEARANCE_M) for key, d in need.items()}
        load = _load_per_step(execution.trajectory)
        carried = {load.get(i, "") for i, s in enumerate(execution.trajectory.steps) if s.line == move}
        raise_by.update({k: 0.0 for k in carried if k not in raise_by})  # every object the move carries has an entry
        var = _loop_variable(tree, move)
        loads = [k for k in raise_by if k]
        why = (
            f"on line {move} what the robot carries (or its fingertips) sinks {max(need.values()):.3g} m "
            f"below the top of what it hits (collision {-verdict.value:.3g} m deep)"
        )
        if var is not None and loads and len(loads) == len(raise_by):
            key = f"{RAISE_TABLE}[{var}.id]"
            table = _raise_table(tree)
            if table is not None and z.endswith(f" + {key}"):
                old, assign = table
                merged = {k: round(old.get(k, 0.0) + raise_by.get(k, 0.0), 3) for k in sorted({**old, **raise_by})}
                ops = [ReplaceText(assign.lineno, text[assign.lineno - 1].strip(), f"{RAISE_TABLE} = {merged!r}  # m")]
            else:
                if table is not None:
                    continue  # another move already uses the table: do not mix them
                merged = {k: raise_by[k] for k in sorted(loads)}
                first = min(c.line for c in calls)
                top = next(s for s in tree.body if s.lineno <= first <= (s.end_lineno or s.lineno))
                ops = [
                    ReplaceText(move, f", {z})", f", {z} + {key})"),
                    Insert(top.lineno, before=(f"{RAISE_TABLE} = {merged!r}  # m",)),
                ]
            what = f"release higher on line {move}, per object: {merged} m"
        else:
            d = max(raise_by.values())
            m = re.fullmatch(r"(.*) \+ (\d+(?:\.\d+)?)", z)
            if re.fullmatch(r"\d+(?:\.\d*)?", z):  # a literal height: write the new number
                new_z = f"{round(float(z) + d, 4):g}"
            else:
                new_z = f"{m.group(1)} + {round(float(m.group(2)) + d, 4):g}" if m else f"{z} + {d:g}"
            ops = [ReplaceText(move, f", {z})", f", {new_z})")]
            what = f"release {d:g} m higher on line {move} ({z} -> {new_z})"
        edits.append(Edit(verdict.critic, move, what, why, ops))
    return edits


def _raise_table(tree: ast.Module):
    """The program's top-level ``release_raise = {...}`` table and its statement, if there is one on one line."""
    for stmt in tree.body:
        if (
            isinstance(stmt, ast.Assign)
            and len(stmt.targets) == 1
            and isinstance(stmt.targets[0], ast.Name)
            and stmt.targets[0].id == RAISE_TABLE
            and stmt.lineno == stmt.end_lineno
        ):
            try:
                value = ast.literal_eval(stmt.value)
            except ValueError:
                return None
            return (value, stmt) if isinstance(value, dict) else None
    return None


_JOINT_MOVES = ("move_to", "move_above")


def _call_named(tree: ast.Module, line: int, skill: str) -> ast.Call | None:
    """The call of ``skill`` (or ``lib.skill``) that starts on ``line``."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and node.lineno == line:
            f = node.func
            if (isinstance(f, ast.Name) and f.id == skill) or (isinstance(f, ast.Attribute) and f.attr == skill):
                return node
    return None


def _natural_posture(verdict, execution, program) -> list[Edit]:
    """A pinch point: the move into the folded posture asks for the natural one (``posture="natural"``).

    The arm posture is set by joint-space moves (``move_to``, ``move_above``); a
    straight-line move keeps the posture of the joint move before it. So each
    flagged line maps to itself when it is a joint move, else to the last joint
    move before it; those calls get ``posture="natural"``: shoulder facing the
    target, elbow up, wrist down, the base turning as far as needed (see
    :func:`robocritics.program.skills.move_to`).
    """
    calls = execution.plan.calls
    tree = ast.parse(program)
    targets: dict[int, str] = {}
    for ln in verdict.evidence.lines:
        i = next((i for i, c in enumerate(calls) if c.line == ln), None)
        if i is None:
            continue
        joint = next((c for c in reversed(calls[: i + 1]) if c.skill in _JOINT_MOVES), None)
        if joint is not None and joint.args.get("posture") != "natural":
            targets[joint.line] = joint.skill
    ops, lines = [], []
    for ln, skill in sorted(targets.items()):
        call = _call_named(tree, ln, skill)
        if call is None or any(k.arg == "posture" for k in call.keywords) or call.end_lineno is None:
            continue
        ops.append(InsertText(call.end_lineno, (call.end_col_offset or 1) - 1, ', posture="natural"'))
        lines.append(ln)
    if not ops:
        return []
    return [
        Edit(
            verdict.critic,
            lines[0],
            f'posture="natural" on line{"s" if len(lines) > 1 else ""} {", ".join(map(str, lines))}',
            f"{verdict.details.get('closest_pair', 'two robot parts').replace('|', ' and ')} are {verdict.value:.3g} m "
            f"apart (under {verdict.threshold:g} m): the arm folds onto itself in the posture nearest its joints",
            ops,
        )
    ]


#: Steps (m) and farthest shift tried when looking for the nearest reachable height of an unreachable target.
REACH_STEP_M = 0.01
REACH_SEARCH_M = 0.5
#: Further shifts (m) offered beyond the nearest reachable height, away from the edge of the reach.
REACH_FURTHER_M = (0.05, 0.1)


def _unreached(execution, program):
    """The PlanningError of an unreachable target (it carries ``call``, ``target_m``, ``yaw_rad``), or None."""
    from ..errors import PlanningError
    from ..pipeline import simulate

    try:
        simulate(program, execution.scene, robot=execution.robot)
    except PlanningError as exc:
        return exc if getattr(exc, "target_m", None) is not None else None
    except Exception:  # noqa: BLE001 - any other failure is not an unreachable target
        return None
    return None


def _nearest_reachable_dz(robot, target, yaw_rad: float, floor_z: float) -> float | None:
    """The smallest vertical shift ``dz`` (m, a multiple of :data:`REACH_STEP_M`) after which ``target`` is reachable.

    Reachable: the robot's IK (fingers down, ``yaw_rad``) has a solution within the
    joint limits at ``target + dz`` *and* one step further, so the new point is not on
    the very edge of the reach. Lower shifts are tried before higher ones of the same
    size (a hover that is too high is the usual case); ``z`` stays above ``floor_z``.
    """
    import numpy as np

    from ..errors import PlanningError

    def reachable(z: float) -> bool:
        try:
            robot.ik(np.array([target[0], target[1], z]), yaw_rad=yaw_rad)
            return True
        except PlanningError:
            return False

    for k in range(1, int(round(REACH_SEARCH_M / REACH_STEP_M)) + 1):
        for sign in (-1, 1):
            dz = sign * k * REACH_STEP_M
            z = target[2] + dz
            if z > floor_z and reachable(z) and reachable(z + sign * REACH_STEP_M):
                return round(dz + sign * REACH_STEP_M, 3)  # the step further in: a margin inside the reach
    return None


def _shifted(program: str, node: ast.expr, delta: float, floor: float | None = None) -> ReplaceSpan | None:
    """Replace the single-line expression ``node`` by itself plus ``delta`` (m): a literal is rewritten."""
    if node.lineno != node.end_lineno or node.end_col_offset is None:
        return None
    text = ast.get_source_segment(program, node) or ""
    if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) and not isinstance(node.value, bool):
        value = round(float(node.value) + delta, 4)
        if floor is not None and value <= floor:
            return None
        new = f"{value:g}"
    else:
        new = f"{text} {'+' if delta > 0 else '-'} {abs(delta):g}"
    return ReplaceSpan(node.lineno, node.col_offset, node.end_col_offset, new)


def _reachable(verdict, execution, program) -> list[Edit]:
    """An unreachable target (a planning Error): move it to the nearest reachable height.

    The failed IK target is shifted vertically by the smallest ``dz`` that the arm
    reaches (:func:`_nearest_reachable_dz`), through the argument that sets that
    height: ``move_above``'s ``height``, the ``z`` of ``move_to``/``move_linear(x, y, z)``,
    or the distance of ``move_up``/``move_down``. A straight line fails at its first
    unreachable point, so its end moves to that point's reachable height
    (``target_z + dz - end_z`` for the end, from the error's ``goal_m``).
    """
    if verdict.critic != "runtime" or verdict.details.get("error") != "PlanningError":
        return []
    exc = _unreached(execution, program)
    if exc is None:
        return []
    dz = _nearest_reachable_dz(execution.robot, exc.target_m, exc.yaw_rad, execution.scene.table.top_z)
    if dz is None:
        return []
    # the nearest reachable point is on the edge of the reach, where the arm is stretched out (and its
    # wrist may leave the workspace): further in by REACH_FURTHER_M too; repair() keeps the best that runs
    # a straight line fails at its first unreachable point: its end moves to where that point became reachable
    end_z = getattr(exc, "goal_m", exc.target_m)[2]
    shifts = [dz + math.copysign(extra, dz) for extra in (0.0, *REACH_FURTHER_M)]
    shifts = [round(exc.target_m[2] + d - end_z, 3) for d in shifts if exc.target_m[2] + d > execution.scene.table.top_z]
    edits = [_reach_edit(verdict, exc, program, d) for d in shifts]
    return [e for e in edits if e is not None]


def _reach_edit(verdict, exc, program: str, dz: float) -> Edit | None:
    """The edit that shifts the end of ``exc.call``'s motion by ``dz`` (m, vertically) through its height argument."""
    call, target = exc.call, getattr(exc, "goal_m", exc.target_m)
    node = _call_named(ast.parse(program), call.line, call.skill)
    if node is None:
        return None
    op = None
    if call.skill == "move_above":
        height = next((k.value for k in node.keywords if k.arg == "height"), node.args[1] if len(node.args) > 1 else None)
        if height is not None:
            op = _shifted(program, height, dz, floor=-1e-9 if isinstance(height, ast.Constant) else None)
        elif node.end_lineno is not None and call.args["height"] + dz >= 0:
            op = InsertText(node.end_lineno, (node.end_col_offset or 1) - 1, f", height={call.args['height'] + dz:g}")
    elif call.skill in ("move_to", "move_linear") and len(node.args) == 3:
        op = _shifted(program, node.args[2], dz)
    elif call.skill in ("move_up", "move_down") and node.args:
        op = _shifted(program, node.args[0], dz if call.skill == "move_up" else -dz, floor=0.0)
    if op is None:
        return None
    p = exc.target_m
    unreached = f"({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) m"
    return Edit(
        verdict.critic,
        call.line,
        f"target {'lowered' if dz < 0 else 'raised'} by {abs(dz):g} m on line {call.line} "
        f"({call.skill}, now z = {target[2] + dz:.3f} m)",
        f"the arm cannot reach {unreached}; it reaches {target[2] + dz:.3f} m at the same x, y",
        [op],
    )


#: Clearance a transit lift leaves between the lowest point of the load (or the fingertips) and the highest
#: thing in the scene, m: the collision critic's warning distance (5 cm) plus 1 cm.
TRANSIT_CLEARANCE_M = 0.06
_TRANSITS = ("move_to", "move_linear", "move_above")


def _entity_tops(execution, row: int, skip: str) -> float:
    """The highest top (m) of the scene's objects (at sample ``row``, moved ones where they are then) and
    containers, except object ``skip`` and the table."""
    tops = [c.top for c in execution.scene.containers]
    for o in execution.scene.objects:
        if o.id == skip:
            continue
        poses = execution.object_poses.get(o.id)
        tops.append(float(poses[row, 2, 3]) + o.half_height if poses is not None else o.top)
    return max(tops, default=execution.scene.table.top_z)


def _transit_need(execution, line: int) -> tuple[float, float] | None:
    """For the move on ``line``: the clearance height (m) for the TCP and the largest lift (m) from where the
    move starts to it, over every time the line runs (a loop: each object carried there)."""
    traj = execution.trajectory
    objects = {o.id: o for o in execution.scene.objects}
    clear_z, lift = -math.inf, 0.0
    load = _load_per_step(traj)
    import numpy as np

    firsts = {int(s): int(r) for s, r in zip(*np.unique(traj.step, return_index=True))}
    for i, step in enumerate(traj.steps):
        if step.line != line or i not in firsts:
            continue
        row = firsts[i]
        tcp_z = float(traj.tcp[row, 2, 3])
        carried = load.get(i, "")
        below = 0.0
        if carried and carried in execution.object_poses:  # how far the load hangs under the fingertips
            below = max(0.0, tcp_z - (float(execution.object_poses[carried][row, 2, 3]) - objects[carried].half_height))
        z = _entity_tops(execution, row, carried) + below + TRANSIT_CLEARANCE_M
        clear_z, lift = max(clear_z, z), max(lift, z - tcp_z)
    return (clear_z, lift) if clear_z > -math.inf else None


def _target_xy(program: str, tree: ast.Module, line: int) -> tuple[str, str] | None:
    """The x and y expressions (source text) of the transit move on ``line``."""
    for skill in ("move_to", "move_linear"):
        call = _call_named(tree, line, skill)
        if call is not None and len(call.args) == 3:
            return ast.get_source_segment(program, call.args[0]), ast.get_source_segment(program, call.args[1])
    call = _call_named(tree, line, "move_above")
    if call is not None and call.args:
        obj = ast.get_source_segment(program, call.args[0])
        return f"{obj}.x", f"{obj}.y"
    return None


def _transit(verdict, execution, program) -> list[Edit]:
    """The arm or its load crosses something *during* a move (not where it ends): go over it.

    For each flagged transit move (``move_to``, ``move_linear``, ``move_above``), the
    clearance height is derived from the scene at that time (:func:`_transit_need`: the
    highest object or container top, plus how far the load hangs below the fingertips,
    plus :data:`TRANSIT_CLEARANCE_M`). Offered, cheapest first: a lift (``move_up``) to
    it before the move, and the lift plus a via point at that height above the move's
    target (``move_to(x, y, clear_z)``), so the move itself ends as a descent. The
    move's own target (a release, say) is never changed.
    """
    calls = execution.plan.calls
    skills = {c.line: c.skill for c in calls}
    tree = ast.parse(program)
    edits = []
    for line in dict.fromkeys(verdict.evidence.lines):
        if skills.get(line) not in _TRANSITS:
            continue
        need = _transit_need(execution, line)
        xy = _target_xy(program, tree, line)
        if need is None or xy is None or need[1] <= 0.005:
            continue
        clear_z, lift = need
        up = f"move_up({_cm_up(lift):g})"
        via = f"move_to({xy[0]}, {xy[1]}, {_cm_up(clear_z):g})"
        pair = str(verdict.details.get("closest_pair", "the robot|the scene")).split("|")
        how = f"sinks {-verdict.value:.3g} m into" if verdict.value < 0 else f"passes {verdict.value:.3g} m from"
        why = (
            f"during line {line} the {pair[0]} {how} the {pair[-1]}; the scene's highest top there needs the "
            f"fingertips at {clear_z:.3f} m"
        )
        edits.append(Edit(verdict.critic, line, f"lift {_cm_up(lift):g} m before line {line}", why,
                          [Insert(line, before=(up,))]))  # fmt: skip
        edits.append(Edit(verdict.critic, line, f"lift {_cm_up(lift):g} m and pass above the target at "
                          f"z = {_cm_up(clear_z):g} m before line {line}", why, [Insert(line, before=(up, via))]))  # fmt: skip
        edits.append(Edit(verdict.critic, line, f"pass above the target at z = {_cm_up(clear_z):g} m before line {line}",
                          why, [Insert(line, before=(via,))]))  # fmt: skip
    return edits


#: Gripper yaw (rad) a turned grasp uses: the fingers close across the object's other horizontal axis.
TURNED_YAW_RAD = round(math.pi / 2, 4)


def _turn_fingers(verdict, execution, program) -> list[Edit]:
    """The fingers land on the object they then grasp (e.g. along a fork's handle): grasp it turned 90 degrees.

    For a flagged finger contact with an object the program grasps, ``rotate_gripper``
    by :data:`TURNED_YAW_RAD` goes before the joint move that approaches that grasp and
    ``rotate_gripper(0)`` after the ``open_gripper`` that lets the object go, so the
    rest of the program keeps its orientation.
    """
    from ..critic.builtin.collision import Params as CollisionParams

    traj = execution.trajectory
    deep = traj.proximity.min(axis=0, initial=math.inf) < -CollisionParams().contact_tolerance_m  # not just touching
    grasped = {e.detail.removeprefix("grasped "): e.line for e in execution.events if e.kind == "grasp"}
    hit = {p.b_entity for p, d in zip(traj.pairs, deep.tolist()) if p.group_a == "gripper" and p.b_entity in grasped and d}
    calls = execution.plan.calls
    edits = []
    for obj in sorted(hit):
        close = grasped[obj]
        i = next(i for i, c in enumerate(calls) if c.line == close and c.skill == "close_gripper")
        approach = next((c for c in reversed(calls[:i]) if c.skill in _JOINT_MOVES), None)
        release = next((c for c in calls[i:] if c.skill == "open_gripper"), None)
        if approach is None or release is None or any(c.skill == "rotate_gripper" for c in calls[calls.index(approach) : i]):
            continue
        ops = [Insert(approach.line, before=(f"rotate_gripper({TURNED_YAW_RAD:g})",)),
               Insert(release.line, after=("rotate_gripper(0)",))]  # fmt: skip
        edits.append(Edit(verdict.critic, approach.line,
                          f"fingers turned {TURNED_YAW_RAD:g} rad before line {approach.line}, back after line {release.line}",
                          f"the fingers land on the {obj} they grasp on line {close}", ops))  # fmt: skip
    return edits


def _joint_instead(verdict, execution, program) -> list[Edit]:
    """A straight line the arm cannot follow (it passes too close to the base, or out of reach): a joint move."""
    if verdict.critic != "runtime" or verdict.details.get("error") != "PlanningError":
        return []
    exc = _unreached(execution, program)
    call = getattr(exc, "call", None)
    if call is None or call.skill != "move_linear":
        return []
    node = _call_named(ast.parse(program), call.line, "move_linear")
    if node is None:
        return []
    name = node.func.attr if isinstance(node.func, ast.Attribute) else node.func.id
    func = node.func
    end = func.end_col_offset
    return [Edit(verdict.critic, call.line, f"move_linear -> move_to on line {call.line} (a joint move)",
                 f"the straight line of line {call.line} leaves what the arm can follow",
                 [ReplaceSpan(call.line, end - len(name), end, "move_to")])]  # fmt: skip


def _shorter_descent(verdict, execution, program) -> list[Edit]:
    """The load is pushed into what is under it by the ``move_down`` before its release: descend less.

    The descent is shortened by the vertical overlap measured in the trace
    (:func:`_vertical_overlaps`) plus :data:`RELEASE_CLEARANCE_M`, rounded up to a
    centimetre (with the largest overlap over every time that line runs); a descent
    that would vanish is not offered.
    """
    if verdict.value is None or verdict.value > 0:
        return []
    calls = [c for c in execution.plan.calls if c.skill not in _SETTINGS]
    tree = ast.parse(program)
    lines = set(verdict.evidence.lines)
    edits = []
    for i, c in enumerate(calls[:-1]):
        if c.skill != "move_down" or calls[i + 1].skill != "open_gripper" or not {c.line, calls[i + 1].line} & lines:
            continue
        need = max(_vertical_overlaps(execution, c.line).values(), default=0.0)
        node = _call_named(tree, c.line, "move_down")
        if need <= 0 or node is None or not node.args or any(e.line == c.line for e in edits):
            continue
        d = _cm_up(need + RELEASE_CLEARANCE_M)
        op = _shifted(program, node.args[0], -d, floor=0.0)
        if op is not None:
            edits.append(Edit(verdict.critic, c.line, f"descend {d:g} m less on line {c.line} before the release",
                              f"the load sinks {need:.3g} m into what is under it at the end of line {c.line}",
                              [op]))  # fmt: skip
    return edits


#: How much higher than its measured overlap a grasp is moved, m (the fingers still close on the object).
GRASP_CLEARANCE_M = 0.005


def _grasp_higher(verdict, execution, program) -> list[Edit]:
    """The gripper plunges into the object it then grasps (its body hits a tall object's top): grasp higher.

    The approach (the move right before ``close_gripper``) ends higher by the deepest
    overlap of the gripper with that object on that line plus :data:`GRASP_CLEARANCE_M`:
    its z argument (``move_to``/``move_linear``) or a shorter ``move_down``.
    """
    from ..critic.builtin.collision import Params as CollisionParams

    traj = execution.trajectory
    motion = [c for c in execution.plan.calls if c.skill not in _SETTINGS]
    grasps = {e.line: e.detail.removeprefix("grasped ") for e in execution.events if e.kind == "grasp"}
    tree = ast.parse(program)
    import numpy as np

    edits = []
    for c, n in zip(motion, motion[1:]):
        obj = grasps.get(n.line) if n.skill == "close_gripper" else None
        if obj is None or c.line not in verdict.evidence.lines or any(e.line == c.line for e in edits):
            continue
        rows = np.isin(traj.step, [i for i, st in enumerate(traj.steps) if st.line == c.line])
        cols = [k for k, p in enumerate(traj.pairs) if p.group_a == "gripper" and p.b_entity == obj]
        depth = -float(traj.proximity[np.ix_(rows, cols)].min(initial=0.0)) if cols and rows.any() else 0.0
        if depth <= CollisionParams().contact_tolerance_m:
            continue
        d = _cm_up(depth + GRASP_CLEARANCE_M)
        node = _call_named(tree, c.line, c.skill)
        op = None
        if node is not None and c.skill in ("move_to", "move_linear") and len(node.args) == 3:
            op = _shifted(program, node.args[2], d)
        elif node is not None and c.skill == "move_down" and node.args:
            op = _shifted(program, node.args[0], -d, floor=0.0)
        if op is not None:
            edits.append(Edit(verdict.critic, c.line, f"grasp {d:g} m higher on line {c.line}",
                              f"the gripper sinks {depth:.3g} m into the {obj} it grasps on line {n.line}", [op]))  # fmt: skip
    return edits


_BY_CRITIC = {
    "joint_speed": [_slowdowns],
    "end_effector_pose": [_slowdowns],
    "collision": [_spread, _raise_release, _shorter_descent, _grasp_higher, _transit, _turn_fingers, _avoid, _pick_first, _slowdowns],
    "space_usage": [_lower_heights],
    "task_outcome": [_spread],
    "pinch_point": [_natural_posture],
    "runtime": [_reachable, _joint_instead],
}


@hookimpl
def robocritics_repairs(verdict, execution, program):  # type: ignore[no-untyped-def]
    """Every built-in candidate for ``verdict``, in the order :data:`_BY_CRITIC` lists the makers."""
    return [e for make in _BY_CRITIC.get(verdict.critic, []) for e in make(verdict, execution, program)]
