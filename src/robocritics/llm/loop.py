"""The RoboCritics loop: request → program → simulated trace → critics → feedback → revision.

:class:`Loop` holds one conversation with a chat model about one scene::

    loop = Loop(OpenAICompatible(), Scene.builtin("sorting"))
    first = loop.request("put the green apple in the white box")
    print(first.report)                 # what the critics found
    better = loop.fix()                 # the paper's one-click Fix: critic feedback → revised program
    best = loop.run("sort the apples by ripeness", max_attempts=5)   # iterate automatically

Every model reply becomes an :class:`Attempt`: its program is extracted,
simulated (:func:`~robocritics.pipeline.simulate`) and critiqued
(:func:`~robocritics.critic.critique`), and the attempt is stored in the
interaction memory as ``(request, program, feedback, score)``.

A reply without code, a program the sandbox rejects (:class:`ProgramError`),
a motion that cannot be planned (:class:`PlanningError`, e.g. an
unreachable target) and a motion a critic cannot judge (:class:`CriticError`
from a critic's ``check``) are not exceptions for the caller: the attempt carries the
runtime feedback (:func:`~robocritics.llm.prompts.runtime_feedback`) and that
text is sent to the model with the next turn. Only :class:`LLMError` (the
endpoint failed after the client's retries) propagates; the conversation is
then left as it was before the call, so the call can simply be repeated (a
repair made by the same :meth:`Loop.fix` stays applied: the repeated call
sends the model what is left after it).

Fix = repairs, then the model: :meth:`Loop.fix` (and each feedback round of
:meth:`Loop.run`) first applies the critics' own repairs
(:func:`robocritics.repair.repair`: program edits derived from a critic's
evidence, each kept only when re-simulation shows it removes its Error without
worsening another verdict or the task goals). The repaired program is an
attempt of its own (``kind="repair"``, ``source="repair"``, its accepted
:class:`~robocritics.repair.Change` list in ``changes``); only the Error and
Warning verdicts left after it are sent to the model, and when none is left no
model call is made. Repairs act on Error verdicts only (a Warning is a
judgement call for the model) and only when the current program ran.
``Loop(repairs=False)`` sends everything to the model (the paper's loop; the
ablation's LLM-only baseline).

Automation levels (``automation=``):

* ``"manual"`` — critics only report. Critic feedback never reaches the model
  unless the user writes it: :meth:`Loop.fix` applies the critics' repairs only
  (refused when repairs are off or change nothing), :meth:`Loop.run` makes a
  single request. Use :meth:`Loop.refine` with your own words.
* ``"guided"`` (default) — the user decides: :meth:`Loop.fix` (the Fix button)
  repairs, then forwards the remaining failing critics' feedback; :meth:`Loop.run` iterates when called.
* ``"auto"`` — :meth:`Loop.request` already iterates like :meth:`Loop.run`.

Approval: ``approve(program, diff) -> bool`` is called for every *revision*
(a program that differs from the current one, with its unified diff) before it
is simulated — the model's revisions and the critics' repairs alike (a
repair's diff names its new side ``attempt N (critic repairs)``). A rejected
revision is recorded (``approved=False``) but not simulated and the previous
attempt stays current. A rejected model revision: the model is told with its
next turn that it was not accepted. A rejected repair: the model is asked with
the unrepaired program's feedback, as if there had been no repair (in
``manual``, nothing more happens).

History: the loop keeps the whole conversation (:attr:`Loop.history`) but
sends the model only the system prompt plus the last ``max_history_messages``
user/assistant messages (always starting at a user message); when the task
message falls out of that window, the task is restated in the first message
that is sent.

Bounds: a task longer than ``llm.limits.MAX_TASK_CHARS`` is refused
(:class:`~robocritics.llm.prompts.PromptError`); every message the loop sends
or keeps in its history is at most ``MAX_MESSAGE_CHARS`` long (a longer reply
is kept as its program, or cut, saying so); all text is cleaned of lone
surrogates before it is sent, stored or handed to ``on_attempt``. Programs and feedback of older turns remain available to the
model through the fix prompt (which quotes the current program) and the memory.

Context: with ``context_tokens`` (the model's context window; learnt from the
server's error when it refuses a prompt as too long, and then the turn is sent
again once) every call is fitted to it by :func:`~robocritics.llm.prompts.estimate_tokens`,
leaving room for the reply (``max_tokens``). In order, until it fits: fewer
memory examples, the compact skill reference, the minimal one (signatures and
short rules), fewer history messages (the task is restated), the new message's
feedback cut, a smaller reply (down to ``llm.limits.MIN_REPLY_TOKENS``). The
task, the skill API and the scene always survive; when even that does not fit,
:class:`~robocritics.llm.prompts.PromptError` says how many tokens are needed.
``last_prompt_tokens`` is the estimate of the latest call.

Truncated replies: a reply the server cut at its token limit (``finish_reason
"length"``, from a model with a ``chat`` method returning a ``ChatReply``) whose
program is unfinished is not run; the model is told its reply was cut at N
tokens and asked for a shorter program (:func:`~robocritics.llm.prompts.truncated_feedback`).

Memory: when the memory's embedder fails (a server without embeddings), the
loop warns once and retrieves by keywords (BM25) for the rest of its life.
Past programs that never ran (score None) are not shown as examples.
"""

from __future__ import annotations

import difflib
import logging
import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal

from ..errors import CriticError, LLMError, PlanningError, ProgramError, RoboCriticsError, TrajectoryError
from ..critic.report import format_score
from .protocol import ChatModel, ContextLengthError
from .fitting import MIN_CONTEXT_TOKENS, fit_messages
from .options import AUTOMATION_LEVELS, Automation, LoopOptions
from .limits import DEFAULT_MAX_TOKENS, MAX_MESSAGE_CHARS, clean_text, cut_text
from .memory import MAX_SEARCH_K, SOURCES, Interaction, InteractionMemory  # SOURCES: who wrote a program
from .prompts import (
    REVIEW_INSTRUCTION,
    PromptError,
    check_task,
    estimate_tokens,
    extract_code,
    fix_prompt,
    has_unclosed_fence,
    request_prompt,
    runtime_feedback,
    says_complete,
    system_prompt,
    truncated_feedback,
)

if TYPE_CHECKING:  # pragma: no cover
    from ..critic import Report
    from ..repair import Change
    from ..execution import Execution
    from ..robot.model import Robot
    from ..scene import Scene

__all__ = ["Attempt", "Loop", "LoopOptions", "NothingToFixError", "AUTOMATION_LEVELS", "SOURCES"]

#: How the loop asks for the next revision in :meth:`Loop.run`.
FeedbackMode = Literal["critics", "review"]

log = logging.getLogger("robocritics.llm")

# Memory hits fetched per example wanted: attempts at the same request share a text, only the best one is kept.
_HITS_PER_EXAMPLE = 4


class NothingToFixError(RoboCriticsError):
    """:meth:`Loop.fix` was called with nothing to fix: no attempt yet, or every selected critic passed."""


@dataclass(eq=False)
class Attempt:
    """One model turn and what came of it.

    ``index`` counts attempts of the loop from 1. ``kind`` says what produced
    it: ``"request"`` (a task), ``"fix"`` (critic or runtime feedback),
    ``"refine"`` (the user's own words), ``"review"`` (the embedded
    condition's self-review) or ``"repair"`` (the critics' own repairs, no
    model call). ``source`` is who wrote the program (:data:`SOURCES`:
    ``"llm"`` or ``"repair"``, as in the memory); a repair attempt's accepted edits are in ``changes``
    (:class:`~robocritics.repair.Change`: critic, line, what, why, cycle-time
    cost in s; [] for the model's). ``prompt`` is the user message sent
    (including any runtime feedback or note carried over from the previous
    turn); ``reply`` the model's raw answer ("" for both of a repair).

    ``program`` is the program this attempt stands for: the extracted code, or
    — when the model said "PROGRAM COMPLETE" without code, or sent the same
    program again — the unchanged current program (``changed`` is False then,
    and ``execution``/``report`` are the current ones). ``None`` when the reply
    had no code. ``execution``/``report`` are None when the program did not
    run (see ``error``) or the revision was rejected (``approved`` False).

    ``error`` is the runtime feedback text (sandbox rejection, planning
    failure, no code) that is sent to the model with the next turn. ``diff``
    is the unified diff from the previous current program ("" when unchanged
    or first). ``score`` is the report's 0–10 quality index (None without a
    report). ``complete`` is the paper's stop signal: the model said the
    program is complete and changed nothing.
    """

    index: int
    kind: str
    request: str
    prompt: str
    reply: str
    program: str | None = None
    execution: Execution | None = field(default=None, repr=False)
    report: Report | None = field(default=None, repr=False)
    error: str | None = None
    diff: str = ""
    score: float | None = None
    complete: bool = False
    changed: bool = True
    approved: bool | None = None
    memory_id: int | None = None
    source: str = "llm"
    changes: list[Change] = field(default_factory=list)

    @property
    def feedback(self) -> str:
        """What this attempt tells the model: the runtime error, or all critic feedback ("" if neither)."""
        if self.error:
            return self.error
        if self.report is not None:
            return self.report.feedback()
        return ""

    @property
    def passed(self) -> bool:
        """Whether the program ran and every critic was OK."""
        return self.report is not None and self.report.passed

    @property
    def has_errors(self) -> bool:
        """Whether the attempt failed: no report (it did not run, or was rejected), or an Error verdict."""
        return self.report is None or self.report.has_errors

    @property
    def failing(self) -> list[str]:
        """Names of the critics that did not give OK ([] without a report)."""
        if self.report is None:
            return []
        return [v.critic for v in self.report.verdicts if not v.ok]

    def summary(self) -> str:
        """One line: index, kind, outcome."""
        if self.approved is False:
            outcome = "repair rejected" if self.source == "repair" else "revision rejected"
        elif self.error:
            outcome = "did not run: " + self.error.splitlines()[0]
        elif self.complete:
            outcome = f"model says complete; score {format_score(self.score)}"
        elif self.report is not None:
            flagged = ", ".join(f"{v.critic} {v.flag.label}" for v in self.report.verdicts if not v.ok)
            outcome = f"score {format_score(self.score)}" + (f" ({flagged})" if flagged else " (all critics OK)")
            if not self.changed:
                outcome += "; program unchanged"
        else:
            outcome = "no result"
        if self.source == "repair" and self.approved is not False:
            outcome = f"{len(self.changes)} critic repair{'s' if len(self.changes) != 1 else ''}; {outcome}"
        return f"attempt {self.index} [{self.kind}]: {outcome}"


def _normalise(program: str) -> str:
    lines = [line.rstrip() for line in program.strip("\n").splitlines()]
    return "\n".join(lines).strip() + "\n"


def unified_diff(old: str, new: str, old_name: str = "previous", new_name: str = "revised") -> str:
    """The unified diff of two programs ("" when they are equal)."""
    return "".join(
        difflib.unified_diff(
            old.splitlines(keepends=True) if old else [],
            new.splitlines(keepends=True),
            fromfile=old_name,
            tofile=new_name,
        )
    )


class Loop:
    """A conversation with a chat model that writes, checks and revises robot programs for one scene.

    Arguments:

    * ``model`` — a :class:`~robocritics.llm.providers.openai_compatible.ChatModel` (e.g.
      :class:`~robocritics.llm.providers.openai_compatible.OpenAICompatible`).
    * ``scene`` — the :class:`~robocritics.scene.Scene`; ``robot`` defaults to the UR3e.
    * ``critics`` / ``params`` — which critics run and their thresholds, as in
      :func:`~robocritics.critic.critique` (default: every installed critic).
      Checked here, so a typo fails before any model call.
    * ``memory`` — an :class:`~robocritics.llm.memory.InteractionMemory`, or a
      path to its SQLite file (the loop then owns and closes it). Every
      program that was run is stored as ``(task, program, feedback, score)``
      (feedback: the critics' or the runtime error's; score None if it did not
      run); replies without code, unchanged programs and rejected revisions
      are not. Each request retrieves the ``memory_k`` most relevant past
      interactions (other than this loop's own; the best-scored one per
      request text) into the system prompt.
    * ``goals`` — task goals (``"green_apple in white_box"`` or :class:`~robocritics.goals.Goal`) that
      every attempt's ``task_outcome`` critic checks on the final scene, beside the program's own
      ``expect(...)`` calls (in-process checking; a ``simulate`` hook checks its own).
    * ``options`` — a :class:`~robocritics.llm.options.LoopOptions` of the rest, which may also be given one by
      one as keywords (``Loop(model, scene, automation="auto", max_attempts=3)``):
    * ``automation`` — ``"manual"``, ``"guided"`` or ``"auto"`` (module docstring).
    * ``approve`` — ``approve(program, diff) -> bool`` for revisions, the model's and the repairs' (module docstring).
    * ``repairs`` — apply the critics' own repairs before asking the model to fix (module docstring);
      False: every fix goes to the model. True: :func:`robocritics.repair.repair` in this process, with
      ``robot``, ``critics``, ``params`` and ``goals``; or a callable ``repairs(program) -> Repair`` that
      repairs elsewhere (e.g. :meth:`robocritics.viz.studio.worker.Evaluator.loop_repair`, in the
      worker process). With a ``simulate`` hook the repaired program is then re-checked through it like
      any revision.
    * ``session`` — the memory session id (default: a fresh one).
    * ``max_history_messages`` — user/assistant messages sent per call (>= 2).
    * ``max_attempts`` — model replies per :meth:`run` (and per request in ``auto``; repairs do not count).
    * ``embedded_rules`` — paste the critics' rules into the system prompt
      (the paper's *embedded* condition).
    * ``on_attempt`` — called with each :class:`Attempt` as soon as it is made.
    * ``model_options`` — keyword arguments for ``model.complete`` (temperature, seed ...).
    * ``sample_rate_hz`` — trajectory sample rate for simulation, Hz (default:
      :func:`~robocritics.pipeline.simulate`'s).
    * ``context_tokens`` — the model's context window in tokens, to fit every
      prompt to (module docstring); None: unknown until the server refuses one.
    * ``simulate`` — ``simulate(program) -> (Execution, Report)`` to check a
      program elsewhere (e.g. :meth:`robocritics.viz.studio.worker.Evaluator.loop_simulate`,
      in a resource-limited process); it raises :class:`ProgramError`,
      :class:`PlanningError`, :class:`TrajectoryError` or :class:`CriticError`
      as the in-process check does. None: :func:`~robocritics.pipeline.simulate`
      and :func:`~robocritics.critic.critique` here, with ``robot``,
      ``critics``, ``params`` and ``sample_rate_hz``.
    """

    def __init__(
        self,
        model: ChatModel,
        scene: Scene,
        robot: Robot | None = None,
        critics: Iterable[str] | str | None = None,
        params: Mapping[str, Any] | None = None,
        memory: InteractionMemory | str | os.PathLike[str] | None = None,
        *,
        goals: Iterable[Any] | None = None,
        options: LoopOptions | None = None,
        **keywords: Any,
    ):
        from ..critic import select_critics

        if not callable(getattr(model, "complete", None)):
            raise TypeError(f"model must be a ChatModel (with a complete(messages) method), got {type(model).__name__}")
        options = (options or LoopOptions()).updated(**keywords)  # the options given one by one, by keyword
        if isinstance(critics, str):
            critics = [c.strip() for c in critics.split(",") if c.strip()]
        selected = select_critics(critics, params)  # fail fast on unknown critics / parameters
        self.model = model
        self.scene = scene
        self._robot = robot
        self._selection = [critic for critic, _ in selected]  # critic objects: unregistered ones work too
        self.critics: list[str] = [critic.name for critic in self._selection]
        self.params = dict(params or {})
        self._owns_memory = memory is not None and not isinstance(memory, InteractionMemory)
        self.memory: InteractionMemory | None = (
            InteractionMemory(memory) if self._owns_memory else memory  # type: ignore[arg-type]
        )
        self.options = options
        self.session = options.session or InteractionMemory.new_session_id()
        self.automation: Automation = options.automation
        self.approve = options.approve
        self.repairs = bool(options.repairs)
        self._repair_hook = options.repairs if callable(options.repairs) else None
        self.max_history_messages = int(options.max_history_messages)
        self.max_attempts = int(options.max_attempts)
        self.memory_k = int(options.memory_k)
        self.embedded_rules = bool(options.embedded_rules)
        self.on_attempt = options.on_attempt
        self.model_options = dict(options.model_options or {})
        self.sample_rate_hz = None if options.sample_rate_hz is None else float(options.sample_rate_hz)
        self.context_tokens: int | None = None if options.context_tokens is None else int(options.context_tokens)
        self._simulate = options.simulate
        from ..goals import parse_goals

        self.goals = parse_goals(goals, scene) if goals else []  # a bad goal fails here, before any model call
        self.last_prompt_tokens: int | None = None
        self.keyword_memory_reason: str | None = None  # why retrieval fell back to BM25, once it did

        self.attempts: list[Attempt] = []
        self.history: list[dict[str, str]] = []  # user/assistant turns, never trimmed
        self.task: str | None = None
        self.examples: list[Interaction] = []  # memory examples in the current system prompt
        self.system: str = self._system_prompt()
        self.current: Attempt | None = None  # the attempt whose program is in effect
        self.last_run: list[Attempt] = []  # the attempts of the latest run()
        self._task_index = 0  # index in history of the current task's first message
        self._pending_error: str | None = None  # runtime feedback owed to the model
        self._notes: list[str] = []  # other things to tell the model with the next turn
        self._memory_ids: set[int] = set()

    # --- public API ------------------------------------------------------------------------

    @property
    def robot(self) -> Robot:
        if self._robot is None:
            from ..robot.model import default_robot

            self._robot = default_robot()
        return self._robot

    @property
    def last(self) -> Attempt | None:
        """The latest attempt (also a rejected or failed one), or None."""
        return self.attempts[-1] if self.attempts else None

    def request(self, text: str) -> Attempt:
        """Start a task: the model writes a program for ``text``; it is simulated, critiqued and stored.

        Retrieves relevant past interactions from the memory into the system
        prompt first. With ``automation="auto"`` this iterates like
        :meth:`run` (``max_attempts`` of the loop) and returns what ``run`` returns.
        """
        if self.automation == "auto":
            return self.run(text)
        return self._request(text)

    def fix(self, critics: Iterable[str] | str | None = None) -> Attempt:
        """The one-click Fix: the critics' repairs, then the FAILING critics' feedback to the model.

        First, when a selected critic gave an Error, the critics' own repairs
        (module docstring) are applied to the current program — one attempt
        with ``source="repair"``, through ``approve`` like any revision. Then
        the feedback of the selected critics that still give a Warning or
        Error is sent to the model; with none left, no model call is made.
        ``critics`` restricts both to some critics (default: the loop's
        critics; a repair still changes only what makes no verdict worse).
        If the last program could not be run (sandbox or planning error: the
        ``runtime`` critic's Error), the repairs first try to make it run (e.g.
        an unreachable hover lowered to the nearest reachable height); if none
        does, or the reply had no code, its runtime feedback is what is sent.

        Returns the latest attempt: the model's revision, or the repair when
        the model was not asked. Raises :class:`NothingToFixError` when there
        is no attempt yet or every selected critic passed, and
        :class:`RoboCriticsError` in ``manual`` automation when the repairs
        are off or changed nothing (the model is never asked there).
        """
        if self.automation == "manual" and not self.repairs:
            raise RoboCriticsError(
                "automation='manual': critic feedback is not sent to the model and repairs are off; use "
                "refine(text) with your own words, or automation='guided' to fix on request"
            )
        return self._fix(critics)

    def refine(self, text: str) -> Attempt:
        """Send the user's own words about the current program; return the revision.

        With no attempt yet this is the same as :meth:`request`.
        """
        if not isinstance(text, str) or not text.strip():
            raise ValueError("refine needs some text")
        if self.task is None:
            return self._request(text)
        return self._turn("refine", text.strip())

    def review(self) -> Attempt:
        """The embedded condition's self-review turn: "Review the program. If any part might violate
        these rules, revise the code to fix it." (with any runtime feedback owed)."""
        if self.task is None:
            raise NothingToFixError("nothing to review: no request yet; call request(text) first")
        return self._turn("review", REVIEW_INSTRUCTION)

    def run(self, text: str, max_attempts: int | None = None, *, feedback: FeedbackMode = "critics") -> Attempt:
        """Request ``text`` and iterate until done; return the BEST attempt of this run.

        Each round after the first sends, for ``feedback="critics"`` (the
        paper's *external* condition), the feedback of the failing critics
        (or the runtime feedback of a program that did not run); for
        ``feedback="review"`` (the *embedded* condition) the self-review
        instruction. It stops when

        * every critic is OK (``"critics"`` only; the model is not asked again),
        * the model says the program is complete and changes nothing (the
          paper's stop rule; that reply counts as an attempt), or
        * ``max_attempts`` model replies were made (default: the loop's).

        In ``manual`` automation only the request is made. Returns the attempt
        with the highest score (the latest of equal ones); when no attempt
        produced a report, the last attempt. All of this run's attempts are in
        :attr:`last_run`.
        """
        if feedback not in ("critics", "review"):
            raise ValueError(f"feedback must be 'critics' or 'review', got {feedback!r}")
        limit = self.max_attempts if max_attempts is None else int(max_attempts)
        if limit < 1:
            raise ValueError(f"max_attempts must be at least 1, got {max_attempts}")
        start = len(self.attempts)
        self.last_run = []
        attempt = self._request(text)
        self.last_run = self.attempts[start:]
        while self.automation != "manual" and self._model_replies(start) < limit:
            if attempt.complete:
                break
            current = self.current
            if feedback == "critics" and self._pending_error is None and current is not None and current.passed:
                break
            if feedback == "critics":
                try:
                    attempt = self._fix(None)  # repairs first (when on), then the model with what is left
                except NothingToFixError:
                    break
            else:
                attempt = self._turn("review", REVIEW_INSTRUCTION)
            self.last_run = self.attempts[start:]
        return self.best(self.last_run)

    def _model_replies(self, start: int) -> int:
        """Attempts since ``start`` that were model replies (repairs make no model call)."""
        return sum(1 for a in self.attempts[start:] if a.source == "llm")

    @staticmethod
    def best(attempts: Iterable[Attempt]) -> Attempt:
        """The best attempt: no Error first (plugin critics count), then the highest score, then the latest.

        The last attempt if none has a report.
        """
        attempts = list(attempts)
        if not attempts:
            raise ValueError("no attempts")
        scored = [a for a in attempts if a.report is not None and a.approved is not False]
        if not scored:
            return attempts[-1]
        return max(scored, key=lambda a: (not a.report.has_errors, a.score if a.score is not None else -1.0, a.index))

    def messages(self) -> list[dict[str, str]]:
        """The messages the next model call would send before its new user message: system + trimmed history."""
        return [{"role": "system", "content": self.system}, *self._trimmed_history()]

    def close(self) -> None:
        """Close the memory if the loop opened it from a path."""
        if self._owns_memory and self.memory is not None:
            self.memory.close()

    def __enter__(self) -> Loop:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return (
            f"Loop(model={getattr(self.model, 'name', type(self.model).__name__)!r}, scene={self.scene.name!r}, "
            f"automation={self.automation!r}, attempts={len(self.attempts)})"
        )

    # --- turns -----------------------------------------------------------------------------

    def _request(self, text: str) -> Attempt:
        text = check_task(text)  # PromptError (a ValueError) for an empty or overlong task
        examples = self._retrieve(text)
        previous = (self.task, self.examples, self.system, self._task_index)
        self.task = text
        self.examples = examples
        self.system = self._system_prompt()
        self._task_index = len(self.history)
        try:
            return self._turn("request", request_prompt(text))
        except BaseException:
            self.task, self.examples, self.system, self._task_index = previous
            raise

    def _fix(self, critics: Iterable[str] | str | None) -> Attempt:
        """One Fix round: repairs (when on and an Error is selected), then the model with what is left."""
        message = self._fix_message(critics)  # NothingToFixError before anything is done
        repaired: Attempt | None = None
        if self.repairs and (self._pending_error is None or self._did_not_run()):
            repaired = self._repair(critics)
            if repaired is not None and repaired.approved is not False:
                try:
                    message = self._fix_message(critics)
                except NothingToFixError:
                    return repaired  # the repairs fixed everything selected: no model call
        if self.automation == "manual":
            if repaired is None:
                raise RoboCriticsError(
                    "automation='manual': the critics' repairs had nothing to change and critic feedback is not "
                    "sent to the model; use refine(text) with your own words, or automation='guided'"
                )
            return repaired
        return self._turn("fix", message)

    def _failing(self, critics: Iterable[str] | str | None) -> tuple[Attempt, list[str]]:
        """The current attempt and its selected critics that did not give OK; NothingToFixError if none."""
        current = self.current
        if current is None or current.report is None:
            raise NothingToFixError("nothing to fix: no program has been checked yet")
        report = current.report
        names = self.critics if critics is None else ([critics] if isinstance(critics, str) else list(critics))
        names = [n for n in names if n in report.critics] if critics is None else names
        failing = [n for n in names if not report.verdict(n).ok]  # report.verdict raises for unknown names
        if not failing:
            raise NothingToFixError(
                f"nothing to fix: {'every selected critic' if critics is not None else 'every critic'} passed "
                f"on attempt {current.index} (score {format_score(report.score)})"
            )
        return current, failing

    def _fix_message(self, critics: Iterable[str] | str | None) -> str:
        """The next fix turn's message; raises NothingToFixError when there is nothing to fix."""
        if not self.attempts:
            raise NothingToFixError("nothing to fix: no attempt yet; call request(text) first")
        if self._pending_error is not None:
            return ""  # the runtime feedback owed to the model is the message
        current, failing = self._failing(critics)
        assert current.report is not None
        return fix_prompt(current.report, failing, program=current.program)

    def _did_not_run(self) -> bool:
        """The current attempt is a program that did not run (sandbox or planning error), not a missing one."""
        c = self.current
        return c is not None and c.program is not None and c.report is None and c.execution is None and bool(c.error)

    def _repair(self, critics: Iterable[str] | str | None) -> Attempt | None:
        """Apply the critics' repairs to the current program as a new attempt (approved, checked, stored).

        None when no selected critic gives an Error, or the repairs change
        nothing (or fail: then the model is asked, as without repairs).
        """
        from ..repair import repair
        from ..critic.verdict import Flag

        did_not_run = self._did_not_run()  # the runtime critic's Error: e.g. an unreachable target
        if did_not_run:
            current = self.current
        else:
            current, failing = self._failing(critics)
            assert current.report is not None
            if not any(current.report.verdict(n).flag == Flag.ERROR for n in failing):
                return None  # repairs act on Errors only
        assert current is not None and current.program is not None
        try:
            if self._repair_hook is not None:
                result = self._repair_hook(current.program)
            else:
                result = repair(current.program, self.scene, goal=self.goals or None, critics=self._selection,
                                robot=self._robot, params=self.params or None)  # fmt: skip
        except RoboCriticsError as exc:  # e.g. a plugin's repair broke the program: the model is asked instead
            log.warning("attempt %d: the critics' repairs failed (%s); asking the model", current.index, exc)
            return None
        code = _normalise(result.program)
        if not result.changes or code == current.program or result.execution is None:
            return None  # nothing changed, or a program that did not run still does not
        assert self.task is not None
        index = len(self.attempts) + 1
        attempt = Attempt(index=index, kind="repair", request=self.task, prompt="", reply="", program=code,
                          source="repair", changes=list(result.changes))  # fmt: skip
        attempt.diff = unified_diff(current.program, code, f"attempt {current.index}",
                                    f"attempt {index} (critic repairs)")  # fmt: skip
        if self.approve is not None:
            if not self.approve(code, attempt.diff):  # it raises: nothing has changed yet
                attempt.approved = False
                self._record(attempt)
                return attempt
            attempt.approved = True
        if did_not_run:
            self._pending_error = None  # the repaired program runs: the model is owed critic feedback instead
        if self._simulate is None and self._repair_hook is None and self.sample_rate_hz is None and result.program == code:
            # repair() checked exactly this program the way _check would (same simulate and critique calls)
            attempt.execution, attempt.report, attempt.score = result.execution, result.report, result.report.score
        else:
            self._check(attempt)
        self.current = attempt
        self._store(attempt)
        self._record(attempt)
        # The model's last program in the history is the unrepaired one: say what changed, so it keeps it.
        done = "\n".join(f"- line {c.line}: {c.what}" for c in attempt.changes)
        self._notes.append(
            f"Automatic repairs were applied to your program (now attempt {index}); keep them:\n{done}"
        )
        return attempt

    def _record(self, attempt: Attempt) -> None:
        self.attempts.append(attempt)
        if self.on_attempt is not None:
            self.on_attempt(attempt)

    def _turn(self, kind: str, message: str) -> Attempt:
        """Send one user message (with what is owed to the model), interpret the reply, record the attempt."""
        assert self.task is not None
        parts = [*self._notes]
        if self._pending_error is not None:
            parts.append(self._pending_error)
        if message:
            parts.append(message)
        content = cut_text(clean_text("\n\n".join(parts)), MAX_MESSAGE_CHARS)
        reply, details = self._ask(content)  # LLMError propagates; nothing changed yet
        if not isinstance(reply, str):
            reply = "" if reply is None else str(reply)
        reply = clean_text(reply)
        saved = (list(self._notes), self._pending_error, self.current)
        self._notes = []
        self._pending_error = None
        self.history.append({"role": "user", "content": content})
        self.history.append({"role": "assistant", "content": reply})
        try:
            attempt = self._interpret(kind, content, reply, details)
        except BaseException:  # approve() or a critic raised: leave the conversation as it was
            del self.history[-2:]
            self._notes, self._pending_error, self.current = saved
            raise
        self.history[-1]["content"] = _kept_reply(reply, attempt.program if attempt.changed else None)
        self.attempts.append(attempt)
        if self.on_attempt is not None:
            self.on_attempt(attempt)
        return attempt

    def _ask(self, content: str) -> tuple[str, Any]:
        """Send the fitted messages with ``content`` as the new user message; (reply text, ChatReply or None).

        A model with a ``chat`` method (``OpenAICompatible``) is asked through
        it, so that a reply cut at the token limit is known. When the server
        refuses the prompt as over its context and names the context, the
        prompt is fitted to it and sent once more.
        """
        for again in (False, True):
            messages, options = self._fitted(content)
            try:
                chat = getattr(self.model, "chat", None)
                if callable(chat):
                    result = chat(messages, **options)
                    text = getattr(result, "content", result)
                    return text, result if hasattr(result, "finish_reason") else None
                return self.model.complete(messages, **options), None
            except ContextLengthError as exc:
                known = exc.context_tokens
                if again or known is None or (self.context_tokens is not None and known >= self.context_tokens):
                    raise
                log.warning(
                    "the server says the model's context is %d tokens; fitting the prompt to it and asking again",
                    known,
                )
                self.context_tokens = max(int(known), MIN_CONTEXT_TOKENS)
        raise AssertionError("unreachable")  # pragma: no cover

    def _reply_tokens(self, options: Mapping[str, Any]) -> int:
        """Tokens to leave for the reply: the call's ``max_tokens``, else the model's, else the default."""
        for value in (options.get("max_tokens"), getattr(self.model, "max_tokens", None)):
            if isinstance(value, int) and not isinstance(value, bool) and value > 0:
                return value
        return DEFAULT_MAX_TOKENS

    def _fitted(self, content: str) -> tuple[list[dict[str, str]], dict[str, Any]]:
        """The messages and model options of the next call, fitted to ``context_tokens`` (module docstring)."""
        options = dict(self.model_options)
        user = {"role": "user", "content": content}
        if self.context_tokens is None:
            messages = [*self.messages(), user]
            self.last_prompt_tokens = estimate_tokens(messages)
            return messages, options
        reply_tokens = self._reply_tokens(options)
        keep_all = self.max_history_messages - 1

        def build(n_examples: int, api: bool | str, keep: int, text: str) -> list[dict[str, str]]:
            system = system_prompt(
                self.scene,
                embedded_rules=self.embedded_rules,
                memory_examples=self.examples[:n_examples],
                critics=self._selection,
                params=self.params or None,
                compact_api=api,
            )
            history = self._trimmed_history(keep)
            if not history and self.task is not None and not text.startswith("Task:"):
                text = f"The task: {self.task}\n\n{text}"  # the task always survives
            return [{"role": "system", "content": system}, *history, {"role": "user", "content": text}]

        messages, max_tokens, self.last_prompt_tokens = fit_messages(
            build, content, context_tokens=self.context_tokens, reply_tokens=reply_tokens,
            examples=len(self.examples), keep_all=keep_all,
        )  # fmt: skip
        if max_tokens is not None:
            options["max_tokens"] = max_tokens
        return messages, options

    def _interpret(self, kind: str, prompt: str, reply: str, details: Any = None) -> Attempt:
        index = len(self.attempts) + 1
        assert self.task is not None
        attempt = Attempt(index=index, kind=kind, request=self.task, prompt=prompt, reply=reply)
        code = extract_code(reply)
        current = self.current
        complete = says_complete(reply)

        if getattr(details, "finish_reason", None) == "length" and (code is None or has_unclosed_fence(reply)):
            # Cut at the token limit in the middle of its program: not the model's broken code, a short budget.
            attempt.error = truncated_feedback(getattr(details, "completion_tokens", None),
                                               getattr(details, "max_tokens", None))  # fmt: skip
            self._pending_error = attempt.error
            return attempt  # nothing to store: the program never ran

        if code is None:
            if complete and current is not None and current.report is not None:
                self._adopt_current(attempt, current, complete=True)
                return attempt
            if complete and current is not None and current.error:
                attempt.error = (
                    "You said the program is complete, but it did not run:\n"
                    + current.error.split("\n\n")[0]
                    + "\nSend the complete corrected program in one ```python block."
                )
            else:
                attempt.error = runtime_feedback(None, reply=reply)
            self._pending_error = attempt.error
            return attempt  # nothing to store: no program

        code = _normalise(code)
        if current is not None and current.program is not None and code == current.program:
            # The same program again: nothing to approve or simulate (a failure is reported again).
            self._adopt_current(attempt, current, complete=complete)
            return attempt

        attempt.program = code
        if current is not None and current.program is not None:
            attempt.diff = unified_diff(current.program, code, f"attempt {current.index}", f"attempt {index}")
        if self.approve is not None and current is not None and current.program is not None:
            if not self.approve(code, attempt.diff):
                attempt.approved = False
                self._notes.append(
                    f"The user did not accept your revision (attempt {index}); it was not run. The current "
                    f"program is still the one of attempt {current.index}."
                )
                return attempt
            attempt.approved = True
        self._check(attempt)
        self.current = attempt
        self._store(attempt)
        return attempt

    def _adopt_current(self, attempt: Attempt, current: Attempt, *, complete: bool) -> None:
        """``attempt`` keeps the current program and its results (the model changed nothing)."""
        attempt.program = current.program
        attempt.execution = current.execution
        attempt.report = current.report
        attempt.score = current.score
        attempt.error = current.error
        attempt.changed = False
        attempt.complete = bool(complete and current.report is not None)
        if attempt.error is not None:
            self._pending_error = attempt.error
        self.current = attempt

    def _check(self, attempt: Attempt) -> None:
        """Simulate and critique ``attempt.program``; a failure becomes runtime feedback."""
        from ..pipeline import check

        assert attempt.program is not None
        if self._simulate is not None:
            try:
                attempt.execution, attempt.report = self._simulate(attempt.program)
            except (ProgramError, PlanningError, TrajectoryError, CriticError) as exc:
                attempt.error = runtime_feedback(exc, program=attempt.program)
                self._pending_error = attempt.error
                return
            attempt.score = attempt.report.score
            return
        rate = {} if self.sample_rate_hz is None else {"sample_rate_hz": self.sample_rate_hz}
        try:
            checked = check(attempt.program, self.scene, robot=self.robot, goals=self.goals, critics=self._selection,
                            params=self.params or None, **rate)  # fmt: skip
        except (TrajectoryError, CriticError) as exc:  # a critic could not judge this motion: report it, never crash
            log.warning("attempt %d: %s", attempt.index, exc)
            attempt.execution = getattr(exc, "execution", None)
            attempt.error = runtime_feedback(exc, program=attempt.program)
            self._pending_error = attempt.error
            return
        if checked.error is not None:  # the program did not run: the model gets the error, with its line
            attempt.error = runtime_feedback(checked.error, program=attempt.program)
            self._pending_error = attempt.error
            return
        attempt.execution, attempt.report = checked
        attempt.score = attempt.report.score

    # --- memory and prompts ----------------------------------------------------------------------

    def _system_prompt(self) -> str:
        return system_prompt(
            self.scene,
            embedded_rules=self.embedded_rules,
            memory_examples=self.examples,
            critics=self._selection,
            params=self.params or None,
        )

    def _retrieve(self, text: str) -> list[Interaction]:
        """The ``memory_k`` most relevant past interactions other than this loop's own, one per request text."""
        if self.memory is None or self.memory_k == 0:
            return []
        wanted = self.memory_k * _HITS_PER_EXAMPLE + len(self._memory_ids)
        try:
            hits = self.memory.search(text, k=min(wanted, MAX_SEARCH_K))
        except LLMError as exc:
            if self.memory.embedder is None:
                raise
            # The embedding server failed (it cannot embed, or is down): keyword memory, for the whole run.
            self.keyword_memory_reason = str(exc)
            log.warning(
                "memory retrieval by embeddings failed, so this run retrieves by keywords (BM25) instead: %s", exc
            )
            self.memory.embedder = None
            hits = self.memory.search(text, k=min(wanted, MAX_SEARCH_K))
        by_request: dict[str, Interaction] = {}
        for hit in hits:  # best similarity first
            if hit.id in self._memory_ids or not hit.program.strip() or hit.score is None:
                continue  # this loop's own, empty, or never ran (nothing to learn from)
            key = " ".join(hit.request.split()).lower()
            kept = by_request.get(key)
            if kept is None or _better(hit, kept):
                by_request[key] = hit
        return list(by_request.values())[: self.memory_k]

    def _store(self, attempt: Attempt) -> None:
        if self.memory is None or attempt.program is None:
            return
        attempt.memory_id = self.memory.add(self.session, attempt.request, attempt.program, attempt.feedback,
                                            attempt.score, source=attempt.source)  # fmt: skip
        self._memory_ids.add(attempt.memory_id)

    # --- history --------------------------------------------------------------------------------

    def _trimmed_history(self, keep: int | None = None) -> list[dict[str, str]]:
        """The last ``keep`` (default ``max_history_messages - 1``, room for the new user message) messages,
        starting at a user turn.

        When the current task's first message is cut off, the task is restated
        at the start of the first message kept.
        """
        keep = self.max_history_messages - 1 if keep is None else keep
        if keep <= 0:
            return []
        if len(self.history) <= keep:
            return [dict(m) for m in self.history]
        start = len(self.history) - keep
        if self.history[start]["role"] != "user":
            start += 1
        tail = [dict(m) for m in self.history[start:]]
        if start > self._task_index and self.task is not None and tail:
            tail[0]["content"] = (
                f"(Earlier messages were left out.) The task: {self.task}\n\n" + tail[0]["content"]
            )
        return tail


def _kept_reply(reply: str, program: str | None) -> str:
    """What the history keeps of a model reply: the reply, or for one over ``MAX_MESSAGE_CHARS`` its program
    (when that fits) or its start, saying what was left out."""
    if len(reply) <= MAX_MESSAGE_CHARS:
        return reply
    if program is not None:
        kept = f"```python\n{program}```\n[{len(reply):,}-character reply; only its program is repeated here]"
        if len(kept) <= MAX_MESSAGE_CHARS:
            return kept
    return cut_text(reply, MAX_MESSAGE_CHARS)


def _better(a: Interaction, b: Interaction) -> bool:
    """Whether interaction ``a`` is a better example than ``b`` of the same request: higher score, then newer."""
    sa = -1.0 if a.score is None else a.score
    sb = -1.0 if b.score is None else b.score
    return (sa, a.id) > (sb, b.id)
