"""The ``softplan`` command (``softplan --help``)."""

from .main import console_main, main
from .parser import build_parser
from .trajectory import trajectory_record, write_trajectory

__all__ = ["main", "console_main", "build_parser", "trajectory_record", "write_trajectory"]
