"""The ``softplan`` command (``softplan --help``)."""

from .main import build_parser, main, trajectory_record, write_trajectory

__all__ = ["main", "build_parser", "trajectory_record", "write_trajectory"]
