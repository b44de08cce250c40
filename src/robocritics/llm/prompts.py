"""Prompts for the language model, and reading its replies.

What the model is told, turn by turn (the RoboCritics workflow, Fig. 2):

* :func:`system_prompt` — the skill API (:func:`~robocritics.program.skills.api_reference`),
  the scene (every object and container with id, shape, position, size, top and
  attributes; the table; the allowed workspace; units), the rules of the
  conversation, optionally the critics' rules (the paper's *embedded*
  condition, thresholds read from each critic's ``Params``) and retrieved past
  interactions from the interaction memory;
* :func:`request_prompt` — the user's task;
* :func:`fix_prompt` — the critics' structured feedback (:meth:`Report.feedback`)
  plus the program with the lines the critics point at marked;
* :func:`runtime_feedback` — a program the sandbox rejected, a motion that
  could not be planned, or a reply without code, as a message the model can act on;
* :data:`REVIEW_INSTRUCTION` — the embedded condition's self-review turn;
* :func:`truncated_feedback` — a reply the server cut at its token limit.

Size: :func:`estimate_tokens` is the cheap prompt-size estimate (characters /
``llm.limits.CHARS_PER_TOKEN``, plus 4 tokens per message: an over-estimate for
the BPE tokenizers of small open models); ``system_prompt(compact_api=True)``
uses :func:`compact_api_reference` (one line per skill) for small contexts.

Reading replies: :func:`extract_code` finds the program, :func:`says_complete`
the model's "PROGRAM COMPLETE".
"""

from __future__ import annotations

import ast
import heapq
import inspect
import math
import re
import textwrap
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from ..errors import CriticError, LLMError, PlanningError, ProgramError, RoboCriticsError
from ..critic.report import format_score
from .limits import CHARS_PER_TOKEN, MAX_FEEDBACK_CHARS, MAX_REPLY_CHARS, MAX_TASK_CHARS, clean_text, cut_text

if TYPE_CHECKING:  # pragma: no cover
    from ..critic import Report
    from ..scene import Scene

__all__ = [
    "COMPLETE_MARKER",
    "PromptError",
    "compact_api_reference",
    "estimate_tokens",
    "truncated_feedback",
    "REVIEW_INSTRUCTION",
    "critic_rules",
    "describe_scene",
    "extract_code",
    "fix_prompt",
    "format_memory_examples",
    "numbered_program",
    "request_prompt",
    "runtime_feedback",
    "says_complete",
    "system_prompt",
]

#: What the model says, with no code, when it is satisfied with its program.
COMPLETE_MARKER = "PROGRAM COMPLETE"

#: The embedded condition's self-review turn (paper, validation protocol).
REVIEW_INSTRUCTION = "Review the program. If any part might violate these rules, revise the code to fix it."

_COMPLETE = re.compile(r"\bPROGRAM[\s_-]*COMPLETE\b", re.IGNORECASE)

# Retrieved memory examples are shown compactly: programs and feedback are cut at these sizes.
_EXAMPLE_PROGRAM_LINES = 40
_EXAMPLE_FEEDBACK_CHARS = 600
_EXAMPLE_REQUEST_CHARS = 300
# Programs longer than this are quoted only around the flagged lines in fix prompts,
# with this many lines of context on each side.
_FULL_LISTING_LINES = 80
_FLAGGED_CONTEXT_LINES = 2
# A reply without code is quoted this far back to the model: enough to recognise it, not to re-send it.
_REPLY_EXCERPT_CHARS = 200
# Characters of one program line quoted in a prompt: far wider than any sensible line.
_LISTED_LINE_CHARS = 300
# Characters of a program listing in a fix prompt: the rest of the message is feedback and instructions.
_LISTING_CHARS = 16_000


class PromptError(RoboCriticsError, ValueError):
    """A prompt cannot be built within its limits (e.g. a task description that is too long)."""


# --- system prompt --------------------------------------------------------------------------


def _m(value: float) -> str:
    """A length in metres: at least three decimals (mm), a fourth when it is not zero."""
    text = f"{value:.4f}"
    if text.endswith("0"):
        text = text[:-1]
    return text[1:] if text.startswith("-") and float(text) == 0 else text


def _xyz(values: Iterable[float]) -> str:
    return "(" + ", ".join(_m(v) for v in values) + ")"


def _attributes(attributes: Mapping[str, Any]) -> str:
    return ", ".join(f"{k}={v}" for k, v in attributes.items())


def _shape_text(obj: Any) -> str:
    size = obj.size
    if obj.shape == "box":
        return f"box {_m(size[0])} x {_m(size[1])} x {_m(size[2])} m (x, y, z)"
    if obj.shape == "cylinder":
        return f"upright cylinder, radius {_m(size[0])} m, height {_m(size[1])} m"
    if obj.shape == "mesh":
        return f"fixture (CAD mesh, not graspable), bounding box {_m(size[0])} x {_m(size[1])} x {_m(size[2])} m, top z {_m(obj.top)} m"
    return f"sphere, radius {_m(size[0])} m"


def describe_scene(scene: "Scene") -> str:
    """The scene as the model sees it: every object and container, the table, the workspace, units."""
    lines = [f"# Scene: {scene.name}", ""]
    if scene.description:
        lines += [scene.description.strip(), ""]
    lines.append(
        "Units: metres; coordinates in the robot base frame (x forward, y left, z up); "
        "angles in radians. Positions below are centres; `top` is the z of the top surface."
    )
    table = scene.table
    lines.append(
        f"Table: top surface at z = {_m(table.top_z)} m, {_m(table.size[0])} x {_m(table.size[1])} m "
        f"centred at (x, y) = ({_m(table.center_xy[0])}, {_m(table.center_xy[1])})."
    )
    ws = scene.workspace
    if ws is None:  # the scene follows its robot; the prompt describes the default arm's reach
        from ..robot.model import default_workspace

        ws = default_workspace()
    lines.append(
        f"Allowed workspace: a sphere of radius {_m(ws.radius_m)} m around {_xyz(ws.center)} "
        f"(volume {ws.volume_m3:.3f} m^3); every part of the robot must stay inside it."
    )
    lines += ["", "Objects:"]
    if not scene.objects:
        lines.append("- (none)")
    for o in scene.objects:
        text = f"- {o.id}: {_shape_text(o)}; centre {_xyz(o.centre)}; top z = {_m(o.top)}"
        if any(abs(a) > 1e-9 for a in o.rpy):
            text += f"; rotated rpy {_xyz(o.rpy)} rad"
        text += "; graspable" if o.graspable else "; NOT graspable (fixed)"
        if o.attributes:
            text += f"; {_attributes(o.attributes)}"
        lines.append(text)
    lines += ["", "Containers (open-top boxes: lower objects in from above the rim; the walls are obstacles):"]
    if not scene.containers:
        lines.append("- (none)")
    for c in scene.containers:
        text = (
            f"- {c.id}: box {_m(c.size[0])} x {_m(c.size[1])} x {_m(c.size[2])} m (outer, x, y, z); "
            f"centre {_xyz(c.position)}; rim (top) z = {_m(c.top)}; inside floor z = {_m(c.floor_top)}; "
            f"walls {_m(c.wall_m)} m"
        )
        if abs(c.yaw) > 1e-9:
            text += f"; yaw {c.yaw:.3f} rad"
        if c.attributes:
            text += f"; {_attributes(c.attributes)}"
        lines.append(text)
    return "\n".join(lines)


_RULES = f"""\
# Rules
1. Use only the skills and names of the API above: no other imports, libraries or robot commands.
2. Positions are metres in the robot base frame (x forward, y left, z up; the table top is z = 0).
   Prefer the scene variables (e.g. `green_apple.x`, `white_box.top`) to copied numbers.
3. Answer with the complete program in exactly one ```python code block. Every revision is the
   whole program again, not a fragment or a diff.
4. The program is simulated before the robot moves. You will be told if it fails to run, if a
   motion cannot be planned, or what expert critics found in the simulated motion; then revise it.
5. When asked to revise and you are satisfied that the current program needs no change, answer
   "{COMPLETE_MARKER}" with no code.
6. State where each object you move should end up with `expect(obj, inside=container)` or
   `expect(obj, on=support)`; the final scene is checked against it."""


def _clean_description(text: str) -> str:
    """A Params field description without its '(source: ...)' note."""
    return re.sub(r"\s*\(source:[^)]*\)", "", text or "").strip()


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def critic_rules(critics: Iterable[Any] | str | None = None, params: Mapping[str, Any] | None = None) -> str:
    """The critics' rules for the *embedded* condition: each critic's description and thresholds.

    Thresholds are the numeric fields of each critic's ``Params`` (its defaults,
    or ``params`` overrides as in :func:`~robocritics.critic.critique`), with the
    field's own description; numerical tolerances (fields named ``*tolerance*``)
    are left out. Raises :class:`~robocritics.errors.CriticError`
    for unknown critics or parameters.
    """
    from ..critic import select_critics

    out = [
        "# Safety and quality rules",
        "Expert critics will check the simulated motion of the program against these rules. Each "
        "critic rates it OK (2 points), Warning (1) or Error (0); the quality score (0-10) is the sum over "
        "the five motion critics (space_usage, collision, joint_speed, end_effector_pose, pinch_point); "
        "any other critic is reported beside it and must pass too.",
    ]
    for critic, p in select_critics(critics, params):
        out.append(f"- {critic.name}: {critic.description}")
        fields = type(p).model_fields
        for field_name, info in fields.items():
            value = getattr(p, field_name)
            if not _is_number(value) or "tolerance" in field_name:
                continue  # thresholds only: numerical tolerances and frame lists say nothing to the model
            description = _clean_description(info.description or "")
            out.append(f"    - {field_name} = {value:g}" + (f": {description}" if description else ""))
    out.append(REVIEW_INSTRUCTION)
    return "\n".join(out)


def _field(item: Any, name: str, default: Any = "") -> Any:
    if isinstance(item, Mapping):
        return item.get(name, default)
    return getattr(item, name, default)


def _cut_lines(text: str, max_lines: int) -> str:
    lines = text.rstrip().splitlines()
    if len(lines) <= max_lines:
        return "\n".join(lines)
    return "\n".join(lines[:max_lines] + [f"# ... ({len(lines) - max_lines} more lines)"])


def _cut(text: str, max_chars: int) -> str:
    text = " ".join(text.split())
    return text if len(text) <= max_chars else text[: max_chars - 3].rstrip() + "..."


def _score_text(score: Any) -> str:
    return "not scored (it did not run)" if score is None else format_score(float(score))


def format_memory_examples(examples: Iterable[Any]) -> str:
    """Past interactions (``request``, ``program``, ``feedback``, ``score``), compactly, for the system prompt.

    Items are :class:`~robocritics.llm.memory.Interaction` objects or mappings
    with those keys. Programs and feedback are cut short (``_EXAMPLE_PROGRAM_LINES``,
    ``_EXAMPLE_FEEDBACK_CHARS``).
    Returns "" for no examples.
    """
    parts = []
    for i, item in enumerate(examples, 1):
        program = str(_field(item, "program") or "").strip()
        if not program:
            continue
        feedback = str(_field(item, "feedback") or "").strip()
        parts.append(
            f"## Past interaction {i}\n"
            f"Request: {_cut(str(_field(item, 'request')), _EXAMPLE_REQUEST_CHARS)}\n"
            f"Score: {_score_text(_field(item, 'score', None))}\n"
            f"Program:\n```python\n{_cut_lines(program, _EXAMPLE_PROGRAM_LINES)}\n```\n"
            f"Critic feedback: {_cut(feedback, _EXAMPLE_FEEDBACK_CHARS) if feedback else '(none)'}"
        )
    if not parts:
        return ""
    head = (
        "# Relevant past interactions\n"
        "From the interaction memory: earlier requests, the programs written for them and what the "
        "critics said. Reuse what worked and avoid what was criticised; the current scene above is "
        "authoritative."
    )
    return "\n\n".join([head, *parts])


def compact_api_reference(level: str = "compact") -> str:
    """The skill API in fewer tokens than ``api_reference()``, for models with a small context.

    ``"compact"`` (about half): the conventions and language rules without the
    example, then one line per skill (signature and the first sentence of its
    docstring). ``"minimal"`` (about a fifth): the conventions in a few lines
    and the signatures alone.
    """
    from ..program.skills import SKILLS, api_reference, usage

    if level not in ("compact", "minimal"):
        raise ValueError(f"level must be 'compact' or 'minimal', got {level!r}")
    if level == "minimal":
        return "\n".join(
            [
                "# Robot program API (short form)",
                "Python calling the skills below. Metres, radians, seconds; base frame x forward, y left, z up; "
                "table top z = 0; fingertips point down. `math`, helper functions, loops and `if` are allowed; "
                "no other imports, classes, try/except or files.",
                "Scene objects and containers are variables named by their id, with fields x, y, z (centre), "
                "top, bottom, size, floor (containers) and every attribute by name (e.g. green_apple.ripeness); "
                "`objects` and `containers` list them.",
                "Skills:",
                *(f"- {usage(name)}" for name in SKILLS),
            ]
        )
    head = api_reference().split("## Skills", 1)[0]
    head = head.split("\nExample:", 1)[0].rstrip()
    lines = [head, "", "## Skills (signature - what it does)"]
    for name, fn in SKILLS.items():
        doc = inspect.cleandoc(fn.__doc__ or "").split("\n\n", 1)[0]
        first = " ".join(doc.split())
        first = first.split(". ", 1)[0].rstrip(".")
        lines.append(f"- {usage(name)} - {first}.")
    lines.append("- print(*values) - Show values in the program's output (for debugging).")
    return "\n".join(lines)


_SHORT_RULES = f"""\
# Rules
Use only the API's skills and the scene variables. Answer with the complete program in one ```python
block; every revision is the whole program again. It is simulated and checked first; you will be told
what failed. When asked to revise and the program needs no change, answer "{COMPLETE_MARKER}".
State where each moved object should end with expect(obj, inside=box) or expect(obj, on=support)."""


def estimate_tokens(messages: str | Iterable[Mapping[str, Any]]) -> int:
    """A cheap, deliberately high estimate of the tokens of a text or a list of chat messages.

    ``ceil(characters / CHARS_PER_TOKEN)`` per text, plus 4 tokens per message
    (role and chat-template markers). Real BPE tokenizers of small open models
    (SmolLM2, Llama, Qwen) give 3.2-4 characters per token on these prompts,
    so a prompt fitted with this estimate fits.
    """
    if isinstance(messages, str):
        return math.ceil(len(messages) / CHARS_PER_TOKEN)
    total = 0
    for message in messages:
        content = message.get("content", "")
        total += math.ceil(len(content if isinstance(content, str) else str(content)) / CHARS_PER_TOKEN) + 4
    return total


def system_prompt(
    scene: "Scene",
    *,
    embedded_rules: bool = False,
    memory_examples: Iterable[Any] = (),
    critics: Iterable[Any] | str | None = None,
    params: Mapping[str, Any] | None = None,
    compact_api: bool | str = False,
) -> str:
    """The system message: role, skill API, scene, rules; optionally critic rules and memory examples.

    ``embedded_rules=True`` pastes in :func:`critic_rules` for ``critics`` /
    ``params`` (the paper's *embedded* condition). ``memory_examples`` are past
    interactions (see :func:`format_memory_examples`). ``compact_api=True``
    (or ``"compact"``) gives the skill API in one line per skill, ``"minimal"``
    its signatures alone and the rules in brief (:func:`compact_api_reference`),
    for models with a small context.
    """
    level = "compact" if compact_api is True else (compact_api or "")
    from ..program.skills import api_reference

    parts = [
        "You write programs for a UR3e robot arm with a two-finger gripper, standing on a table. "
        "Each program is simulated and checked for safety before the robot runs it.",
        (compact_api_reference(level) if level else api_reference()).strip(),
        describe_scene(scene),
        _SHORT_RULES if level == "minimal" else _RULES,
    ]
    if embedded_rules:
        parts.append(critic_rules(critics, params))
    examples = format_memory_examples(memory_examples)
    if examples:
        parts.append(examples)
    return "\n\n".join(parts) + "\n"


# --- user turns -------------------------------------------------------------------------------


def check_task(text: str) -> str:
    """``text`` stripped and cleaned of lone surrogates, if it is a usable task description.

    Raises :class:`PromptError` for a task that is empty or longer than
    ``MAX_TASK_CHARS`` characters.
    """
    if not isinstance(text, str) or not text.strip():
        raise PromptError("the task description is empty: say what the robot should do")
    text = clean_text(text.strip())
    if len(text) > MAX_TASK_CHARS:
        raise PromptError(
            f"the task description is {len(text):,} characters long; the limit is {MAX_TASK_CHARS:,} "
            "(llm.limits.MAX_TASK_CHARS): describe the task in a few sentences"
        )
    return text


def request_prompt(text: str) -> str:
    """The user's task as the first message of a request (see :func:`check_task` for what is refused)."""
    return f"Task: {check_task(text)}\n\nWrite the complete program."


def numbered_program(program: str, marked: Iterable[int] = (), *, context: int | None = None) -> str:
    """``program`` with right-aligned line numbers; lines in ``marked`` start with ``>>``.

    With ``context`` (a number of lines), only the marked lines and that many
    lines around each are shown; gaps are shown as ``...``. Lines longer than
    ``_LISTED_LINE_CHARS`` are cut, saying so.
    """
    lines = program.rstrip("\n").splitlines()
    marked = {int(n) for n in marked}
    width = len(str(max(len(lines), 1)))
    show = set(range(1, len(lines) + 1))
    if context is not None and marked:
        show = {n for m in marked for n in range(m - context, m + context + 1) if 1 <= n <= len(lines)}
    out, previous = [], 0
    for n in sorted(show):
        if previous and n != previous + 1:
            out.append("    ...")
        line = cut_text(lines[n - 1], _LISTED_LINE_CHARS, "characters of this line")
        out.append(f"{'>>' if n in marked else '  '} {n:>{width}} | {line}".rstrip())
        previous = n
    return "\n".join(out)


def _flagged_lines(report: "Report", critics: Iterable[str] | None) -> list[int]:
    names = None if critics is None else ({critics} if isinstance(critics, str) else set(critics))
    lines: set[int] = set()
    for v in report.verdicts:
        if v.ok or (names is not None and v.critic not in names):
            continue
        lines.update(v.evidence.lines)
    return sorted(lines)


def fix_prompt(report: "Report", critics: Iterable[str] | str | None = None, *, program: str | None = None) -> str:
    """The structured critic feedback of ``report`` (``Report.feedback(critics)``) as a revision request.

    With ``program`` (the source the report judged), the program is quoted
    with line numbers and the lines the selected critics point at marked
    ``>>`` (only those lines and their neighbours for long programs).
    """
    feedback = cut_text(clean_text(report.feedback(critics)), MAX_FEEDBACK_CHARS)
    parts = [
        f"The critics checked the simulated motion of your program (quality score "
        f"{_score_text(report.score)}) and report:\n{feedback}"
    ]
    if program:
        marked = [n for n in _flagged_lines(report, critics) if 1 <= n <= len(program.splitlines())]
        long = len(program.splitlines()) > _FULL_LISTING_LINES
        listing = numbered_program(program, marked, context=_FLAGGED_CONTEXT_LINES if long and marked else None)
        listing = cut_text(clean_text(listing), _LISTING_CHARS)
        note = " (lines the critics point at are marked >>)" if marked else ""
        parts.append(f"Your program{note}:\n{listing}")
    parts.append(
        "Revise the program to fix these issues while still doing the task. Answer with the complete "
        "revised program in one ```python block."
    )
    return "\n\n".join(parts)


def _quote_line(program: str | None, line: int) -> str:
    if not program or line <= 0:
        return ""
    lines = program.splitlines()
    if line > len(lines):
        return ""
    return "\n" + numbered_program(program, [line], context=0)


def runtime_feedback(
    error: BaseException | None, *, program: str | None = None, reply: str | None = None
) -> str:
    """A message telling the model why its last reply produced no checked motion, and what to do.

    ``error`` is a :class:`ProgramError` (the sandbox rejected or stopped the
    program), a :class:`PlanningError` (a motion could not be planned, e.g. an
    unreachable target), another robocritics error, or ``None`` for a reply
    that contained no program (``reply`` is then quoted briefly). ``program``
    (the source that failed) lets the offending line be quoted.
    """
    resend = "Send the complete corrected program in one ```python block."
    text = _runtime_feedback(error, program=program, reply=reply, resend=resend)
    return clean_text(cut_text(text, MAX_FEEDBACK_CHARS))


def _reason(error: BaseException) -> str:
    """The error's own words, bounded: an error may quote a huge value from the program."""
    reason = getattr(error, "reason", None) or str(error)
    return cut_text(str(reason), MAX_FEEDBACK_CHARS // 2)


def _runtime_feedback(error: BaseException | None, *, program: str | None, reply: str | None, resend: str) -> str:
    if error is None:
        said = ""
        if reply is not None and reply.strip():
            said = f' (your reply began: "{_cut(reply, _REPLY_EXCERPT_CHARS)}")'
        return (
            f"Your reply contained no Python program{said}. Answer with the complete program in one "
            f"```python code block, using only the skills of the API. Say \"{COMPLETE_MARKER}\" (with no "
            f"code) only when a program has run and you are satisfied with it."
        )
    if isinstance(error, ProgramError):
        line = int(getattr(error, "line", 0) or 0)
        col = int(getattr(error, "col", 0) or 0)
        where = f" at line {line}" + (f", column {col}" if col else "") if line else ""
        reason = _reason(error)
        return (
            f"Your program did not run: the sandbox stopped it{where}, before the robot moved.\n"
            f"Problem: {reason}{_quote_line(program, line)}\n"
            f"Use only the skills and names of the API (no imports other than math, no files, no "
            f"classes or try/except). {resend}"
        )
    if isinstance(error, PlanningError):
        line = int(getattr(error, "line", 0) or 0)
        reason = _reason(error)
        where = f" at line {line}" if line else ""
        return (
            f"Your program ran, but the motion{where} could not be planned, so nothing was checked or "
            f"executed.\nProblem: {reason}{_quote_line(program, line)}\n"
            f"Keep every target within the robot's reach and inside the allowed workspace (see the "
            f"scene), above the table and clear of the objects. {resend}"
        )
    if isinstance(error, CriticError):
        return (
            f"Your program ran, but the critics could not check its motion: {_reason(error)}\n"
            f"Make sure the program moves the robot to do the task. {resend}"
        )
    if isinstance(error, RoboCriticsError):
        return f"Your program could not be checked: {_reason(error)}\n{resend}"
    return f"Your program could not be checked ({type(error).__name__}: {_reason(error)}).\n{resend}"


def truncated_feedback(tokens: int | None, max_tokens: int | None = None) -> str:
    """The message for a reply the server cut at its token limit (``finish_reason == "length"``).

    The program in such a reply is incomplete, so it is not run; the model is
    told why and asked for a shorter one (instead of being blamed for the
    broken last line of a program it never finished).
    """
    count = tokens if tokens else max_tokens
    at = f" at {count} tokens" if count else ""
    limit = f" (the reply limit, max_tokens={max_tokens})" if max_tokens else " (the reply limit)"
    return (
        f"Your reply was cut{at}{limit} before it was finished, so its program is incomplete and was not "
        "run. Send a shorter program: the complete program in one ```python block with no explanation "
        "before or after it, few comments, and a loop or a helper function for steps that repeat."
    )


def has_unclosed_fence(reply: str) -> bool:
    """Whether ``reply`` opens a fenced block it never closes (a reply cut in the middle of its code)."""
    fences = [line for line in reply.splitlines() if _OPENING.match(line)]
    return len(fences) % 2 == 1


def says_complete(reply: str) -> bool:
    """Whether the model's reply declares the program complete ("PROGRAM COMPLETE", any case)."""
    return bool(isinstance(reply, str) and _COMPLETE.search(reply))

#: Info-string words that mark a fenced block as Python (compared lower-case).
PYTHON_TAGS = frozenset({"python", "py", "python3", "py3", "ipython", "ipython3"})

# An opening fence: indentation, 3+ backticks or tildes, then an optional info string.
# Backtick fences may not have a backtick in their info string (CommonMark).
_OPENING = re.compile(r"^(?P<indent>[ \t]*)(?P<fence>`{3,}|~{3,})(?P<info>.*)$")

# With no fences: try the whole reply, then spans that drop up to this many lines of prose at either end.
_MAX_TRIMMED_LINES = 20
# Characters the parser may be given while looking for unfenced code, per character of the reply (plus a
# constant). A failing parse is charged twice what it read (CPython parses again to word the error), so prose
# at both ends costs about three whole-reply parses; four keep the search linear and short.
_PARSE_BUDGET_PER_CHAR = 4
_PARSE_BUDGET_BASE = 10_000
# Spans looked at in all: each error-guided step drops at least a line from one end, so the search reaches
# any span in at most 2 * _MAX_TRIMMED_LINES + 1 steps.
_MAX_SPANS_TRIED = 2 * _MAX_TRIMMED_LINES + 4


@dataclass(frozen=True)
class _Block:
    language: str  # "" when untagged
    text: str


def extract_code(reply: str) -> str | None:
    """Return the Python program in an LLM ``reply``, or None if there is none.

    Rules, in order:

    1. Fenced blocks (```` ``` ```` or ``~~~``, any indentation, closed by a
       fence of the same character at least as long; a final block left open
       runs to the end of the reply). Blocks tagged ``python``/``py``/
       ``python3``/``py3``/``ipython`` win: all of them are joined in order,
       separated by a blank line, since models often split one program into
       several blocks.
    2. Otherwise untagged blocks: those that parse as Python are joined in
       order; if none parses, all untagged blocks are joined anyway so the
       sandbox can report the syntax error with a line number.
    3. Blocks tagged with another language (``json``, ``bash``, ``text`` ...)
       are never returned.
    4. No fences at all: the whole reply if it parses with ``ast`` and
       contains a call; else the longest span that does after dropping up to
       20 lines of prose at its start and/or end. The spans tried are guided
       by where the parser reports the error (a prose line), so the search
       costs a few parses of the reply, never one per span.

    Empty blocks are ignored. The result has its common indentation removed,
    no leading or trailing blank lines, lone surrogates replaced, and ends
    with one newline.

    Linear in the length of ``reply``; code nested too deeply for Python's
    parser counts as not parsing. Raises :class:`LLMError` (and nothing else)
    for a reply longer than ``MAX_REPLY_CHARS``.
    """
    if not isinstance(reply, str) or not reply.strip():
        return None
    if len(reply) > MAX_REPLY_CHARS:
        raise LLMError(
            f"the model's reply is {len(reply):,} characters long; the limit is {MAX_REPLY_CHARS:,} "
            "(llm.limits.MAX_REPLY_CHARS): a reply that long is not a program"
        )
    reply = clean_text(reply)
    blocks, saw_fence = _fenced_blocks(reply)
    if saw_fence:
        python = [b.text for b in blocks if b.language in PYTHON_TAGS]
        if python:
            return _join(python)
        untagged = [b.text for b in blocks if not b.language]
        if untagged:
            parsing = [text for text in untagged if _parses(text)]
            return _join(parsing or untagged)
        if blocks:
            return None  # only blocks in other languages
        # Fences with nothing inside: fall through and look at the prose itself.
    return _bare_code(reply)


def _fenced_blocks(reply: str) -> tuple[list[_Block], bool]:
    """Non-empty fenced blocks in order, and whether any fence was seen at all."""
    lines = reply.splitlines()
    blocks: list[_Block] = []
    saw_fence = False
    i = 0
    while i < len(lines):
        opening = _OPENING.match(lines[i])
        if opening is None or (opening["fence"][0] == "`" and "`" in opening["info"]):
            i += 1
            continue
        saw_fence = True
        fence = opening["fence"]
        closing = re.compile(rf"^[ \t]*{re.escape(fence[0])}{{{len(fence)},}}[ \t]*$")
        body: list[str] = []
        i += 1
        while i < len(lines) and not closing.match(lines[i]):
            body.append(lines[i])
            i += 1
        i += 1  # skip the closing fence (or run past the end of an unterminated block)
        text = _tidy("\n".join(body))
        if text:
            blocks.append(_Block(language=_language(opening["info"]), text=text))
    return blocks, saw_fence


def _language(info: str) -> str:
    """The language word of a fence's info string: '```Python title="x"' -> 'python', '```{py}' -> 'py'."""
    words = info.strip().split()
    if not words:
        return ""
    return words[0].strip("{}.").lower()


def _bare_code(reply: str) -> str | None:
    """The longest span of ``reply``'s lines, trimmed by at most ``_MAX_TRIMMED_LINES`` at each end, that is code.

    A best-first search over spans (longest first, then earliest). When a
    span fails to parse at line L, the lines before L were a valid start of
    a program, so the only spans worth trying next drop line L and what
    precedes it (L was prose at the start) or L and what follows it (prose at
    the end). The parser is given at most ``_PARSE_BUDGET_PER_CHAR`` times
    the reply's characters in all (a failing parse is charged twice what it
    read, up to its error) and at most ``_MAX_SPANS_TRIED`` spans are looked at, so the
    search is linear; when either runs out there is no code. A span that
    parses but calls nothing is not searched further.
    """
    lines = _tidy(reply).splitlines()
    n = len(lines)
    trim = min(_MAX_TRIMMED_LINES, max(n - 1, 0))
    offsets = [0]
    for line in lines:
        offsets.append(offsets[-1] + len(line) + 1)
    budget = _PARSE_BUDGET_PER_CHAR * offsets[-1] + _PARSE_BUDGET_BASE
    queue: list[tuple[int, int, int]] = [(-n, 0, n)]  # (-length, start, end)
    seen = {(0, n)}

    def push(start: int, end: int) -> None:
        if start < end and start <= trim and end >= n - trim and (start, end) not in seen:
            seen.add((start, end))
            heapq.heappush(queue, (start - end, start, end))

    tried = 0
    while queue and budget > 0 and tried < _MAX_SPANS_TRIED:
        tried += 1
        _, start, end = heapq.heappop(queue)
        candidate = _tidy("\n".join(lines[start:end]))
        if not candidate:
            continue
        outcome, error_line = _try_parse(candidate)
        if outcome is not None:
            budget -= len(candidate)
            if _calls_something(outcome):
                return candidate + "\n"
            continue  # parses but calls nothing: neither do its parts (dropping whole lines keeps statements)
        # The tidied candidate starts at its first non-blank line: map the error back to a line of `lines`.
        first = start + next(i for i, line in enumerate(lines[start:end]) if line.strip())
        bad = first + error_line - 1 if error_line else None
        if bad is None or not start <= bad < end:
            budget -= 2 * len(candidate)
            push(start + 1, end)
            push(start, end - 1)
            continue
        budget -= 2 * (offsets[bad + 1] - offsets[start])
        push(bad + 1, end)  # line `bad` and everything before it were prose
        push(start, bad)  # line `bad` and everything after it were prose
    return None


def _try_parse(text: str) -> tuple[ast.Module | None, int | None]:
    """(tree, None) if ``text`` parses; else (None, the 1-based line of the error if the parser named one).

    Code nested deeper than the parser allows (it raises MemoryError or
    RecursionError for that) counts as not parsing, with no line.
    """
    try:
        return ast.parse(text), None
    except SyntaxError as exc:  # IndentationError and TabError included
        return None, exc.lineno if isinstance(exc.lineno, int) and exc.lineno > 0 else None
    except (ValueError, MemoryError, RecursionError, OverflowError):
        return None, None


def _calls_something(tree: ast.Module) -> bool:
    """Whether the program calls something (bare prose like 'Done' parses as a name but calls nothing)."""
    return any(isinstance(node, ast.Call) for node in ast.walk(tree))


def _is_code(text: str) -> bool:
    """Parses as Python and calls something."""
    tree, _ = _try_parse(text)
    return tree is not None and _calls_something(tree)


def _parses(text: str) -> bool:
    return _try_parse(text)[0] is not None


def _tidy(text: str) -> str:
    """Dedent, drop leading/trailing blank lines and trailing spaces."""
    text = textwrap.dedent(text)
    lines = [line.rstrip() for line in text.splitlines()]
    while lines and not lines[0]:
        lines.pop(0)
    while lines and not lines[-1]:
        lines.pop()
    return "\n".join(lines)


def _join(texts: list[str]) -> str:
    return "\n\n".join(texts) + "\n"
