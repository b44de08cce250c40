"""``robocritics run``: a task in words → an LLM-written program → simulated → critiqued (→ fixed).

::

    robocritics run "put the green apple in the white box" --scene sorting \\
        --base-url http://localhost:11434/v1 --model llama3.1 [--auto] [--max-attempts 5] \\
        [--critics joint_speed,collision] [--memory memory.sqlite] [--api-key-env OPENAI_API_KEY]

Without ``--auto`` the model is asked once and its program is checked; with
``--auto`` the critics' feedback goes back to the model until every critic is
OK, the model says the program is complete, or ``--max-attempts`` replies were
made (:meth:`robocritics.llm.loop.Loop.run`; the best attempt is the final one).
Each attempt's program, critic report and score are printed as they come.

``--base-url`` / ``--model`` fall back to ``ROBOCRITICS_BASE_URL`` /
``ROBOCRITICS_MODEL``; the API key is read from the variable named by
``--api-key-env``, else ``ROBOCRITICS_API_KEY`` / ``OPENAI_API_KEY``.

Exit status: 0 the final attempt has no Error verdict; 1 it has one (or its
program did not run); 2 configuration errors (no base URL or model, unknown
scene or critic, unset key variable) and failures of the LLM endpoint.

"""

from __future__ import annotations

import argparse
import os
import sys
from typing import TextIO

from ._common import load_params, one_line, positive_float, positive_int, subcommand
from ..errors import LLMError, RoboCriticsError

__all__ = ["add_run_parser", "run_command"]

# Seconds per HTTP phase; longer than the library's default because an interactive run is often the first
# request to a local server, which loads the model before it answers.
_TIMEOUT_S = 120.0
# Model replies with --auto: the paper's five attempts per task (llm.loop.DEFAULT_MAX_ATTEMPTS, not imported
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
    p.add_argument("--base-url", metavar="URL", help="OpenAI-compatible endpoint (default: $ROBOCRITICS_BASE_URL)")
    p.add_argument("--model", metavar="NAME", help="chat model (default: $ROBOCRITICS_MODEL)")
    p.add_argument(
        "--api-key-env",
        metavar="VAR",
        help="name of the environment variable holding the API key (default: ROBOCRITICS_API_KEY, then OPENAI_API_KEY)",
    )
    p.add_argument(
        "--embedding-model",
        metavar="NAME",
        help="embedding model for memory retrieval (default: $ROBOCRITICS_EMBEDDING_MODEL; without one, BM25)",
    )
    p.add_argument("--auto", action="store_true", help="iterate automatically with the critics' feedback")
    p.add_argument(
        "--max-attempts",
        metavar="N",
        type=positive_int,
        default=_MAX_ATTEMPTS,
        help=f"most model replies with --auto (default {_MAX_ATTEMPTS}, as in the paper)",
    )
    p.add_argument("--critics", metavar="A,B", help="comma-separated critic names (default: all installed)")
    p.add_argument(
        "--params",
        metavar="FILE",
        help='JSON file of threshold overrides, e.g. {"joint_speed": {"warn_speed_m_s": 0.8}}',
    )
    p.add_argument("--memory", metavar="FILE", help="interaction memory (SQLite file, created if missing)")
    p.add_argument(
        "--embedded-rules",
        action="store_true",
        help="also paste the critics' rules into the system prompt (the paper's embedded condition)",
    )
    p.add_argument("--temperature", metavar="T", type=float, default=None, help="sampling temperature (default 0)")
    p.add_argument(
        "--timeout",
        metavar="S",
        type=positive_float,
        default=_TIMEOUT_S,
        help=f"seconds per HTTP phase (default {_TIMEOUT_S:g})",
    )
    p.set_defaults(func=run_command)
    return p


def _error(message: str, stream: TextIO) -> int:
    print(f"robocritics run: error: {one_line(message)}", file=stream)
    return 2


def _print_attempt(attempt, out: TextIO) -> None:
    from ..report import format_score

    print(f"=== attempt {attempt.index} [{attempt.kind}] ===", file=out)
    if attempt.error and attempt.program is None:
        print("The reply contained no program.", file=out)
    elif attempt.complete:
        print("The model says the program is complete (no change).", file=out)
    elif not attempt.changed:
        print("The model sent the same program again.", file=out)
    elif attempt.program is not None:
        print("--- program ---", file=out)
        print(attempt.program.rstrip("\n"), file=out)
    if attempt.error:
        print("--- did not run ---", file=out)
        print(attempt.error, file=out)
    elif attempt.report is not None and (attempt.changed or attempt.index == 1):
        print("--- critics ---", file=out)
        print(str(attempt.report), file=out)
    print(f"score: {format_score(attempt.score)}", file=out)
    print(file=out, flush=True)


def run_command(args: argparse.Namespace, *, stdout: TextIO | None = None, stderr: TextIO | None = None) -> int:
    """Handle ``robocritics run`` (see the module docstring); returns the exit status."""
    from ..critic import select_critics
    from ..scene import Scene
    from ..llm.client import OpenAICompatible
    from ..llm.loop import Loop
    from ..llm.memory import InteractionMemory
    from ..report import format_score

    out = stdout or sys.stdout
    err = stderr or sys.stderr

    # Configuration: everything is checked before the first request.
    api_key = None
    if args.api_key_env:
        api_key = os.environ.get(args.api_key_env)
        if not api_key:
            return _error(f"the environment variable {args.api_key_env} (from --api-key-env) is not set", err)
    try:
        scene = Scene.resolve(args.scene)
        params = load_params(getattr(args, "params", None)) or None
        critics = [c.strip() for c in args.critics.split(",") if c.strip()] if args.critics else None
        select_critics(critics, params)
    except RoboCriticsError as exc:
        return _error(str(exc), err)
    try:
        client = OpenAICompatible(
            base_url=args.base_url,
            model=args.model,
            api_key=api_key,
            embedding_model=args.embedding_model,
            timeout_s=args.timeout,
        )
    except LLMError as exc:
        return _error(f"{exc} (or use --base-url / --model)", err)

    memory = None
    try:
        if args.memory:
            try:
                memory = InteractionMemory(args.memory, embedder=client if client.embedding_name else None)
            except RoboCriticsError as exc:
                return _error(str(exc), err)
        options = {} if args.temperature is None else {"temperature": args.temperature}
        loop = Loop(
            client,
            scene,
            critics=critics,
            params=params,
            memory=memory,
            automation="auto" if args.auto else "guided",
            max_attempts=args.max_attempts,
            embedded_rules=args.embedded_rules,
            on_attempt=lambda attempt: _print_attempt(attempt, out),
            model_options=options,
        )
        print(f"robocritics run: {client.model} at {client.base_url}, scene {scene.name!r}", file=out)
        print(f"task: {args.task}", file=out)
        print(file=out)
        try:
            final = loop.request(args.task)
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
        print(f"final: {which}, score {format_score(final.score)}, {verdict}", file=out, flush=True)
        return 1 if final.has_errors else 0
    finally:
        if memory is not None:
            memory.close()
        client.close()


@subcommand("run")
def _build_run(sub: "argparse._SubParsersAction") -> None:
    add_run_parser(sub)
