"""Evaluation suite benchmark: wall time of `gs eval --fast` and the figures it reaches.

Flies the whole suite in-process (the same call as `gs eval --fast`), prints each
flight's wall time, the total wall time with and without the figures, and the
metrics table of report.md. The reached figures are what tests/test_evaluation_suite.py
holds its thresholds against.

    .venv/bin/python benchmarks/bench_eval.py                 # report into a temp dir
    .venv/bin/python benchmarks/bench_eval.py --out eval      # keep the report
    .venv/bin/python benchmarks/bench_eval.py --real-time     # the real-time suite (slow)
    .venv/bin/python benchmarks/bench_eval.py --perturb 1-5   # worst case over 5 vehicles

Target: the fast suite within 2-3 minutes on 2 cores.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from groundstation.config import load_config  # noqa: E402
from groundstation.logs import configure_logging  # noqa: E402
from sim_device.evaluation import run_eval  # noqa: E402
from sim_device.evaluation.perturb import parse_seeds  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, default=None, help="report directory")
    parser.add_argument("--real-time", action="store_true", help="fly in real time")
    parser.add_argument("--config", type=Path, default=REPO / "config" / "sim.yaml")
    parser.add_argument("--perturb", action="append", default=[],
                        help="seed(s) of perturbed vehicles, as gs eval --perturb")
    args = parser.parse_args()
    configure_logging("warning", "console")
    out = args.out or Path(tempfile.mkdtemp(prefix="bench_eval_"))
    cpu0, wall0 = time.process_time(), time.perf_counter()
    report = run_eval(load_config(args.config), fast=not args.real_time, out_dir=out,
                      progress=print, perturb=parse_seeds(args.perturb))
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    flights = sum(o.wall_s for o in report.outcomes.values())
    print(f"\nsuite: {len(report.outcomes)} flights in {wall:.1f} s wall "
          f"({flights:.1f} s flying, {wall - flights:.1f} s scoring and figures), "
          f"{cpu:.1f} s CPU, {os.cpu_count()} CPUs")
    text = report.report_md.read_text(encoding="utf-8")
    table = text.split("## Metrics", 1)[1].split("Definitions.", 1)[0]
    print(table.strip())
    print(f"\nreport: {report.report_md}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
