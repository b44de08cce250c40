"""The critic benchmark runs (tiny sizes) and its vectorised and reference critics agree."""

from __future__ import annotations

import importlib.util
from pathlib import Path


def test_benchmark_smoke(capsys):
    path = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_critics.py"
    spec = importlib.util.spec_from_file_location("bench_critics", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    assert bench.main(["--duration", "3", "--rate", "100", "--repeats", "1", "--ref-repeats", "1"]) == 0
    out = capsys.readouterr().out
    assert "flags agree with the references: yes" in out
    assert "reproduce:" in out
