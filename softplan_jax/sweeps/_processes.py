"""One sweep on several processes (``jax.distributed``) through a folder they all see:
process ``i`` of ``P`` plans the chunks ``c`` with ``c % P == i`` into the shared folder,
and the processes meet three times through the coordination service's key-value store
(folder prepared, header checked, chunks written), each posting "" or its error so that
all raise the first error instead of waiting (the documentation's "A sweep on several
hosts")."""

from __future__ import annotations

import itertools

import jax

__all__ = ["Processes", "current", "share"]

# How long a process waits for the others at a meeting: the slowest process's chunks of
# the whole sweep may lie between two meetings. A process that dies ends the wait early
# (the coordination service reports it); rerunning the same command resumes the sweep.
MEETING_TIMEOUT_MS = 7 * 24 * 3600 * 1000

_calls = itertools.count()  # sweep calls in this process: the same sequence on every process


class Processes:
    """This process's place among the sweep's processes, and their meetings."""

    def __init__(self, index: int, count: int, client=None, tag: str = ""):
        self.index, self.count, self.client, self.tag = index, count, client, tag

    @property
    def lead(self) -> bool:
        """Whether this process prepares the folder and merges the tables (process 0)."""
        return self.index == 0

    def meet(self, step: str, error: str = "") -> None:
        """Post this process's outcome of ``step`` ("" when it went well) and wait for
        every other's; raise ValueError with the first error posted."""
        if self.count == 1:
            if error:
                raise ValueError(error)
            return
        prefix = f"softplan_jax/sweep/{self.tag}/{step}"
        self.client.key_value_set(f"{prefix}/{self.index}", error or "ok")
        posted = [self.client.blocking_key_value_get(f"{prefix}/{i}", MEETING_TIMEOUT_MS) for i in range(self.count)]
        for i, text in enumerate(posted):
            if text != "ok":
                raise ValueError(text if i == self.index else f"process {i} of {self.count}: {text}")

    def post(self, step: str, error: str) -> None:
        """Post this process's error for ``step`` without waiting (it is about to raise):
        the others raise it at that meeting instead of waiting for this process."""
        if self.count > 1:
            self.client.key_value_set(f"softplan_jax/sweep/{self.tag}/{step}/{self.index}", error or "failed")

    def prefix(self, text: str) -> str:
        """A progress line's prefix: ``sweep`` or ``sweep[i/P]``."""
        return text if self.count == 1 else f"{text}[{self.index}/{self.count}]"


def current() -> Processes:
    """This process among ``jax.process_count()`` processes (one without ``jax.distributed``)."""
    count = jax.process_count()
    if count == 1:
        return Processes(0, 1)
    from jax._src import distributed  # the coordination service's client (as orbax and jax's own utilities use it)

    client = distributed.global_state.client
    if client is None:
        raise ValueError("several jax processes without a jax.distributed client: call jax.distributed.initialize")
    return Processes(jax.process_index(), count, client, str(next(_calls)))


def share(chunks, processes: Processes) -> list:
    """The chunks this process plans: those with ``c % P == i``."""
    return [c for c in chunks if c % processes.count == processes.index]
