"""A real kill -9 for the resume tests: a rodphase command in its own process group,
SIGKILLed (workers and all) once enough runs are in its store."""

import os
import signal
import subprocess
import sys
import time

from rodphase.store import read_table


def kill_after_runs(args: list[str], store, runs: int, *, poll: float = 0.05,
                    timeout: float = 300.0) -> set[str]:
    """Start `python -m rodphase.cli *args`, SIGKILL its process group once `store` holds at
    least `runs` runs (or it ends, or `timeout` s pass), and return the run ids the store
    held: a reader may follow a running sweep, since the file is never written in place."""
    command = [sys.executable, "-m", "rodphase.cli", *map(str, args)]
    proc = subprocess.Popen(command, start_new_session=True, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL,
                            env=dict(os.environ, HDF5_USE_FILE_LOCKING="FALSE"))
    deadline, finished = time.time() + timeout, set()
    try:
        while time.time() < deadline and proc.poll() is None:
            time.sleep(poll)
            if os.path.exists(store):
                finished = set(read_table(store)["run_id"])
                if len(finished) >= runs:
                    break
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    return finished
