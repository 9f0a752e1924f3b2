"""Cold starts and the main job against a baseline revision, in alternating new processes (not a test).

    git worktree add "$TMPDIR/base" REV
    .venv/bin/python benchmarks/cold_starts.py --baseline "$TMPDIR/base" --trace 8 --run 3

Each round runs the baseline and then this checkout: ``bsdfkit trace fitting/scenes/example.toml --rays 2097152``
(``--trace`` rounds) and ``bsdfkit run fitting/cl830.toml`` (``--run`` rounds), after one warm-up run of each
(so that both find their kernels in the compilation cache). Alternating matters: the speed of a shared machine
drifts by ±20 % within an hour. The baseline runs as ``python -m bsdfkit`` from its own folder with
``PYTHONPATH`` pointing there, because ``python -m`` puts the current folder first on ``sys.path``; run from
this checkout it would import this checkout's code. Both use this checkout's virtual environment.
Prints min-max and median wall time per command and checkout; numbers go into docs/tracer.md.
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TRACE = ["trace", "fitting/scenes/example.toml", "--rays", "2097152"]


def _seconds(argv: list[str], cwd: Path, env: dict[str, str]) -> float:
    t0 = time.monotonic()
    proc = subprocess.run(argv, cwd=cwd, env={**os.environ, **env}, capture_output=True, text=True)
    if proc.returncode != 0:
        sys.exit(f"cold_starts: {' '.join(argv)} in {cwd} failed: {proc.stderr.strip()[-500:]}")
    return time.monotonic() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", type=Path, required=True, help="a worktree of the baseline revision")
    ap.add_argument("--trace", type=int, default=8, help="rounds of the cold trace")
    ap.add_argument("--run", type=int, default=3, help="rounds of the main job")
    args = ap.parse_args()
    base = args.baseline.resolve()
    if not (base / "bsdfkit" / "__init__.py").is_file():
        sys.exit(f"cold_starts: {base}: not a bsdfkit checkout")
    python = str(Path(sys.executable))
    sides = {"baseline": ([python, "-m", "bsdfkit"], base, {"PYTHONPATH": str(base)}),
             "this": ([python, "-m", "bsdfkit"], ROOT, {})}
    with tempfile.TemporaryDirectory() as tmp:
        jobs = {"trace": (TRACE, args.trace),
                "run": (lambda side: ["run", "fitting/cl830.toml", "-o", f"{tmp}/{side}", "--force"], args.run)}
        for job, (argv, rounds) in jobs.items():
            if rounds < 1:
                continue
            times: dict[str, list[float]] = {side: [] for side in sides}
            for k in range(rounds + 1):  # round 0 warms the caches and is not counted
                for side, (cmd, cwd, env) in sides.items():
                    extra = argv(side) if callable(argv) else argv
                    t = _seconds(cmd + extra, cwd, env)
                    if k:
                        times[side].append(t)
            for side, values in times.items():
                print(f"{job:6s} {side:9s} {min(values):7.2f}-{max(values):7.2f} s, median "
                      f"{statistics.median(values):7.2f} s ({', '.join(f'{v:.2f}' for v in values)})", flush=True)


if __name__ == "__main__":
    main()
