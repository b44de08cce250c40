"""A real headless Chromium for tests of what a person looks at (selenium + Debian's chromium-driver).

``chromium()`` starts one browser with flags that work on a machine with no screen,
no GPU and no network: SwiftShader renders WebGL on the CPU, and every host name
except 127.0.0.1 resolves to nothing, so a page that tried to load anything from
the internet would fail visibly instead of hanging. ``.ci/run`` installs
``chromium`` and ``chromium-driver`` when they are missing.

Helpers here read what the page shows: :func:`canvas_stats` reads a WebGL
canvas's pixels back (mean and variance per channel), :func:`wait_for` polls a
JavaScript condition with a generous timeout (a loaded CI machine renders slowly).
"""

from __future__ import annotations

import contextlib
import shutil
import tempfile
import time
from pathlib import Path

import pytest

CHROMIUM_FLAGS = (
    "--headless=new",
    "--no-sandbox",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
    "--disable-dev-shm-usage",
    '--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1',
    "--window-size=1400,900",
)

#: Seconds a page may take to reach a state: generous, because SwiftShader on a loaded 2-core machine is slow.
PAGE_TIMEOUT_S = 60.0

SCREENSHOTS = Path(__file__).resolve().parent.parent / "docs" / "screenshots"


def save_screenshot(driver, name: str) -> Path:
    """The page as PNG in ``docs/screenshots/name``, through the project's safe writer (a temporary file renamed
    over it: never written through a link placed at the name)."""
    from robocritics._files import write_file_atomically

    SCREENSHOTS.mkdir(parents=True, exist_ok=True)
    return write_file_atomically(SCREENSHOTS / name, driver.get_screenshot_as_png(), "screenshot")


def chromium_paths() -> tuple[str, str] | None:
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    driver = shutil.which("chromedriver")
    return (browser, driver) if browser and driver else None


@contextlib.contextmanager
def chromium():
    """A headless Chromium WebDriver; the test is skipped when chromium/chromedriver are not installed."""
    paths = chromium_paths()
    if paths is None:
        pytest.skip("chromium and chromium-driver are not installed (.ci/run installs them)")
    pytest.importorskip("selenium")
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    browser, driver_path = paths
    options = webdriver.ChromeOptions()
    options.binary_location = browser
    profile = tempfile.mkdtemp(prefix="robocritics-chromium-")
    for flag in CHROMIUM_FLAGS:
        options.add_argument(flag)
    options.add_argument(f"--user-data-dir={profile}")
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service(driver_path), options=options)
    driver.set_page_load_timeout(PAGE_TIMEOUT_S)
    driver.set_script_timeout(PAGE_TIMEOUT_S)
    try:
        yield driver
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)


def wait_for(driver, script: str, *args, timeout_s: float = PAGE_TIMEOUT_S, what: str = ""):
    """Poll ``return <script>`` until it is truthy; return its value, or fail naming ``what``."""
    deadline = time.monotonic() + timeout_s
    last = None
    while time.monotonic() < deadline:
        last = driver.execute_script(script, *args)
        if last:
            return last
        time.sleep(0.1)
    errors = [e["message"] for e in driver.get_log("browser") if e.get("level") == "SEVERE"]
    raise AssertionError(f"timed out after {timeout_s} s waiting for {what or script!r}; last value {last!r}; "
                         f"browser errors: {errors}")


def severe_console_errors(driver) -> list[str]:
    """The page's SEVERE console messages (uncaught exceptions, failed loads)."""
    return [e["message"] for e in driver.get_log("browser") if e.get("level") == "SEVERE"]


# Reads a canvas back as a PNG data URL: works for WebGL canvases created with
# preserveDrawingBuffer (the replay sets it), returns per-channel statistics.
_CANVAS_STATS_JS = """
const canvas = arguments[0];
const w = canvas.width, h = canvas.height;
const copy = document.createElement('canvas');
copy.width = w; copy.height = h;
const ctx = copy.getContext('2d');
ctx.drawImage(canvas, 0, 0);
const px = ctx.getImageData(0, 0, w, h).data;
let n = 0, sum = [0, 0, 0], sq = [0, 0, 0];
for (let i = 0; i < px.length; i += 4 * 7) {
  for (let c = 0; c < 3; c++) { sum[c] += px[i + c]; sq[c] += px[i + c] * px[i + c]; }
  n++;
}
const mean = sum.map(s => s / n);
const variance = sq.map((s, c) => s / n - mean[c] * mean[c]);
return {width: w, height: h, mean: mean, variance: variance};
"""


def canvas_stats(driver, canvas) -> dict:
    """``{"width", "height", "mean": [r, g, b], "variance": [r, g, b]}`` of a canvas element's pixels."""
    return driver.execute_script(_CANVAS_STATS_JS, canvas)


def canvas_pixels(driver, canvas) -> bytes:
    """The canvas as PNG bytes, to compare two renders of the same canvas."""
    import base64

    data_url = driver.execute_script(
        "const c = arguments[0]; const copy = document.createElement('canvas');"
        "copy.width = c.width; copy.height = c.height; copy.getContext('2d').drawImage(c, 0, 0);"
        "return copy.toDataURL('image/png');",
        canvas,
    )
    return base64.b64decode(data_url.split(",", 1)[1])


# ---------------------------------------------------------------------------- real processes for the studio's tests


@contextlib.contextmanager
def command_process(args: list[str], first_line: str, *, start_timeout_s: float = 120.0):
    """Run ``python -m robocritics ARGS`` (stderr to a file: a full pipe must never block it); yield
    ``(proc, lines, stderr_path)`` once its first stdout line starts with ``first_line`` (``lines``: that line and
    any printed right after it). Ctrl-C (SIGINT) ends it."""
    import os
    import signal
    import subprocess
    import sys

    log = tempfile.NamedTemporaryFile(prefix="robocritics-", suffix=".log", delete=False)
    proc = subprocess.Popen(
        [sys.executable, "-m", "robocritics", *args], stdout=subprocess.PIPE, stderr=log, text=True,
        env={**os.environ, "ROBOCRITICS_BASE_URL": "", "ROBOCRITICS_MODEL": ""},
        # a suite started from a background shell ignores SIGINT, and children inherit that: give Ctrl-C back
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    try:
        lines = [proc.stdout.readline()]
        if not lines[0].startswith(first_line):
            proc.kill()
            proc.wait()
            raise AssertionError(f"{args[0]} did not start: {lines[0]!r} {Path(log.name).read_text()[-2000:]}")
        yield proc, lines, Path(log.name)
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        proc.stdout.close()
        log.close()
        Path(log.name).unlink(missing_ok=True)


@contextlib.contextmanager
def studio_process(*args: str):
    """``robocritics studio --port 0 --no-browser ARGS``; yields ``(url, proc)``."""
    with command_process(["studio", "--port", "0", "--no-browser", *args], "robocritics studio: http") as (proc, lines, _):
        yield lines[0].split()[2], proc


@contextlib.contextmanager
def ursim_process(*args: str):
    """``robocritics ursim -v`` on free ports; yields ``(ports, stderr_path)`` with ``ports`` as
    ``{"rtde": …, "dashboard": …, "secondary": …}`` (its event log, e.g. ``program_started``, is in the file)."""
    with command_process(["ursim", "-v", "--rtde-port", "0", "--dashboard-port", "0", "--secondary-port", "0", *args],
                         "URSim on 127.0.0.1") as (_, lines, log):
        line = lines[0]
        ports = {"rtde": int(line.split("RTDE ")[1].split(",")[0]),
                 "dashboard": int(line.split("dashboard ")[1].split(",")[0]),
                 "secondary": int(line.split("secondary ")[1].split(" ")[0])}
        yield ports, log


def click(driver, element_id: str) -> None:
    """Click an element by id from JavaScript (a loaded renderer can be slow to report layout to WebDriver)."""
    driver.execute_script("document.getElementById(arguments[0]).click()", element_id)


def set_editor(driver, text: str) -> None:
    """Type ``text`` into the studio's editor as a person would (an input event follows)."""
    driver.execute_script("const e = document.getElementById('editor'); e.value = arguments[0];"
                          "e.dispatchEvent(new Event('input'));", text)
