"""The command line's BLAS threads: ``python benchmarks/blas_threads.py [RUNS]``.

``fmscal calibrate`` on a 60 s 1 kHz ``spatial-arm`` log (issue 46's cost: "no more than 7 s of CPU with
everything on"), run as a user runs it, in a process of its own: as the command line runs it (numpy's BLAS on
one thread, ``analysis/cli/_main.py``) and with ``OPENBLAS_NUM_THREADS`` set to the machine's cores (OpenBLAS's
own default, which the command keeps where the environment sets it). ``RUNS`` (default 3) alternated runs of
each after one warm-up; printed per run and as the range: the CPU (user and system, the process and its
threads) and the wall time, s. ``PYTHONDONTWRITEBYTECODE`` is dropped from the runs' environment: an installed
package keeps its compiled bytecode, which the warm-up writes for an editable one.
"""

import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from fmscal.plant.numerics import THREAD_VARIABLES

PAYLOAD = ["--mass", "1.2", "--com", "0.01", "-0.005", "0.06",
           "--inertia", "4e-3", "5e-3", "2.5e-3", "2e-4", "-1e-4", "1.5e-4"]


def _run(log, env):
    """``(cpu_s, wall_s)`` of one ``fmscal calibrate`` of ``log``."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "fmscal.analysis.cli", "calibrate", str(log), *PAYLOAD],
                   env=env, check=True, capture_output=True)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime), wall


def main(argv=None):
    args = sys.argv[1:] if argv is None else argv
    runs = int(args[0]) if args else 3
    base = {k: v for k, v in os.environ.items() if k not in (*THREAD_VARIABLES, "PYTHONDONTWRITEBYTECODE")}
    settings = {"the command line (one thread)": base,
                f"OPENBLAS_NUM_THREADS={os.cpu_count()}": {**base, "OPENBLAS_NUM_THREADS": str(os.cpu_count())}}
    with tempfile.TemporaryDirectory() as folder:
        log = Path(folder) / "arm60.csv"
        subprocess.run([sys.executable, "-m", "fmscal.analysis.cli", "simulate", "--scenario", "spatial-arm",
                        "--duration", "60", "--seed", "1", "--out", str(log)], check=True, capture_output=True)
        _run(log, base)                                                  # warm-up: the caches, casadi's files
        figures = {name: [] for name in settings}
        for i in range(runs):
            for name, env in settings.items():
                figures[name].append(_run(log, env))
                cpu, wall = figures[name][-1]
                print(f"run {i + 1}, {name}: CPU {cpu:.2f} s, wall {wall:.2f} s", flush=True)
    for name, values in figures.items():
        cpu, wall = zip(*values)
        print(f"{name}: CPU {min(cpu):.2f}-{max(cpu):.2f} s, wall {min(wall):.2f}-{max(wall):.2f} s")


if __name__ == "__main__":
    main()
