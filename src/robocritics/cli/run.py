"""``robocritics run``: a task in words → an LLM-written program → simulated → critiqued (→ fixed).

::

    robocritics run "put the green apple in the white box" --scene sorting \\
        --base-url http://localhost:11434/v1 --model llama3.1 [--auto] [--max-attempts 5] \\
        [--critics joint_speed,collision] [--memory memory.sqlite] [--api-key-env OPENAI_API_KEY]

Without ``--auto`` the model is asked once and its program is checked; with
``--auto`` the critics' feedback goes back to the model until every critic is
OK, the model says the program is complete, or ``--max-attempts`` replies were
made (:meth:`robocritics.llm.loop.Loop.run`; the best attempt is the final one).
Each fix first applies the critics' own repairs (an attempt of kind ``repair``,
its changes listed) and sends the model only what is left; ``--no-repairs``
sends everything to the model (the paper's loop).
Each attempt's program, critic report and score are printed as they come.

``--base-url`` / ``--model`` fall back to ``ROBOCRITICS_BASE_URL`` /
``ROBOCRITICS_MODEL``; the API key is read from the variable named by
``--api-key-env``, else ``ROBOCRITICS_API_KEY`` / ``OPENAI_API_KEY``.

``--timeout`` is the most one LLM request may take in all (connecting,
waiting, reading the reply, retries and their pauses): a server that stalls or
sends a byte at a time ends the run at that deadline with exit status 2.
Replies are streamed (``--no-stream`` to ask for whole replies) and capped at
``--max-tokens`` (default 1024); a stream silent for ``--idle-timeout`` seconds
ends the request, which is not retried (the connection is closed, so the
server stops generating). ``--context-tokens`` is the model's context window
(default: what the server says: llama.cpp ``/props``, vLLM ``/v1/models``, or
its error when a prompt is too long); every prompt is fitted to it. While a
reply is awaited a line says so, and with ``--verbose`` the tokens are counted
as they arrive. A memory whose embedding server fails falls back, with one
warning, to keyword (BM25) retrieval.
Replies, programs and errors are printed cleaned of undecodable characters
and, past ``llm.limits.MAX_PRINTED_CHARS``, cut.

Exit status: 0 the final attempt has no Error verdict; 1 it has one (or its
program did not run); 2 configuration errors (no base URL or model, unknown
scene or critic, unset key variable, an empty or overlong task, an unusable
memory file) and failures of the LLM endpoint.

"""

from __future__ import annotations

import argparse
import logging
import sys
from typing import TextIO

import math

from ._common import (
    UsageError,
    add_critic_options,
    add_goal_option,
    add_llm_options,
    add_robot_options,
    file_name,
    llm_api_key,
    llm_client,
    load_params,
    one_line,
    positive_int,
    robot_for,
    subcommand,
    terminal_text,
)
from ..errors import LLMError, RoboCriticsError

__all__ = ["add_run_parser", "run_command"]

# Seconds between two progress lines while tokens arrive (--verbose).
_PROGRESS_EVERY_S = 2.0
# Model replies with --auto: the paper's five attempts per task (llm.options.DEFAULT_MAX_ATTEMPTS, not imported
# here so that building the parser stays cheap).
_MAX_ATTEMPTS = 5


def add_run_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Add the ``run`` subcommand to ``subparsers``; its handler (``args.func``) is :func:`run_command`."""
    p = subparsers.add_parser(
        "run",
        help="let an LLM write a robot program for a task, simulate it and run the critics (optionally fix it)",
        description="Ask an OpenAI-compatible LLM for a robot program for TASK in a scene, simulate it, run the "
        "critics and print the report. With --auto, send the critics' feedback back until every critic is OK, the "
        "model says the program is complete, or --max-attempts replies were made. Exit status: 0 the final "
        "attempt has no Error verdict, 1 it has one or did not run, 2 configuration or LLM endpoint errors.",
    )
    p.add_argument("task", metavar="TASK", help='what the robot should do, e.g. "put the green apple in the white box"')
    p.add_argument(
        "--scene",
        metavar="NAME|PATH",
        required=True,
        help="built-in scene name (recycling, sorting, breakfast) or a scene JSON file",
    )
    add_llm_options(p)
    p.add_argument(
        "--embedding-model",
        metavar="NAME",
        help="embedding model for memory retrieval (default: $ROBOCRITICS_EMBEDDING_MODEL; without one, BM25)",
    )
    p.add_argument("--auto", action="store_true", help="iterate automatically with the critics' feedback")
    p.add_argument(
        "--no-repairs",
        action="store_true",
        help="send every fix to the model (default: the critics' own repairs first, the model gets what is left)",
    )
    p.add_argument(
        "--max-attempts",
        metavar="N",
        type=positive_int,
        default=_MAX_ATTEMPTS,
        help=f"most model replies with --auto (default {_MAX_ATTEMPTS}, as in the paper)",
    )
    add_critic_options(p)
    add_goal_option(p)
    add_robot_options(p)
    p.add_argument("--memory", metavar="FILE", type=file_name, help="interaction memory (SQLite file, created if missing)")
    p.add_argument(
        "--embedded-rules",
        action="store_true",
        help="also paste the critics' rules into the system prompt (the paper's embedded condition)",
    )
    p.add_argument(
        "--temperature", metavar="T", type=_temperature, default=None, help="sampling temperature, 0 to 2 (default 0)"
    )
    p.add_argument(
        "--context-tokens",
        metavar="N",
        type=positive_int,
        default=None,
        help="the model's context window in tokens, to fit the prompt to (default: what the server says, "
        "e.g. llama.cpp's n_ctx; see docs/llm.md)",
    )
    p.add_argument("-v", "--verbose", action="store_true", help="show tokens arriving and prompt sizes (stderr)")
    p.set_defaults(func=run_command)
    return p


class _Progress:
    """Progress lines on ``stream`` while the model is asked: one when a request is sent, the token count
    every ``_PROGRESS_EVERY_S`` seconds (``verbose``), and the total when the reply is in."""

    def __init__(self, stream: TextIO, model: str, verbose: bool):
        self.stream = stream
        self.model = model
        self.verbose = verbose
        self._last_s = 0.0
        self.loop = None

    def __call__(self, progress) -> None:
        if progress.phase == "waiting":
            self._last_s = 0.0
            tokens = getattr(self.loop, "last_prompt_tokens", None)
            size = f" (prompt ~{tokens:,} tokens)" if self.verbose and tokens else ""
            _say(self.stream, f"robocritics run: asking {self.model}{size} ...", flush=True)
        elif progress.phase == "receiving":
            if self.verbose and progress.elapsed_s - self._last_s >= _PROGRESS_EVERY_S:
                self._last_s = progress.elapsed_s
                _say(self.stream, f"  ... {progress.tokens} tokens, {progress.elapsed_s:.1f} s", flush=True)
        elif progress.phase == "done":
            rate = f", {progress.tokens / progress.elapsed_s:.1f} tokens/s" if progress.elapsed_s > 0 else ""
            _say(self.stream, f"  reply: {progress.tokens} tokens in {progress.elapsed_s:.1f} s{rate}", flush=True)


class _WarningLines(logging.Handler):
    """Prints the library's warnings as ``robocritics run: warning: ...`` lines."""

    def __init__(self, stream: TextIO):
        super().__init__(logging.WARNING)
        self.stream = stream

    def emit(self, record: logging.LogRecord) -> None:
        try:
            _say(self.stream, f"robocritics run: warning: {one_line(record.getMessage())}", flush=True)
        except Exception:  # never let a warning line end the run
            self.handleError(record)


def _temperature(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not (math.isfinite(value) and 0.0 <= value <= 2.0):
        raise argparse.ArgumentTypeError(f"{text!r} must be a number from 0 to 2")
    return value


def _say(out: TextIO, text: object = "", *, flush: bool = False) -> None:
    """Print ``text`` cleaned of lone surrogates and with the escape sequences of the model's reply (or of any
    outside text) shown as escapes (:func:`terminal_text`), and still print it on a stream that cannot encode all
    of it."""
    from ..llm.limits import clean_text

    line = terminal_text(clean_text(str(text)))
    try:
        print(line, file=out, flush=flush)
    except UnicodeEncodeError:
        encoding = getattr(out, "encoding", None) or "ascii"
        print(line.encode(encoding, errors="replace").decode(encoding, errors="replace"), file=out, flush=flush)


def _error(message: str, stream: TextIO) -> int:
    _say(stream, f"robocritics run: error: {one_line(message)}")
    return 2


def _print_attempt(attempt, out: TextIO) -> None:
    from ..llm.limits import MAX_PRINTED_CHARS, cut_text
    from ..critic.report import format_score

    _say(out, f"=== attempt {attempt.index} [{attempt.kind}] ===")
    if attempt.error and attempt.program is None:
        _say(out, "The reply contained no program.")
    elif attempt.complete:
        _say(out, "The model says the program is complete (no change).")
    elif not attempt.changed:
        _say(out, "The model sent the same program again.")
    elif attempt.program is not None:
        if attempt.changes:
            _say(out, "--- critic repairs ---")
            for change in attempt.changes:
                _say(out, cut_text(str(change), MAX_PRINTED_CHARS))
        _say(out, "--- program ---")
        _say(out, cut_text(attempt.program.rstrip("\n"), MAX_PRINTED_CHARS, "characters of the program"))
    if attempt.error:
        _say(out, "--- did not run ---")
        _say(out, cut_text(attempt.error, MAX_PRINTED_CHARS))
    elif attempt.report is not None and (attempt.changed or attempt.index == 1):
        _say(out, "--- critics ---")
        _say(out, cut_text(str(attempt.report), MAX_PRINTED_CHARS))
    _say(out, f"score: {format_score(attempt.score)}")
    _say(out, flush=True)


def run_command(args: argparse.Namespace, *, stdout: TextIO | None = None, stderr: TextIO | None = None) -> int:
    """Handle ``robocritics run`` (see the module docstring); returns the exit status."""
    from ..critic import select_critics
    from ..goals import parse_goals
    from ..scene import Scene
    from ..pipeline import check_scene_ids
    from ..llm.loop import Loop
    from ..llm.memory import InteractionMemory
    from ..llm.prompts import check_task
    from ..critic.report import format_score

    out = stdout or sys.stdout
    err = stderr or sys.stderr

    # Configuration: everything is checked before the first request.
    try:
        api_key = llm_api_key(args)
    except UsageError as exc:
        return _error(str(exc), err)
    try:
        task = check_task(args.task)
        scene = Scene.resolve(args.scene)
        check_scene_ids(scene)  # an id that shadows a skill would only fail after the LLM was asked
        params = load_params(getattr(args, "params", None)) or None
        critics = [c.strip() for c in args.critics.split(",") if c.strip()] if args.critics else None
        select_critics(critics, params)
        goals = parse_goals(getattr(args, "goals", None), scene)
        robot = robot_for(args, scene)
    except RoboCriticsError as exc:
        return _error(str(exc), err)
    if goals:  # the model is asked to state them with expect(...), which the task_outcome critic checks
        task += "\nGoals (checked on the final scene; state each with expect(...)): " + "; ".join(map(str, goals))
    try:
        client = llm_client(args, api_key, embedding_model=args.embedding_model)
    except UsageError as exc:
        return _error(str(exc), err)
    verbose = bool(getattr(args, "verbose", False))
    progress = _Progress(err, client.model, verbose)
    client.on_progress = progress
    warnings = _WarningLines(err)
    library_log = logging.getLogger("robocritics.llm")
    library_log.addHandler(warnings)

    memory = None
    try:
        if args.memory:
            try:
                memory = InteractionMemory(args.memory, embedder=client if client.embedding_name else None)
            except RoboCriticsError as exc:
                return _error(str(exc), err)
        options = {} if args.temperature is None else {"temperature": args.temperature}
        context = getattr(args, "context_tokens", None)
        where = "--context-tokens"
        if context is None:
            context, where = client.server_context_tokens(), "from the server"
        if context is not None and context < 512:
            return _error(f"--context-tokens {context}: a context under 512 tokens cannot hold the prompt", err)
        loop = Loop(
            client,
            scene,
            robot=robot,
            critics=critics,
            params=params,
            memory=memory,
            automation="auto" if args.auto else "guided",
            max_attempts=args.max_attempts,
            embedded_rules=args.embedded_rules,
            on_attempt=lambda attempt: _print_attempt(attempt, out),
            model_options=options,
            context_tokens=context,
            goals=goals,
            repairs=not args.no_repairs,
        )
        progress.loop = loop  # the prompt size of each call, for the progress line
        _say(out, f"robocritics run: {client.model} at {client.base_url}, scene {scene.name!r}")
        if context is not None:
            _say(out, f"context: {context:,} tokens ({where}); replies up to {client.max_tokens or 'any'} tokens")
        _say(out, f"task: {task}")
        _say(out)
        try:
            final = loop.request(task)
        except LLMError as exc:
            return _error(f"the LLM endpoint failed: {exc}", err)
        except RoboCriticsError as exc:
            return _error(str(exc), err)
        n = len(loop.attempts)
        if final.report is None:
            verdict = "its program did not run"
        elif final.report.has_errors:
            verdict = "it still has an Error"
        else:
            verdict = "no Error"
        which = f"attempt {final.index} of {n}" if n > 1 else "attempt 1"
        _say(out, f"final: {which}, score {format_score(final.score)}, {verdict}", flush=True)
        return 1 if final.has_errors else 0
    finally:
        library_log.removeHandler(warnings)
        if memory is not None:
            memory.close()
        client.close()


@subcommand("run")
def _build_run(sub: "argparse._SubParsersAction") -> None:
    add_run_parser(sub)
