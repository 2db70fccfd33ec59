"""``python -m softplan_jax.cli``: the ``softplan`` command, as the console script runs it."""

from .main import console_main

__all__ = []

if __name__ == "__main__":
    raise SystemExit(console_main())
