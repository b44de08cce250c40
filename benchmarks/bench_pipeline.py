"""CPU per program of the check pipeline: warm simulate()+critique() per bundled program, and a cold CLI check.

Warm: one process started with the tree's worker environment (``robocritics.child.WORKER_ENV``, as a batch
worker and the studio's evaluator start: one BLAS thread, glibc malloc tunables), the UR3e loaded once, each
bundled program simulated and critiqued in its own scene (default critics, 125 Hz) once to warm caches, then
REPEATS times; the table shows the least CPU (``time.process_time``: user + system of the process, all
threads) per program and the mean over the programs both trees have the scene of (c045a0b lacks ``workbench``:
its programs are shown, not averaged). Programs/s per core is ``1000 / mean CPU ms``. Cold:
``robocritics check examples/programs/sorting_careful.py --scene sorting`` run as a child RUNS times, its user +
system CPU from ``resource.getrusage(RUSAGE_CHILDREN)``, the least; with a bytecode cache (as an installed package
has) and without (every module compiled from source: ``PYTHONDONTWRITEBYTECODE=1``, as this machine's environment
sets). FK: ``Robot.forward`` of 20,000 random samples (least of 7), the case where one batched BLAS pass lets
OpenBLAS go multi-threaded.

Every measurement runs in a fresh child interpreter, three rounds alternating the two trees, and the table shows
each number's least over the rounds. "Before" is the source tree of commit c045a0b (the baseline of issue 28),
extracted with ``git archive`` into a temporary directory and measured beside the current tree in the same
conditions: the speed of this shared machine changes by 2x from day to day, so only ratios measured in one run
compare. ``--before-src DIR`` measures an extracted tree (``DIR/src``) instead.

Run:
    .venv/bin/python benchmarks/bench_pipeline.py [REPEATS] [RUNS] [--before-src DIR]
"""

from __future__ import annotations

import json
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PROGRAMS = ROOT / "examples" / "programs"

#: The baseline of issue 28, measured beside the current tree in every run (see the module docstring).
BEFORE_COMMIT = "c045a0b"


def warm(repeats: int) -> dict[str, float]:
    """Least CPU ms of simulate()+critique() per bundled program in one warm process (the programs of this
    checkout whose scene the tree under test has built in: an older tree lacks the newer scenes)."""
    from robocritics import Robot, Scene, critique, simulate
    from robocritics.errors import SceneError

    robot = Robot.ur3e()
    out = {}
    for path in sorted(PROGRAMS.glob("*.py")):
        try:
            scene = Scene.builtin(path.stem.split("_")[0])
        except SceneError:
            continue
        source = path.read_text()
        critique(simulate(source, scene, robot))  # warm-up: collision models, caches
        times = []
        for _ in range(repeats):
            t0 = time.process_time()
            critique(simulate(source, scene, robot))
            times.append(time.process_time() - t0)
        out[path.stem] = 1000 * min(times)  # other load only ever adds CPU time
    return out


def worker_env(src: Path | None) -> dict[str, str]:
    """The variables the worker environment of tree ``src`` (``robocritics.child.WORKER_ENV``) adds to this one."""
    env = dict(os.environ)
    if src is not None:
        env["PYTHONPATH"] = str(Path(src) / "src")
    code = "import json\nfrom robocritics.child import WORKER_ENV\nprint(json.dumps(dict(WORKER_ENV)))"
    done = subprocess.run([sys.executable, "-c", code], env=env, cwd=ROOT, capture_output=True, text=True, check=True)
    return {k: v for k, v in json.loads(done.stdout).items() if k not in os.environ}


def cli_cold(runs: int, src: Path, bytecode_cache: bool, not_inherited: list[str]) -> float:
    """Least user + system CPU s of one cold ``robocritics check`` child (of the tree on ``PYTHONPATH``).

    ``bytecode_cache``: the children share a bytecode cache (``PYTHONPYCACHEPREFIX`` in a temporary directory,
    filled by one untimed run), as an installed package has; else they compile every robocritics module from
    source (``PYTHONDONTWRITEBYTECODE=1``, this machine's default).
    """
    import tempfile

    cmd = [sys.executable, "-m", "robocritics.cli", "check", str(PROGRAMS / "sorting_careful.py"), "--scene", "sorting"]
    env = {k: v for k, v in os.environ.items() if k not in not_inherited}  # a user's shell: no worker environment
    with tempfile.TemporaryDirectory() as cache:
        if bytecode_cache:
            env.pop("PYTHONDONTWRITEBYTECODE", None)
            env["PYTHONPYCACHEPREFIX"] = cache
            subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=ROOT, env=env)
        else:
            env["PYTHONDONTWRITEBYTECODE"] = "1"
            env.pop("PYTHONPYCACHEPREFIX", None)
        cpu = []
        for _ in range(runs):
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=ROOT, env=env)
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpu.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    return min(cpu)


def fk_cpu_ms(samples: int = 20000) -> float:
    import numpy as np

    from robocritics import Robot

    robot = Robot.ur3e()
    q = np.random.default_rng(0).uniform(-3, 3, size=(samples, robot.n))
    robot.forward(q, 0.05)
    times = []
    for _ in range(7):
        t0 = time.process_time()
        robot.forward(q, 0.05)
        times.append(time.process_time() - t0)
    return 1000 * min(times)


def expose_entry_points(tree: Path) -> None:
    """Make tree ``tree``'s own critic entry points visible on its ``src`` path.

    The virtual environment's installed robocritics names this checkout's critic modules, which an older tree
    lays out differently (c045a0b: ``robocritics.critics.*``); its plugin loader skips those by name. A
    ``.dist-info`` beside the older tree's package, made from that tree's ``pyproject.toml``, registers its
    critics the way its own install would.
    """
    import tomllib

    dist = tree / "src" / "robocritics_before-0.dist-info"
    if dist.exists():
        return
    project = tomllib.loads((tree / "pyproject.toml").read_text())["project"]
    entry_points = project["entry-points"]["robocritics"]
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: robocritics-before\nVersion: 0\n")
    lines = "".join(f"{name} = {module}\n" for name, module in entry_points.items())
    (dist / "entry_points.txt").write_text("[robocritics]\n" + lines)


def measure(src: Path | None, repeats: int, runs: int) -> dict[str, float]:
    """Run the measurements in a child interpreter on source tree ``src`` (None: this checkout)."""
    env = dict(os.environ)
    if src is not None:
        env["PYTHONPATH"] = str(Path(src) / "src")
    added = worker_env(src)
    env.update(added)
    done = subprocess.run(
        [sys.executable, __file__, "--child", str(repeats), str(runs), str(src or ROOT), json.dumps(sorted(added))],
        env=env, cwd=ROOT, capture_output=True, text=True, check=True,
    )  # fmt: skip
    return json.loads(done.stdout.strip().splitlines()[-1])


def child(repeats: int, runs: int, src: Path, not_inherited: list[str]) -> None:
    out = {f"{k} CPU ms": v for k, v in warm(repeats).items()}
    out["FK 20k samples CPU ms"] = fk_cpu_ms()
    out["check, cold CPU s (bytecode cached)"] = cli_cold(runs, src, True, not_inherited)
    out["check, cold CPU s (no bytecode)"] = cli_cold(runs, src, False, not_inherited)
    print(json.dumps(out))


def main() -> None:
    args = [a for a in sys.argv[1:]]
    if args[:1] == ["--child"]:
        child(int(args[1]), int(args[2]), Path(args[3]), json.loads(args[4]))
        return
    import tempfile

    scratch = tempfile.TemporaryDirectory()
    if "--before-src" in args:
        i = args.index("--before-src")
        before_src = Path(args[i + 1])
        del args[i : i + 2]
        before_name = f"the tree in {before_src}"
    else:
        archive = subprocess.run(["git", "archive", BEFORE_COMMIT], cwd=ROOT, capture_output=True, check=True).stdout
        subprocess.run(["tar", "-x", "-C", scratch.name], input=archive, check=True)
        before_src = Path(scratch.name)
        before_name = f"commit {BEFORE_COMMIT}"
    expose_entry_points(before_src)
    repeats = int(args[0]) if args else 15
    runs = int(args[1]) if len(args) > 1 else 7
    # rounds alternate the trees, and each number is the least over rounds: other load on the machine only
    # ever adds CPU time (cache and memory-bandwidth contention), so the minimum is the fairest comparison
    rounds = 3
    befores, nows = [], []
    for _ in range(rounds):
        befores.append(measure(before_src, repeats, runs))
        nows.append(measure(None, repeats, runs))
    before = {k: min(b[k] for b in befores) for k in befores[0]}
    now = {k: min(n[k] for n in nows) for k in nows[0]}
    # the mean over the programs both trees ran (a program of a scene the older tree lacks is listed, not averaged)
    both = [k for k in now if k in before and k.endswith(" CPU ms") and not k.startswith("FK")]
    for d in (before, now):
        d["mean CPU per program ms"] = statistics.fmean(d[k] for k in both)
        d["programs/s per core"] = 1000 / d["mean CPU per program ms"]
    order = [k for k in now if k.endswith(" CPU ms") and not k.startswith("FK")]
    order += ["mean CPU per program ms", "programs/s per core", "FK 20k samples CPU ms"]
    order += ["check, cold CPU s (bytecode cached)", "check, cold CPU s (no bytecode)"]
    w = max(map(len, order))
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    print(
        f"bench_pipeline — least over {rounds} rounds of: warm least of {repeats}, cold least of {runs}; "
        f"{os.cpu_count()} CPUs, load average {load}"
    )
    print(f"{'':<{w}}  {'before':>9}  {'now':>9}  {'before/now':>10}")
    for k in order:
        b, n = before.get(k), now[k]
        ratio = (n / b if k.startswith("programs/s") else b / n) if b else None
        bs = f"{b:9.3f}" if b is not None else f"{'-':>9}"
        print(f"{k:<{w}}  {bs}  {n:9.3f}  {ratio:10.2f}" if ratio else f"{k:<{w}}  {bs}  {n:9.3f}")
    print(f"before: {before_name}, measured in this run")
    print(f"reproduce: .venv/bin/python benchmarks/bench_pipeline.py {' '.join(sys.argv[1:])}")


if __name__ == "__main__":
    main()
