"""The RoboCritics validation protocol (paper, Table 1): embedded critic rules vs. external critic feedback.

Three tasks (recycling — easy, sorting — medium, breakfast — hard), each run
with up to ``--max-attempts`` LLM generation attempts (5 in the paper) under two
conditions:

* **embedded** — the critics' rules (each critic's description and thresholds,
  read from its ``Params``) are pasted into the system prompt. The model never
  sees trace feedback; after each program it is told "Review the program. If
  any part might violate these rules, revise the code to fix it." and it
  revises on its own until it says the program is complete (and changes
  nothing) or the attempts run out.
* **external** — no rules in the prompt; each round the critics check the
  simulated trace and their structured feedback goes back to the model, until
  every critic is OK, the model says the program is complete, or the attempts
  run out.

In both conditions every program is simulated and scored by the five critics
(0–10 program quality index). A reply without code, a program the sandbox
rejects or an unreachable target is fed back as runtime feedback in both
conditions (it is not critic feedback) and counts as an attempt.

Columns: ``attempts`` = model replies used; ``final`` = score of the last
program that ran (0 if none ran); ``best`` = best score of the run; ``goal`` =
whether the final program's simulated end state does the task (objects in the
right containers / on the plate); ``runtime errors`` = attempts whose program
did not run (no code, sandbox, planning, a reply cut at ``--max-tokens``);
``stopped`` = why the run ended ("llm error" when the endpoint failed). Paper
averages: embedded 2.3 attempts, score 6.3; external 5.0 attempts, score 7.7.

Results are kept cell by cell: each finished run (one task, condition and
repeat) is appended to ``--results`` (JSON lines, flushed and synced) at
once, with the configuration it was run with. Running the same command again
resumes: cells already in the file with the same configuration are not run
again (``--fresh`` starts over). One LLM error ends only its cell (recorded
with the error, and run again on resume); Ctrl-C stops after printing the
table of the cells done so far.

Repairs vs LLM (``--repairs``, issue 13): the same three tasks, the model
answering first with the naive program, each run in three modes:

* **llm-only** — ``Loop(repairs=False)``: every Fix round sends the failing
  critics' feedback to the model (the external condition above);
* **repairs+llm** — ``Loop()``: each Fix round first applies the critics' own
  repairs (:func:`robocritics.repair.repair`), then sends only what is left;
* **repairs-only** — one request, then one Fix in ``manual`` automation: the
  repairs alone, the model never asked to fix;

plus the **careful** example program simulated as the reference. Every loop
checks the task's goals (``task_outcome``: the objects in the right
containers / on the plate), so a repair can never trade the task away.
Columns: ``LLM calls`` (model replies, the task included), ``repairs``
(accepted repair edits); ``final score`` (0–10), ``Error left`` (critics
still at Error), ``cycle s`` (motion time, s) and ``goal`` are those of the
program the run hands back (:meth:`Loop.best`: no Error first, then the
highest score); ``CPU s`` (this process's CPU time for the run: simulation,
critics, repairs and the client; the loopback server's thread included).
With the scripted model the model's replies are the same in both
modes, so the difference is the repairs' alone.

Usage::

    python benchmarks/ablation.py --base-url https://api.openai.com/v1 --model gpt-4o-mini \\
        --api-key-env OPENAI_API_KEY [--max-attempts 5] [--repeats 3] [--results ablation.jsonl]
    python benchmarks/ablation.py --base-url http://127.0.0.1:8080/v1 --model smollm2 \\
        --context-tokens 2048 --max-tokens 512 --timeout 120     # a local llama.cpp server
    python benchmarks/ablation.py --selftest     # offline, against the scripted loopback server
    python benchmarks/ablation.py --selftest --repairs    # repairs vs LLM, offline
    python benchmarks/ablation.py --selftest --repairs --stubborn    # ... with a model that never improves

``--selftest`` starts ``tests/llm_server.LLMServer`` on 127.0.0.1 with a
scripted model that answers the task with the naive example program, answers
critic feedback with the careful example program, and says "PROGRAM COMPLETE"
when asked to review its program or when it has nothing better — so the harness
is demonstrably working end to end without any real LLM. ``--stubborn``
replaces it with one that answers everything with the naive program.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import shlex
import statistics
import sys
import time
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
try:
    import robocritics  # noqa: F401
except ImportError:  # run from a checkout without installing
    sys.path.insert(0, str(ROOT / "src"))

from robocritics._files import OutputFileError, check_output_path, open_regular, write_file_atomically  # noqa: E402
from robocritics.errors import LLMError, RoboCriticsError  # noqa: E402
from robocritics.llm.providers.openai_compatible import OpenAICompatible  # noqa: E402
from robocritics.llm.limits import DEFAULT_MAX_TOKENS  # noqa: E402
from robocritics.llm.loop import Attempt, Loop, NothingToFixError  # noqa: E402
from robocritics.llm.prompts import REVIEW_INSTRUCTION  # noqa: E402
from robocritics.scene import Scene  # noqa: E402

#: The paper's three tasks, easiest first, with the request given to the model.
TASKS: dict[str, str] = {
    "recycling": "Discard the coffee cup, the food container and the water bottle into the trash bin, "
    "avoiding collisions.",
    "sorting": "Sort the apples by ripeness: put the ripe red apples into the brown box to make jam and "
    "the unripe green apple into the white box.",
    "breakfast": "Prepare breakfast: throw the fork away into the trash bin, then serve the apple and the "
    "cupcake on the plate. The cupcake sits on top of the apple inside the brown box.",
}
CONDITIONS = ("embedded", "external")
#: Where results are kept (and resumed from) unless --results says otherwise.
DEFAULT_RESULTS = "ablation-results.jsonl"
#: Paper, Table 1 averages: (attempts, final score).
PAPER = {"embedded": (2.3, 6.3), "external": (5.0, 7.7)}


# --- did the program do the task? ------------------------------------------------------------


def _on_plate(execution: Any, obj_id: str) -> bool:
    scene = execution.final_scene
    plate = next(o for o in scene.objects if o.id == "plate")
    obj = next(o for o in scene.objects if o.id == obj_id)
    dx, dy = obj.position[0] - plate.position[0], obj.position[1] - plate.position[1]
    return (
        math.hypot(dx, dy) <= plate.size[0]
        and obj.bottom >= plate.top - 0.01
        and scene.container_holding(obj_id) is None
    )


def goal_reached(task: str, execution: Any) -> bool | None:
    """Whether the simulated end state does ``task`` (None: no execution to judge)."""
    if execution is None:
        return None
    scene = execution.scene
    try:
        if task == "recycling":
            return all(execution.object_inside(o.id, "trash_bin") for o in scene.objects)
        if task == "sorting":
            return all(
                execution.object_inside(o.id, "brown_box" if o.attributes.get("ripeness") == "ripe" else "white_box")
                for o in scene.objects
            )
        if task == "breakfast":
            return (
                execution.object_inside("fork", "trash_bin")
                and _on_plate(execution, "apple")
                and _on_plate(execution, "cupcake")
            )
    except (StopIteration, RoboCriticsError):
        return False
    return None


# --- one run -----------------------------------------------------------------------------------


@dataclass
class Result:
    task: str
    condition: str
    repeat: int
    attempts: int
    final_score: float
    best_score: float
    final_has_error: bool
    goal: bool | None
    stopped: str  # "complete" | "all OK" | "max attempts"
    seconds: float
    runtime_errors: int
    scores: list[float | None] = field(default_factory=list)
    llm_error: str | None = None  # the endpoint's error when the cell ended with one


def run_one(
    model: Any,
    task: str,
    condition: str,
    *,
    max_attempts: int,
    repeat: int = 0,
    model_options: dict | None = None,
    verbose: bool = False,
    context_tokens: int | None = None,
) -> Result:
    """Run one task under one condition with a fresh conversation (no memory) and summarise it."""
    scene = Scene.builtin(task)

    def show(attempt: Attempt) -> None:
        if verbose:
            print(f"  [{task}/{condition}] {attempt.summary()}", file=sys.stderr, flush=True)

    loop = Loop(
        model,
        scene,
        repairs=False,  # the paper's protocol: every fix is the model's (--repairs compares the two)
        embedded_rules=condition == "embedded",
        max_attempts=max_attempts,
        on_attempt=show,
        model_options=model_options,
        context_tokens=context_tokens,
    )
    started = time.monotonic()
    best = loop.run(TASKS[task], feedback="review" if condition == "embedded" else "critics")
    seconds = time.monotonic() - started
    attempts = loop.last_run
    ran = [a for a in attempts if a.report is not None and a.approved is not False]
    final = ran[-1] if ran else None
    last = attempts[-1]
    if last.complete:
        stopped = "complete"
    elif condition == "external" and last.passed:
        stopped = "all OK"
    else:
        stopped = "max attempts"
    return Result(
        task=task,
        condition=condition,
        repeat=repeat,
        attempts=len(attempts),
        final_score=final.score if final is not None else 0.0,
        best_score=best.score if best.score is not None else 0.0,
        final_has_error=final is None or final.report.has_errors,
        goal=goal_reached(task, final.execution) if final is not None else None,
        stopped=stopped,
        seconds=seconds,
        runtime_errors=sum(1 for a in attempts if a.error),
        scores=[a.score for a in attempts],
    )


# --- the table ---------------------------------------------------------------------------------


def _num(values: list[float], digits: int = 1) -> str:  # "-" for no values
    if not values:
        return "-"
    mean = statistics.fmean(values)
    text = f"{mean:.{digits}f}"
    if len(values) > 1:
        text += f" ±{statistics.pstdev(values):.{digits}f}"
    return text


def _goal(values: list[bool | None]) -> str:
    known = [v for v in values if v is not None]
    if not known:
        return "-"
    if len(values) == 1:
        return "yes" if known[0] else "no"
    return f"{sum(known)}/{len(values)}"


def format_table(results: list[Result], tasks: list[str], conditions: list[str]) -> str:
    """Task × condition rows (attempts, final score, best, goal), averages, and the paper's averages."""
    header = ("task", "condition", "attempts", "final score", "best score", "goal", "runtime errors", "stopped")
    rows: list[tuple[str, ...]] = []
    for task in tasks:
        for condition in conditions:
            every = [r for r in results if r.task == task and r.condition == condition]
            if not every:
                continue
            stops = sorted({r.stopped for r in every})
            cell = [r for r in every if r.llm_error is None]  # a cell the endpoint ended has no scores
            rows.append(
                (
                    task,
                    condition,
                    _num([r.attempts for r in cell]),
                    _num([r.final_score for r in cell]),
                    _num([r.best_score for r in cell]),
                    _goal([r.goal for r in cell]),
                    _num([r.runtime_errors for r in cell]),
                    "/".join(stops),
                )
            )
    rows.append(("",) * len(header))
    for condition in conditions:
        cell = [r for r in results if r.condition == condition and r.llm_error is None]
        if cell:
            # average over tasks of the per-task means, as in the paper
            per_task = [[r for r in cell if r.task == t] for t in tasks]
            per_task = [c for c in per_task if c]
            attempts = [statistics.fmean(r.attempts for r in c) for c in per_task]
            scores = [statistics.fmean(r.final_score for r in c) for c in per_task]
            best = [statistics.fmean(r.best_score for r in c) for c in per_task]
            rows.append(
                (
                    "average",
                    condition,
                    f"{statistics.fmean(attempts):.1f}",
                    f"{statistics.fmean(scores):.1f}",
                    f"{statistics.fmean(best):.1f}",
                    _goal([r.goal for r in cell]),
                    f"{statistics.fmean(r.runtime_errors for r in cell):.1f}",
                    "",
                )
            )
    for condition in conditions:
        if condition in PAPER:
            attempts, score = PAPER[condition]
            rows.append(("paper", condition, f"{attempts:.1f}", f"{score:.1f}", "", "", "", ""))
    widths = [max(len(header[i]), *(len(row[i]) for row in rows)) for i in range(len(header))]
    lines = [
        "  ".join(h.ljust(w) for h, w in zip(header, widths)).rstrip(),
        "  ".join("-" * w for w in widths),
    ]
    for row in rows:
        lines.append("  ".join(c.ljust(w) for c, w in zip(row, widths)).rstrip())
    return "\n".join(lines)


# --- the offline self-test: a scripted model on the loopback server ------------------------------

_BREAKFAST_NAIVE = """\
# Breakfast, first try: full speed, straight down onto each object.
rotate_gripper(math.radians(90))
move_to(fork.x, fork.y, fork.z + 0.2)
move_down(0.2)
close_gripper()
move_up(0.2)
move_to(trash_bin.x, trash_bin.y, 0.2)
open_gripper()
rotate_gripper(0)
move_to(cupcake.x, cupcake.y, cupcake.z + 0.2)
move_down(0.2)
close_gripper()
move_up(0.2)
move_to(plate.x + 0.05, plate.y, 0.08)
open_gripper()
move_to(apple.x, apple.y, apple.z + 0.2)
move_down(0.2)
close_gripper()
move_up(0.2)
move_to(plate.x - 0.05, plate.y, 0.06)
open_gripper()
home()
"""

_BREAKFAST_CAREFUL = """\
# Breakfast: throw the fork away, then serve the cupcake and the apple on the plate.
# Careful: moderate speed in free space, slow straight approaches along the fingers,
# lift clear of the box walls before moving sideways; the cupcake comes off the apple first.
lib.set_speed(0.3)


def pick(obj, depth):
    lib.open_gripper()
    lib.move_above(obj, 0.08)
    lib.reduce_speed(15)
    lib.move_linear(obj.x, obj.y, obj.top - depth)
    lib.close_gripper()
    lib.move_up(0.12)
    lib.set_speed(0.3)


def place(x, y, z):
    lib.move_to(x, y, z + 0.1)
    lib.reduce_speed(15)
    lib.move_down(0.1)
    lib.open_gripper()
    lib.move_up(0.1)
    lib.set_speed(0.3)


lib.rotate_gripper(math.radians(90))
pick(fork, 0.006)
lib.move_above(trash_bin, 0.05)
lib.open_gripper()
lib.rotate_gripper(0)
pick(cupcake, 0.02)
place(plate.x + 0.04, plate.y, plate.top + 0.035)
pick(apple, 0.035)
place(plate.x - 0.04, plate.y, plate.top + 0.04)
lib.home()
"""


def example_programs(task: str) -> tuple[str, str]:
    """(naive, careful) programs for ``task``: ``examples/programs/<task>_*.py``, else the ones above."""
    folder = ROOT / "examples" / "programs"
    naive, careful = folder / f"{task}_naive.py", folder / f"{task}_careful.py"
    if naive.exists() and careful.exists():
        return naive.read_text(), careful.read_text()
    if task == "breakfast":
        return _BREAKFAST_NAIVE, _BREAKFAST_CAREFUL
    raise FileNotFoundError(f"no example programs for task {task!r} in {folder}")


def scripted_responder(request: dict) -> str:
    """A stand-in model: naive program first, careful program after critic or runtime feedback,
    "PROGRAM COMPLETE" when asked to review or when it has already given its careful program."""
    messages = request.get("messages", [])
    system = messages[0]["content"] if messages else ""
    found = re.search(r"^# Scene: (\w+)", system, re.MULTILINE)
    if not found:
        return "I do not know this scene."
    naive, careful = example_programs(found.group(1))
    said = [m["content"] for m in messages if m.get("role") == "assistant"]
    last = messages[-1]["content"] if messages else ""
    if not said and last.startswith("Task:"):
        return f"Here is a program for the task:\n\n```python\n{naive}```\n"
    if REVIEW_INSTRUCTION in last:
        return "I reviewed the program against the rules; it does the task. PROGRAM COMPLETE"
    if any(careful.strip() in s for s in said):
        return "I have no further changes. PROGRAM COMPLETE"
    return f"I slowed the robot down and made the approaches straight:\n\n```python\n{careful}```\n"


# --- repairs vs LLM (--repairs) --------------------------------------------------------------------

#: Modes of the repairs-vs-LLM table, in the order printed.
REPAIR_MODES = ("llm-only", "repairs+llm", "repairs-only")


def task_goals(task: str, scene: Scene) -> list[str]:
    """The goals of ``task`` in ``scene`` as ``task_outcome`` goals, the same end state :func:`goal_reached` checks."""
    if task == "recycling":
        return [f"{o.id} in trash_bin" for o in scene.objects]
    if task == "sorting":
        return [f"{o.id} in {'brown_box' if o.attributes.get('ripeness') == 'ripe' else 'white_box'}"
                for o in scene.objects]  # fmt: skip
    if task == "breakfast":
        return ["fork in trash_bin", "apple on plate", "cupcake on plate"]
    raise ValueError(f"no goals for task {task!r}")


@dataclass
class RepairsResult:
    task: str
    mode: str
    llm_calls: int | None  # model replies (None for the careful reference: no model)
    repairs: int  # accepted repair edits
    final_score: float
    errors_left: list[str]  # critics at Error on the final program (["(did not run)"] when none ran)
    cycle_time_s: float | None  # the final program's motion time, s
    cpu_s: float  # process CPU time of the run, s
    goal: bool | None


def _summarise(task: str, mode: str, attempts: list[Attempt], llm_calls: int | None, cpu_s: float) -> RepairsResult:
    ran = [a for a in attempts if a.report is not None and a.approved is not False]
    final = Loop.best(ran) if ran else None  # the program the run hands back: no Error first, then best score
    return RepairsResult(
        task=task,
        mode=mode,
        llm_calls=llm_calls,
        repairs=sum(len(a.changes) for a in attempts if a.source == "repair" and a.approved is not False),
        final_score=final.score if final is not None else 0.0,
        errors_left=["(did not run)"] if final is None else [v.critic for v in final.report.verdicts
                                                               if v.flag.name == "ERROR"],  # fmt: skip
        cycle_time_s=final.execution.duration_s if final is not None else None,
        cpu_s=cpu_s,
        goal=goal_reached(task, final.execution) if final is not None else None,
    )


def run_repairs_one(model: Any, task: str, mode: str, *, max_attempts: int, model_options: dict | None = None,
                    context_tokens: int | None = None, verbose: bool = False) -> RepairsResult:  # fmt: skip
    """Run ``task`` in one mode of :data:`REPAIR_MODES` with a fresh conversation (no memory)."""
    if mode not in REPAIR_MODES:
        raise ValueError(f"mode must be one of {', '.join(REPAIR_MODES)}, got {mode!r}")
    scene = Scene.builtin(task)

    def show(attempt: Attempt) -> None:
        if verbose:
            print(f"  [{task}/{mode}] {attempt.summary()}", file=sys.stderr, flush=True)

    loop = Loop(model, scene, goals=task_goals(task, scene), repairs=mode != "llm-only", max_attempts=max_attempts,
                automation="manual" if mode == "repairs-only" else "guided", on_attempt=show,
                model_options=model_options, context_tokens=context_tokens)  # fmt: skip
    started = time.process_time()
    if mode == "repairs-only":
        loop.request(TASKS[task])
        try:
            loop.fix()  # manual automation: the repairs only, never the model
        except NothingToFixError:
            pass  # every critic passed already
        except LLMError:
            raise
        except RoboCriticsError:
            pass  # the program did not run, or no repair applied: the request's program stays
        attempts = loop.attempts
    else:
        loop.run(TASKS[task])
        attempts = loop.last_run
    cpu_s = time.process_time() - started
    return _summarise(task, mode, attempts, sum(1 for a in attempts if a.source == "llm"), cpu_s)


def careful_reference(task: str) -> RepairsResult:
    """The careful example program simulated and critiqued with the task's goals (no model, no repairs)."""
    from robocritics.critic import critique
    from robocritics.pipeline import simulate

    scene = Scene.builtin(task)
    started = time.process_time()
    execution = simulate(example_programs(task)[1], scene)
    report = critique(execution, scene, goals=task_goals(task, scene))
    cpu_s = time.process_time() - started
    attempt = Attempt(index=1, kind="user", request=TASKS[task], prompt="", reply="", program="",
                      execution=execution, report=report, score=report.score)  # fmt: skip
    return _summarise(task, "careful", [attempt], None, cpu_s)


def format_repairs_table(results: list[RepairsResult]) -> str:
    """One row per task and mode: LLM calls, repairs, final score, Error left, cycle time s, CPU s, goal."""
    header = ("task", "mode", "LLM calls", "repairs", "final score", "Error left", "cycle s", "CPU s", "goal")
    rows = [
        (
            r.task,
            r.mode,
            "-" if r.llm_calls is None else str(r.llm_calls),
            str(r.repairs),
            f"{r.final_score:.1f}",
            ",".join(r.errors_left) or "none",
            "-" if r.cycle_time_s is None else f"{r.cycle_time_s:.2f}",
            f"{r.cpu_s:.2f}",
            _goal([r.goal]),
        )
        for r in results
    ]
    widths = [max(len(header[i]), *(len(row[i]) for row in rows)) for i in range(len(header))]
    lines = ["  ".join(h.ljust(w) for h, w in zip(header, widths)).rstrip(), "  ".join("-" * w for w in widths)]
    lines += ["  ".join(c.ljust(w) for c, w in zip(row, widths)).rstrip() for row in rows]
    return "\n".join(lines)


def stubborn_responder(request: dict) -> str:
    """A stand-in model that never improves: the naive program for the task, whatever it is told."""
    messages = request.get("messages", [])
    found = re.search(r"^# Scene: (\w+)", messages[0]["content"] if messages else "", re.MULTILINE)
    if not found:
        return "I do not know this scene."
    return f"Here is a program for the task:\n\n```python\n{example_programs(found.group(1))[0]}```\n"


# --- command line ---------------------------------------------------------------------------------


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        description="RoboCritics validation protocol (paper Table 1): embedded critic rules vs. external "
        "critic feedback, on the recycling, sorting and breakfast tasks.",
    )
    p.add_argument("--base-url", metavar="URL", help="OpenAI-compatible endpoint (default: $ROBOCRITICS_BASE_URL)")
    p.add_argument("--model", metavar="NAME", help="chat model (default: $ROBOCRITICS_MODEL)")
    p.add_argument("--api-key-env", metavar="VAR", help="environment variable holding the API key")
    p.add_argument("--selftest", action="store_true", help="run offline against the scripted loopback server")
    p.add_argument("--stubborn", action="store_true",
                   help="with --selftest: the scripted model answers everything with the naive program (a model "
                   "that never improves)")
    p.add_argument("--tasks", default=",".join(TASKS), help=f"comma-separated tasks (default: {','.join(TASKS)})")
    p.add_argument("--conditions", default=",".join(CONDITIONS), help="comma-separated conditions (default: both)")
    p.add_argument("--max-attempts", type=int, default=5, help="LLM generation attempts per run (paper: 5)")
    p.add_argument("--repeats", type=int, default=1, help="runs per task and condition (LLMs are stochastic)")
    p.add_argument("--temperature", type=float, default=None, help="sampling temperature (client default 0)")
    p.add_argument("--seed", type=int, default=None, help="sampling seed, for servers that honour it")
    p.add_argument("--timeout", type=float, default=300.0,
                   help="seconds one LLM request may take in all, retries included (default 300)")
    p.add_argument("--max-tokens", type=int, default=DEFAULT_MAX_TOKENS,
                   help=f"most tokens per model reply (default {DEFAULT_MAX_TOKENS})")
    p.add_argument("--context-tokens", type=int, default=None,
                   help="the model's context window, to fit prompts to (default: what the server says)")
    p.add_argument("--no-stream", action="store_true", help="ask for whole replies instead of streamed ones")
    p.add_argument("--results", metavar="FILE", default=None,
                   help="JSON-lines file each finished cell is appended to, and resumed from (default "
                   f"{DEFAULT_RESULTS}; none with --selftest)")
    p.add_argument("--fresh", action="store_true", help="ignore (and replace) the cells already in --results")
    p.add_argument("--json", metavar="FILE", help="also write every run's results as one JSON list")
    p.add_argument("--repairs", action="store_true",
                   help="the repairs-vs-LLM table (llm-only, repairs+llm, repairs-only, careful) instead of the "
                   "embedded/external protocol; --conditions, --repeats and --results do not apply")
    p.add_argument("-v", "--verbose", action="store_true", help="print each attempt as it happens (stderr)")
    return p


def _reproduce(args: argparse.Namespace, model_name: str, base_url: str) -> str:
    if args.selftest:
        parts = ["python", "benchmarks/ablation.py", "--selftest"] + (["--stubborn"] if args.stubborn else [])
    else:
        parts = ["python", "benchmarks/ablation.py", "--base-url", base_url, "--model", model_name]
        if args.api_key_env:
            parts += ["--api-key-env", args.api_key_env]
    if args.repairs:
        parts.append("--repairs")
    if args.tasks != ",".join(TASKS):
        parts += ["--tasks", args.tasks]
    if args.conditions != ",".join(CONDITIONS) and not args.repairs:
        parts += ["--conditions", args.conditions]
    parts += ["--max-attempts", str(args.max_attempts)]
    if not args.repairs:
        parts += ["--repeats", str(args.repeats)]
    parts += ["--timeout", f"{args.timeout:g}", "--max-tokens", str(args.max_tokens)]
    if args.context_tokens is not None:
        parts += ["--context-tokens", str(args.context_tokens)]
    if args.no_stream:
        parts.append("--no-stream")
    if args.results and not args.repairs:
        parts += ["--results", args.results]
    if args.temperature is not None:
        parts += ["--temperature", str(args.temperature)]
    if args.seed is not None:
        parts += ["--seed", str(args.seed)]
    return " ".join(shlex.quote(p) for p in parts)


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    tasks = [t.strip() for t in args.tasks.split(",") if t.strip()]
    conditions = [c.strip() for c in args.conditions.split(",") if c.strip()]
    bad = [t for t in tasks if t not in TASKS] + [c for c in conditions if c not in CONDITIONS]
    if bad or not tasks or not conditions:
        print(f"ablation: unknown or missing tasks/conditions: {', '.join(bad) or '(none given)'}", file=sys.stderr)
        return 2
    if args.stubborn and not args.selftest:
        print("ablation: --stubborn is a scripted model: use it with --selftest", file=sys.stderr)
        return 2
    if args.max_attempts < 1 or args.repeats < 1:
        print("ablation: --max-attempts and --repeats must be at least 1", file=sys.stderr)
        return 2
    for option, path in (("--json", args.json), ("--results", args.results or (None if args.selftest else DEFAULT_RESULTS))):
        try:  # before any run: a link, directory or FIFO at the name is refused (the project's safe writer)
            if path is not None:
                check_output_path(path, option)
        except OutputFileError as exc:
            print(f"ablation: {exc}", file=sys.stderr)
            return 2

    server = None
    if args.selftest:
        sys.path.insert(0, str(ROOT / "tests"))
        from llm_server import LLMServer  # the test suite's loopback server

        if args.stubborn:
            server = LLMServer(responder=stubborn_responder).start()
            base_url, model_name, api_key = server.url, "scripted-always-naive", None
        else:
            server = LLMServer(responder=scripted_responder).start()
            base_url, model_name, api_key = server.url, "scripted-naive-then-careful", None
    else:
        base_url = args.base_url or os.environ.get("ROBOCRITICS_BASE_URL")
        model_name = args.model or os.environ.get("ROBOCRITICS_MODEL")
        api_key = None
        if args.api_key_env:
            api_key = os.environ.get(args.api_key_env)
            if not api_key:
                print(f"ablation: the environment variable {args.api_key_env} is not set", file=sys.stderr)
                return 2
        if not base_url or not model_name:
            print("ablation: give --base-url and --model (or set ROBOCRITICS_BASE_URL / ROBOCRITICS_MODEL), "
                  "or use --selftest", file=sys.stderr)  # fmt: skip
            return 2
    options: dict[str, Any] = {}
    if args.temperature is not None:
        options["temperature"] = args.temperature
    if args.seed is not None:
        options["seed"] = args.seed

    if args.max_tokens < 1 or (args.context_tokens is not None and args.context_tokens < 512):
        print("ablation: --max-tokens must be at least 1 and --context-tokens at least 512", file=sys.stderr)
        if server is not None:
            server.stop()
        return 2
    if args.repairs:
        try:
            return _repairs_main(args, tasks, base_url, model_name, api_key, options)
        finally:
            if server is not None:
                server.stop()
    results_path = Path(args.results) if args.results else (None if args.selftest else Path(DEFAULT_RESULTS))
    if args.results is None and results_path is not None:
        args.results = str(results_path)
    config = {
        "model": model_name,
        "base_url": "(self-test)" if args.selftest else base_url,  # the self-test's port changes every run
        "max_attempts": args.max_attempts,
        "max_tokens": args.max_tokens,
        "context_tokens": args.context_tokens,
        "temperature": args.temperature,
        "seed": args.seed,
    }
    results = [] if results_path is None or args.fresh else load_results(results_path, config)
    if results_path is not None and args.fresh and results_path.exists():
        results_path.unlink()
    done = {(r.task, r.condition, r.repeat) for r in results if r.llm_error is None}
    results = [r for r in results if r.llm_error is None]  # failed cells are run again
    cells = [(repeat, task, condition) for repeat in range(args.repeats) for task in tasks for condition in conditions]
    todo = [c for c in cells if (c[1], c[2], c[0]) not in done]
    if done:
        print(f"ablation: resuming from {results_path}: {len(cells) - len(todo)} of {len(cells)} cells already done",
              file=sys.stderr)  # fmt: skip

    interrupted = False
    failed = 0
    try:
        with OpenAICompatible(
            base_url=base_url,
            model=model_name,
            api_key=api_key,
            timeout_s=min(args.timeout, 120.0),
            deadline_s=args.timeout,
            max_tokens=args.max_tokens,
            stream=not args.no_stream,
        ) as client:
            context = args.context_tokens if args.context_tokens is not None else client.server_context_tokens()
            for repeat, task, condition in todo:
                started = time.monotonic()
                try:
                    result = run_one(
                        client,
                        task,
                        condition,
                        max_attempts=args.max_attempts,
                        repeat=repeat,
                        model_options=options,
                        verbose=args.verbose,
                        context_tokens=context,
                    )
                except (LLMError, RoboCriticsError) as exc:  # the endpoint failed, or no prompt fits: this cell only
                    failed += 1
                    print(f"  [{task}/{condition}] failed: {exc}", file=sys.stderr, flush=True)
                    result = Result(
                        task=task, condition=condition, repeat=repeat, attempts=0, final_score=0.0, best_score=0.0,
                        final_has_error=True, goal=None, stopped="llm error", seconds=time.monotonic() - started,
                        runtime_errors=0, llm_error=str(exc),
                    )  # fmt: skip
                else:
                    results.append(result)
                if results_path is not None:
                    append_result(results_path, result, config)
                if args.verbose:
                    print(
                        f"  [{task}/{condition}] {result.attempts} attempts, final score "
                        f"{result.final_score:g}, stopped: {result.stopped}",
                        file=sys.stderr,
                        flush=True,
                    )
    except KeyboardInterrupt:
        interrupted = True
    finally:
        if server is not None:
            server.stop()

    what = f"scripted loopback model {model_name} (self-test)" if args.selftest else f"{model_name} at {base_url}"
    print(
        f"RoboCritics validation protocol (paper Table 1): {what}; up to {args.max_attempts} attempts, "
        f"{args.repeats} run(s) per cell"
    )
    print()
    print(format_table(results, tasks, conditions))
    print()
    print(f"Reproduce: {_reproduce(args, model_name, base_url)}")
    if results_path is not None:
        print(f"Results (one JSON line per cell, resumable): {results_path}")
    if args.json:
        write_file_atomically(args.json, json.dumps([asdict(r) for r in results], indent=2), "--json")
        print(f"Results written to {args.json}")
    if interrupted:
        kept = f"; they are in {results_path}: run the same command to resume" if results_path else ""
        print(f"Interrupted: {len(results)} of {len(cells)} cells done{kept}", file=sys.stderr)
        return 130
    if failed:
        print(f"ablation: {failed} cell(s) ended with an LLM error; run the same command again to retry them",
              file=sys.stderr)  # fmt: skip
        return 1
    return 0


def _repairs_main(args: argparse.Namespace, tasks: list[str], base_url: str, model_name: str, api_key: str | None,
                  options: dict[str, Any]) -> int:  # fmt: skip
    """``--repairs``: every task in every mode, then the table and the command that reproduces it."""
    results: list[RepairsResult] = []
    failed = 0
    with OpenAICompatible(base_url=base_url, model=model_name, api_key=api_key, timeout_s=min(args.timeout, 120.0),
                          deadline_s=args.timeout, max_tokens=args.max_tokens,
                          stream=not args.no_stream) as client:  # fmt: skip
        context = args.context_tokens if args.context_tokens is not None else client.server_context_tokens()
        careful_reference(tasks[0])  # warm-up, not counted: the first simulation loads the robot model and caches
        for task in tasks:
            for mode in REPAIR_MODES:
                try:
                    results.append(run_repairs_one(client, task, mode, max_attempts=args.max_attempts,
                                                   model_options=options, context_tokens=context,
                                                   verbose=args.verbose))  # fmt: skip
                except (LLMError, RoboCriticsError) as exc:  # the endpoint failed, or no prompt fits: this run only
                    failed += 1
                    print(f"  [{task}/{mode}] failed: {exc}", file=sys.stderr, flush=True)
            results.append(careful_reference(task))
    what = f"scripted loopback model {model_name} (self-test)" if args.selftest else f"{model_name} at {base_url}"
    print(f"Repairs vs LLM on the naive programs: {what}; up to {args.max_attempts} model replies per run; "
          "task goals checked (task_outcome)")  # fmt: skip
    print()
    print(format_repairs_table(results))
    print()
    print(f"Reproduce: {_reproduce(args, model_name, base_url)}")
    if args.json:
        write_file_atomically(args.json, json.dumps([asdict(r) for r in results], indent=2), "--json")
        print(f"Results written to {args.json}")
    if failed:
        print(f"ablation: {failed} run(s) ended with an LLM error", file=sys.stderr)
        return 1
    return 0


# --- the results file -----------------------------------------------------------------------------


def append_result(path: Path, result: Result, config: dict) -> None:
    """Append one cell to the JSON-lines file ``path``, flushed and synced before returning."""
    line = json.dumps({"config": config, **asdict(result)}, allow_nan=False) + "\n"
    with open_regular(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, "results file") as f:  # never through a link
        f.write(line.encode("utf-8"))
        f.flush()
        os.fsync(f.fileno())


def load_results(path: Path, config: dict) -> list[Result]:
    """The cells of ``path`` run with ``config`` (the last one of each task/condition/repeat).

    A line that is not a whole JSON record (the process died while writing
    it) and cells of another configuration are skipped, saying so.
    """
    if not path.exists():
        return []
    names = {f.name for f in fields(Result)}
    found: dict[tuple, Result] = {}
    broken = other = 0
    for line in path.read_text(encoding="utf-8").splitlines():
        if not line.strip():
            continue
        try:
            record = json.loads(line)
            if record.pop("config", None) != config:
                other += 1
                continue
            result = Result(**{k: v for k, v in record.items() if k in names})
        except (ValueError, TypeError, AttributeError):
            broken += 1
            continue
        found[(result.task, result.condition, result.repeat)] = result
    if broken:
        print(f"ablation: {broken} unreadable line(s) in {path} skipped", file=sys.stderr)
    if other:
        print(f"ablation: {other} cell(s) in {path} were run with another configuration; not reused", file=sys.stderr)
    return list(found.values())


if __name__ == "__main__":
    sys.exit(main())
