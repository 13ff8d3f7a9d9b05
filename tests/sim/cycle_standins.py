"""Stand-ins for the pure clock logic (no physics), in a module of its own: a cycle process is
spawned, so it must import the factories by a plain module name (test_clock puts this folder
on sys.path, which the spawned child inherits)."""
from __future__ import annotations


class StandIn:
    """Counts steps; simulated time is steps * cycle_time (s). Raises in step `fail_at`."""

    def __init__(self, cycle_time: float = 0.004, fail_at: int | None = None):
        self.cycle_time = cycle_time
        self.steps = 0
        self.fail_at = fail_at

    @property
    def time(self) -> float:
        return self.steps * self.cycle_time

    def step(self) -> None:
        self.steps += 1
        if self.steps == self.fail_at:
            raise RuntimeError("cycle failed on purpose")


def make_stand_in(mailbox, cycle_time: float = 0.004, fail_at: int | None = None) -> StandIn:
    return StandIn(cycle_time, fail_at)


def make_broken(mailbox):
    raise ValueError("no controller today")


class Echo(StandIn):
    """Posts back every message the parent sends, with the step it arrived in."""

    def __init__(self, mailbox, cycle_time: float = 0.004):
        super().__init__(cycle_time)
        self.mailbox = mailbox

    def step(self) -> None:
        super().step()
        while (msg := self.mailbox.poll()) is not None:
            self.mailbox.post((self.steps, msg))


def make_echo(mailbox) -> Echo:
    return Echo(mailbox)


class SlowStore(StandIn):
    """Storing its recording takes 2 s (on the cycle process's asynchronous task)."""

    def rec_store(self) -> str:
        import time
        time.sleep(2.0)
        return "stored"


def make_slow_store(mailbox) -> SlowStore:
    return SlowStore()


def steps_of(controller) -> int:
    return controller.steps
