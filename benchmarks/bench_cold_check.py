"""Where the CPU of a cold ``robocritics check`` goes: the interpreter, the third-party libraries a check needs, and
what is robocritics' own (its imports and the check).

Each row is the least user + system CPU (``resource.getrusage(RUSAGE_CHILDREN)``) of RUNS fresh children, with a
bytecode cache (``PYTHONPYCACHEPREFIX`` in a temporary directory, filled by one untimed run of each), the rows
alternating run by run so that the machine's load falls on all alike:

* ``python -c pass``: the interpreter's start (with this venv's ``.pth`` files).
* ``third-party floor``: importing what every check imports from other packages (numpy, pydantic with one model
  validated, coal, ruckig, pluggy, importlib.metadata) and nothing of robocritics: no change to robocritics can
  take a cold check below it. With ``--pinocchio``, Pinocchio is in the floor too.
* ``check``: ``robocritics check examples/programs/sorting_careful.py --scene sorting``.

The last column is each row's share of the check. ``benchmarks/bench_pipeline.py`` compares the check with
c045a0b's; this script says how much of it robocritics can still cut.

Run:
    .venv/bin/python benchmarks/bench_cold_check.py [RUNS] [--pinocchio]
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

FLOOR = """import numpy, pydantic, coal, ruckig, pluggy, importlib.metadata{extra}
class Probe(pydantic.BaseModel):
    x: float = 0.0
Probe(x=1.0)
"""


def rows(pinocchio: bool) -> dict[str, list[str]]:
    floor = FLOOR.format(extra=", pinocchio" if pinocchio else "")
    check = ["-m", "robocritics.cli", "check", str(ROOT / "examples/programs/sorting_careful.py"), "--scene", "sorting"]
    return {
        "python -c pass": ["-c", "pass"],
        "third-party floor" + (" (with pinocchio)" if pinocchio else ""): ["-c", floor],
        "check": check,
    }


def cpu_s(args: list[str], env: dict[str, str]) -> float:
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run([sys.executable, *args], env=env, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime


def main() -> None:
    args = sys.argv[1:]
    pinocchio = "--pinocchio" in args
    args = [a for a in args if a != "--pinocchio"]
    runs = int(args[0]) if args else 9
    table = rows(pinocchio)
    with tempfile.TemporaryDirectory() as cache:
        env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
        env["PYTHONPYCACHEPREFIX"] = cache
        for command in table.values():
            cpu_s(command, env)  # fills the bytecode cache
        best = {name: float("inf") for name in table}
        for _ in range(runs):
            for name, command in table.items():
                best[name] = min(best[name], cpu_s(command, env))  # other load only ever adds CPU time
    check = best["check"]
    own = "robocritics (check - floor)"
    width = max(map(len, [*best, own]))
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    print(f"bench_cold_check — least of {runs} runs each, CPU s; {os.cpu_count()} CPUs, load average {load}")
    for name, value in best.items():
        print(f"{name:<{width}}  {value:7.3f}  {100 * value / check:5.1f} %")
    floor = [v for k, v in best.items() if k.startswith("third-party floor")][0]
    print(f"{own:<{width}}  {check - floor:7.3f}  {100 * (check - floor) / check:5.1f} %")
    print(f"reproduce: .venv/bin/python benchmarks/bench_cold_check.py {' '.join(sys.argv[1:])}")


if __name__ == "__main__":
    main()
