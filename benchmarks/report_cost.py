"""What `lolacli report --simulate` costs against `lolacli bus simulate` alone.

Both as a user runs them (a new process each, the defaults: the LOLA chain, 10 s at
2 kHz), interleaved, ``--repeat`` times; the best wall time of each counts. Issue #25
asks the report to take at most 2x the simulation alone, and its page to stay under 3 MB.

    python benchmarks/report_cost.py [--repeat 3] [-- extra bus simulate options]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def wall(command: list[str]) -> float:
    t0 = time.perf_counter()
    subprocess.run(command, cwd=ROOT, check=True, capture_output=True)
    return time.perf_counter() - t0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("extra", nargs="*",
                        help="options for both (e.g. --host-latency-us 31.2:10.2)")
    args = parser.parse_args()
    cli = [sys.executable, "-m", "lolacli"]
    with tempfile.TemporaryDirectory() as tmp:
        page = Path(tmp) / "lola.html"
        simulate = [*cli, "bus", "simulate", "--quiet", "--format", "json", *args.extra]
        report = [*cli, "report", "--simulate", "-o", str(page), *args.extra]
        runs: dict[str, list[float]] = {"simulate": [], "report": []}
        for _ in range(args.repeat):
            runs["simulate"].append(wall(simulate))
            runs["report"].append(wall(report))
        best = {k: min(v) for k, v in runs.items()}
        out = {
            "simulate_s": round(best["simulate"], 3),
            "report_s": round(best["report"], 3),
            "report_over_simulate": round(best["report"] / best["simulate"], 2),
            "html_bytes": page.stat().st_size,
            "json_bytes": page.with_suffix(".json").stat().st_size,
            "runs": {k: [round(x, 3) for x in v] for k, v in runs.items()},
        }
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
