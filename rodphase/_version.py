"""The version of rodphase: its one definition (pyproject.toml reads it from here).

Its own module, at the bottom of the package, so that the store, the sweep and the CLI can
name it without importing the package's `__init__`, which loads the Python API (a cycle)."""

__version__ = "0.1.0"
