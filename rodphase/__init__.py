"""rodphase: phase diagrams of stretched and twisted soft filaments."""

__version__ = "0.1.0"
