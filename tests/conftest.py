"""Test-session setup shared by every test module.

Under pytest-xdist (`make test` runs `pytest -n auto`), the controlling process compiles the
kernel once, into numba's disk cache, before it starts the workers: otherwise every worker's
first run compiles the same kernel at the same moment (about a minute of CPU each on a fresh
clone, the cores shared between them) and they race to write the same cache files. The
workers then load it. Without xdist nothing happens here: the first test that runs the kernel
compiles it, as a user's first run does.
"""

import sys
import time


def pytest_configure(config):
    workers = getattr(config.option, "numprocesses", None)
    if hasattr(config, "workerinput") or not workers or config.option.collectonly:
        return
    from rodphase.runner import compile_kernel

    sys.stderr.write(f"compiling the kernel once before the {workers} test workers start "
                     "(numba caches it on disk) ...\n")
    start = time.process_time()
    wall = compile_kernel()
    sys.stderr.write(f"kernel ready in {wall:.1f} s ({time.process_time() - start:.1f} s CPU "
                     "here; the topology and static functions compile beside it)\n")
