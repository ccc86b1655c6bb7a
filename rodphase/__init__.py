"""rodphase: phase diagrams of stretched and twisted soft filaments.

From Python: rodphase.load, run, run_sweep, trace_boundaries, classify_file, open, table,
histories (see rodphase.api); from the shell: the `rodphase` command.
"""

from ._version import __version__

_API = ("classify_file", "histories", "load", "load_sweep", "open", "run", "run_sweep", "table",
        "trace_boundaries")
__all__ = ["__version__", *_API]


def __getattr__(name):
    # imported on first use: `rodphase --help` and the workers need not load the API
    if name in _API:
        from . import api

        return getattr(api, name)
    raise AttributeError(f"module 'rodphase' has no attribute {name!r}")


def __dir__():
    # the lazily loaded names too: tab completion in a notebook offers rodphase.run
    return sorted(set(globals()) | set(_API))
