"""The two serial dialects side by side: the same flights in the virtual lab over a pty.

Flies ``gs fly --demo`` (the daemon against ``gs sim-device`` in a child process) once
per dialect and trajectory, and prints from each flight's ``meta.json`` and report:
the serial line used per direction (bytes per second and share of the 57600-baud line),
in the AscTec LL dialect the polls (unanswered) and command acknowledgements (missing,
command-to-acknowledgement p50/p99), and the tracking error against the lab's ground
truth (RMS and maximum) with the LL figure relative to the X-3D's (within 20 %).

    .venv/bin/python benchmarks/bench_dialects.py                    # hover 20 s and the square
    .venv/bin/python benchmarks/bench_dialects.py --trajectory hover --duration 20
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
DIALECTS = ("x3d", "asctec-ll")


def fly(protocol: str, trajectory: str, duration: float | None, out: Path) -> dict[str, Any]:
    """One demo flight; returns its link figures and truth metrics."""
    args = [sys.executable, "-m", "groundstation", "fly", "--config",
            str(ROOT / "config" / "sim.yaml"), "--demo", "--protocol", protocol,
            "--trajectory", trajectory, "--log-dir", str(out)]
    if duration is not None:
        args += ["--duration", str(duration)]
    done = subprocess.run(args, capture_output=True, text=True, cwd=ROOT, timeout=600)
    if done.returncode != 0:
        raise SystemExit(f"{protocol} {trajectory}: exit {done.returncode}\n{done.stdout}")
    (log,) = [p for p in out.iterdir() if (p / "meta.json").exists()]
    link = json.loads((log / "meta.json").read_text())["outcome"]["link"]
    metrics = json.loads((log / "report" / "metrics.json").read_text())["metrics"]
    return {"link": link, "rms_m": metrics["rms_m"], "max_m": metrics["max_m"]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trajectory", action="append",
                        help="hover, square, ... (repeatable; default: hover and square)")
    parser.add_argument("--duration", type=float, default=None,
                        help="seconds on the trajectory (default: hover 20 s, others one lap)")
    args = parser.parse_args()
    trajectories = args.trajectory or ["hover", "square"]
    for trajectory in trajectories:
        duration = args.duration if args.duration is not None else (
            20.0 if trajectory == "hover" else None)
        results = {}
        for protocol in DIALECTS:
            with tempfile.TemporaryDirectory() as tmp:
                results[protocol] = fly(protocol, trajectory, duration, Path(tmp))
        print(f"== {trajectory}" + (f" ({duration:g} s)" if duration else ""))
        for protocol, r in results.items():
            link = r["link"]
            line = (f"  {protocol:9s} in {link['in_bytes_per_s']:5.0f} B/s "
                    f"({100 * link['in_line_share']:3.0f} %), out {link['out_bytes_per_s']:5.0f}"
                    f" B/s ({100 * link['out_line_share']:3.0f} %), rejected {link['rejected']}")
            if link.get("polls") is not None:
                line += (f"; polls {link['polls']} ({link['polls_unanswered']} unanswered), "
                         f"acks {link['acks']} ({link['acks_missing']} missing), "
                         f"command->ack p50/p99 {link['ack_p50_ms']:.1f}/"
                         f"{link['ack_p99_ms']:.1f} ms")
            print(line)
            print(f"  {'':9s} truth RMS {1e3 * r['rms_m']:.2f} mm, max {1e3 * r['max_m']:.2f} mm")
        ratio = results["asctec-ll"]["rms_m"] / results["x3d"]["rms_m"]
        print(f"  LL / X-3D RMS: {ratio:.2f} (target within 0.8-1.2)")


if __name__ == "__main__":
    main()
