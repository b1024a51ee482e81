"""Where `make test`'s time goes: each test's CPU, in its pytest worker and in the processes
it ran, with its wall time; summed per module.

    .venv/bin/python benchmarks/suite_cpu.py                        # the suite, as make test
    .venv/bin/python benchmarks/suite_cpu.py --top 20 -- -m "not realtime" tests/test_cli.py

Runs pytest as `make test` does (``-n 4 --dist loadgroup``, bytecode written and read
whatever ``PYTHONDONTWRITEBYTECODE`` says; anything after ``--`` goes to pytest as well)
with this file as a plugin (``-p suite_cpu``, in every worker). Around each test it reads
the worker's ``getrusage``:

* ``RUSAGE_SELF``: the worker's own CPU, its threads included (an in-process flight, a
  daemon flown in a thread, the virtual lab in a thread);
* ``RUSAGE_CHILDREN``: the processes the test started and reaped (``gs fly``,
  ``gs sim-device``, a fleet's daemons), their own children included once reaped.

It prints the pytest run's wall time, the CPU those two account for, the modules by CPU and
the tests whose wall time is over ``--slow`` seconds. On CI's 2 cores the suite is bound
by CPU when the sum approaches twice the wall time: then a test's CPU, not its wall time,
is what it costs the run. Not a test: it runs the suite once and prints numbers.
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

REPO = Path(__file__).resolve().parents[1]
OUT_ENV = "GS_SUITE_CPU_DIR"
"""The directory the workers write their rows into (set by :func:`main`)."""


def _cpu(who: int) -> float:
    usage = resource.getrusage(who)
    return usage.ru_utime + usage.ru_stime


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None) -> Iterator[None]:
    """Setup, call and teardown of ``item``: one row (node id, self CPU, children's CPU,
    wall) [s] into this worker's file."""
    out = os.environ.get(OUT_ENV)
    own, children, wall = (_cpu(resource.RUSAGE_SELF), _cpu(resource.RUSAGE_CHILDREN),
                           time.monotonic())
    yield
    if out:
        row = (f"{item.nodeid}\t{_cpu(resource.RUSAGE_SELF) - own:.3f}\t"
               f"{_cpu(resource.RUSAGE_CHILDREN) - children:.3f}\t"
               f"{time.monotonic() - wall:.3f}\n")
        with open(Path(out) / f"{os.getpid()}.tsv", "a", encoding="utf-8") as handle:
            handle.write(row)


def _rows(directory: Path) -> list[tuple[str, float, float, float]]:
    rows = []
    for path in directory.glob("*.tsv"):
        for line in path.read_text(encoding="utf-8").splitlines():
            node, own, children, wall = line.split("\t")
            rows.append((node, float(own), float(children), float(wall)))
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--workers", default="4", help="pytest -n (make test: 4)")
    parser.add_argument("--top", type=int, default=30, help="modules to list")
    parser.add_argument("--slow", type=float, default=30.0, help="list tests over this [s]")
    parser.add_argument("--rows", type=Path, help="also write every test's row here (TSV: "
                        "node id, worker CPU, processes' CPU, wall [s])")
    parser.add_argument("pytest_args", nargs="*", help="after --: more pytest arguments")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="suite_cpu_") as folder:
        env = {**os.environ, OUT_ENV: folder,
               "PYTHONPATH": os.pathsep.join(filter(None, (str(REPO / "benchmarks"),
                                                           os.environ.get("PYTHONPATH"))))}
        env.pop("PYTHONDONTWRITEBYTECODE", None)  # as the Makefile's pytest target
        subprocess.run([sys.executable, "-m", "compileall", "-q", "groundstation", "sim_device"],
                       cwd=REPO, env=env, check=True)
        command = [sys.executable, "-m", "pytest", "-q", "-n", args.workers,
                   "--dist", "loadgroup", "-p", "suite_cpu", *args.pytest_args]
        wall0, children0 = time.monotonic(), _cpu(resource.RUSAGE_CHILDREN)
        code = subprocess.run(command, cwd=REPO, env=env, check=False).returncode
        wall, total = time.monotonic() - wall0, _cpu(resource.RUSAGE_CHILDREN) - children0
        rows = _rows(Path(folder))
    if args.rows:
        args.rows.write_text("".join(f"{n}\t{o:.3f}\t{c:.3f}\t{w:.3f}\n" for n, o, c, w in rows),
                             encoding="utf-8")
    own = sum(r[1] for r in rows)
    children = sum(r[2] for r in rows)
    print(f"\npytest: exit {code}, {len(rows)} tests, {wall:.0f} s wall, {total:.0f} s CPU in "
          f"all ({total / wall:.2f} cores busy on average, {os.cpu_count()} here)")
    print(f"in the tests: {own:.0f} s in the workers (their threads included), "
          f"{children:.0f} s in the processes they ran; the rest ({total - own - children:.0f} s)"
          " is collection, start-up and processes never reaped")
    modules: dict[str, list[Any]] = defaultdict(lambda: [0.0, 0.0, 0.0, 0])
    for node, o, c, w in rows:
        m = modules[node.split("::")[0]]
        m[0] += o
        m[1] += c
        m[2] += w
        m[3] += 1
    print(f"\n{'CPU s':>7} {'worker':>7} {'procs':>7} {'wall s':>7} {'tests':>5}  module")
    for name, (o, c, w, n) in sorted(modules.items(), key=lambda kv: -(kv[1][0] + kv[1][1])
                                     )[: args.top]:
        print(f"{o + c:7.1f} {o:7.1f} {c:7.1f} {w:7.1f} {n:5d}  {name}")
    slow = sorted((r for r in rows if r[3] > args.slow), key=lambda r: -r[3])
    print(f"\ntests over {args.slow:g} s of wall time: {len(slow)}")
    for node, o, c, w in slow:
        print(f"{w:7.1f} s wall, {o + c:6.1f} s CPU  {node}")
    return code


if __name__ == "__main__":
    raise SystemExit(main())
