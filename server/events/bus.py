"""The device's event bus: one ordered stream of events and alarms (seed section 2, DESIGN 8).

The device core publishes through the helpers of `EventBus` (`command`, `alarm`,
`state_change`, `digital_io`, `rsvp_request`, `rsvp_answer`, `operator_message`,
`alarm_acknowledged`) from any thread; every
subscriber sees the same events in the same order, each numbered by `sequence` (1, 2, 3, ...
per bus). Pure Python: the gRPC servicer converts these records to and from the wire.

Guarantees:
- Publishing never waits for a subscriber and costs O(subscribers).
- The last `history` events are kept; `subscribe(after_sequence=n)` first yields the kept
  events after n, then live ones, with nothing duplicated or skipped at the seam. Events it
  asks for that are no longer kept are announced first by one `EventsLost(first, last)`.
- Each subscriber has a buffer of `buffer` events. When a publish finds it full, the
  subscriber's pending events are dropped and replaced by one `EventsLost` naming exactly
  the sequences dropped; it then continues live. A slow reader costs itself events, never
  the device or the other readers their time.

An `EventsLost` is delivered as an `Event` whose `sequence` is the last lost one, so a client
that resumes "after the last sequence I saw" resumes correctly after a loss too.
"""
from __future__ import annotations

import asyncio
import dataclasses
import functools
import itertools
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator, Sequence

# The records are the bus's vocabulary: importable from here as well.
from landscape.server.events.records import (  # noqa: F401
    _PUBLISHED, PHASE_EVENT_IDS, Alarm, AlarmAcknowledged, CommandEvent, Detail, DigitalIOSignal,
    Event, EventsLost, OperatorMessage, Phase, RsvpAnswer, RsvpRequest, Severity, StateChange,
    _check)

DEFAULT_HISTORY = 10_000   # events kept for resuming subscribers
DEFAULT_BUFFER = 1_024     # events a subscriber may fall behind before it loses some
MAX_TEXT = 1_024           # characters of any one string of an event; longer ones are cut
                           # (with "…"), so no event exceeds a few kilobytes

class SequenceOutOfRange(ValueError):
    """A subscriber asked to resume after a sequence this bus has not reached.

    Typically the client saw an earlier run of the device server (sequences restart at 1).
    """


# -- Subscriptions ---------------------------------------------------------------------------

class Subscription:
    """One reader of the bus: `get()` or iterate, or `await next_async()` on an event loop;
    `close()` (or leave the `with`) to stop.

    Made by `EventBus.subscribe`. Thread-safe; closing it from another thread wakes a
    waiting `get` or `next_async`.
    """

    def __init__(self, bus: EventBus, capacity: int, replay: Sequence[Event]):
        self._bus = bus
        self._capacity = capacity
        # The raw lock on the hot paths (a publish offers every subscriber an event; an async
        # reader takes it): the condition only for readers that wait on a thread, so a
        # publish pays for a notify only when one does (issue 31 item 6).
        self._lock = threading.Lock()
        self._cond = threading.Condition(self._lock)
        self._blocked = 0          # threads waiting in get()
        self._replay = deque(replay)   # resumed events; not bounded, the history bounds it
        self._live: deque[Event] = deque()
        self._closed = False
        self._draining = False     # the bus closed: what is pending still goes out, then end
        self._waiter: asyncio.Future | None = None   # an async reader waiting, on its loop

    def get(self, timeout: float | None = None) -> Event | None:
        """The next event, waiting up to `timeout` seconds (None: forever).

        Returns None on timeout or once the subscription is closed.
        """
        with self._lock:
            self._blocked += 1
            try:
                if not self._cond.wait_for(self._ready, timeout) or self._closed:
                    return None
            finally:
                self._blocked -= 1
            return self._next()

    def __iter__(self) -> Iterator[Event]:
        while (event := self.get()) is not None:
            yield event

    async def next_async(self) -> Event | None:
        """The next event, awaited on the running loop; None once closed. Publishers on any
        thread wake it through the loop (no thread waits for it)."""
        while True:
            with self._lock:
                if self._closed:
                    return None
                if self._replay or self._live or self._draining:
                    return self._next()
                waiter = self._waiter = asyncio.get_running_loop().create_future()
            # Whoever takes the waiter (offer, end) clears it; a cancelled one is never
            # resolved (_resolve looks).
            await waiter

    @property
    def closed(self) -> bool:
        """Closed, or the bus closed and everything pending has been taken."""
        return self._closed or (self._draining and not (self._replay or self._live))

    def close(self) -> None:
        """Stop receiving; pending events are discarded. Idempotent."""
        self._bus.unsubscribe(self)
        self.end()

    def __enter__(self) -> Subscription:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # Called by the bus with its lock held (lock order: bus, then subscription).

    def offer(self, event: Event, clock: Callable[[], float]) -> asyncio.Future | None:
        """Take `event`; returns the async reader's wake-up, if one waits, for the publisher
        to resolve (with the others of its loop in one hand-over: `_wake_all`)."""
        with self._lock:
            live = self._live
            if len(live) >= self._capacity:
                # Full: drop what is pending (merging an unread loss notice) and say so once.
                head = live[0]
                first = (head.detail.first_sequence if isinstance(head.detail, EventsLost)
                         else head.sequence)
                live.clear()
                live.append(_lost(first, event.sequence - 1, clock()))
            live.append(event)
            if self._blocked:
                self._cond.notify()
            waiter, self._waiter = self._waiter, None
            return waiter

    def end(self, drain: bool = False) -> None:
        """No more events; with `drain`, the pending ones are still delivered first."""
        with self._lock:
            if drain:
                self._draining = True
            else:
                self._closed = True
                self._replay.clear()
                self._live.clear()
            self._cond.notify_all()
            self._wake()

    def _next(self) -> Event | None:
        # With the lock held: the next pending event, or None once a drained bus has none left.
        if self._replay or self._live:
            return (self._replay or self._live).popleft()
        return None

    def _wake(self) -> None:
        # With the lock held: hand the async reader's wake-up to its loop.
        waiter, self._waiter = self._waiter, None
        if waiter is not None:
            waiter.get_loop().call_soon_threadsafe(_resolve, waiter)

    def _ready(self) -> bool:
        return self._closed or self._draining or bool(self._replay) or bool(self._live)


def _clip(text: str) -> str:
    return text if len(text) <= MAX_TEXT else text[:MAX_TEXT - 1] + "…"


def _clipped(detail):
    """`detail` with every string field (and every string of a tuple field) clipped."""
    changes = None
    for name in _text_fields(type(detail)):
        value = getattr(detail, name)
        if isinstance(value, str):
            if len(value) > MAX_TEXT:
                changes = {**(changes or {}), name: _clip(value)}
        elif any(len(v) > MAX_TEXT for v in value):
            changes = {**(changes or {}), name: tuple(_clip(v) for v in value)}
    return dataclasses.replace(detail, **changes) if changes else detail


@functools.cache
def _text_fields(kind: type) -> tuple[str, ...]:
    """The fields of a detail record that hold text (str, or tuples of str)."""
    return tuple(f.name for f in dataclasses.fields(kind)
                 if f.type in ("str", "tuple[str, ...]"))


def _resolve(waiter: asyncio.Future) -> None:
    if not waiter.done():
        waiter.set_result(None)


def _resolve_all(waiters: list[asyncio.Future]) -> None:
    for waiter in waiters:
        _resolve(waiter)


def _wake_all(waiters: list[asyncio.Future]) -> None:
    """Resolve the async readers' wake-ups with one call per event loop: 50 subscribers
    waiting on the server's loop cost it one wake-up, not 50 (issue 31 item 6)."""
    by_loop: dict[asyncio.AbstractEventLoop, list[asyncio.Future]] = {}
    for waiter in waiters:
        by_loop.setdefault(waiter.get_loop(), []).append(waiter)
    for loop, some in by_loop.items():
        try:
            loop.call_soon_threadsafe(_resolve_all, some)
        except RuntimeError:   # that loop is closed: nobody is left to wake
            pass


def _lost(first: int, last: int, now: float) -> Event:
    return Event(last, now, "events_lost", (str(first), str(last)), EventsLost(first, last))


# -- The bus ---------------------------------------------------------------------------------

class EventBus:
    """The device's ordered event stream; see the module docstring for its guarantees.

    history: events kept for resuming subscribers. buffer: events one subscriber may fall
    behind before it loses some (at least 2: the loss notice and the newest event).
    clock: the publish time source, unix seconds (time.time by default; tests inject one).
    """

    def __init__(self, history: int = DEFAULT_HISTORY, buffer: int = DEFAULT_BUFFER,
                 clock: Callable[[], float] = time.time):
        if history < 0 or buffer < 2:
            raise ValueError("history must be >= 0 and buffer >= 2")
        self.history_size = history
        self.buffer_size = buffer
        self._clock = clock
        self._lock = threading.Lock()   # guards everything below; held for O(subscribers)
        self._history: deque[Event] = deque(maxlen=history)
        self._last_sequence = 0
        # In subscription order, which is the order waiting readers are woken: in a set's
        # hash order, 50 gRPC streams cost the server's loop 10-12 us more per delivery
        # (measured, issue 31 item 6; most likely each connection's writes then interleave).
        self._subscribers: dict[Subscription, None] = {}
        self._closed = False

    @property
    def last_sequence(self) -> int:
        """The sequence of the latest event published, 0 before the first."""
        return self._last_sequence

    @property
    def subscriber_count(self) -> int:
        return len(self._subscribers)

    # Publishing helpers for the device core; each returns the Event it published.

    def command(self, command_id: str, command: str, phase: Phase, point_name: str = "",
                tag_name: str = "", tag_index: int = 0, message: str = "") -> Event:
        """A non-blocking command's phase, e.g. (id, "MoveAbsolute", Phase.DONE, "p1").

        data: [command_id, tag_name] for TAG_REACHED, [command_id, message] for FAILED,
        [command_id, point_name] otherwise.
        """
        detail = CommandEvent(command_id, command, phase, point_name, tag_name, tag_index,
                              message)
        second = {Phase.TAG_REACHED: tag_name, Phase.FAILED: message}.get(phase, point_name)
        return self.publish(PHASE_EVENT_IDS[phase], (command_id, second), detail)

    def alarm(self, severity: Severity, code: int, message: str, command_id: str = "") -> Event:
        """Seed clientAlarm; data: [code, message, command_id]."""
        detail = Alarm(severity, code, message, command_id)
        return self.publish("alarm", (str(code), message, command_id), detail)

    def state_change(self, from_state: str, to_state: str, reason: str = "") -> Event:
        """The device state moved; data: [from_state, to_state, reason]."""
        detail = StateChange(from_state, to_state, reason)
        return self.publish("state_changed", (from_state, to_state, reason), detail)

    def digital_io(self, command_id: str, type: str, unit_id: int, bit_string: int,
                   bits_on: int) -> Event:
        """A signalDigitalIO watch fired; data: [command_id, type, unit_id, bit_string, bits_on]."""
        detail = DigitalIOSignal(command_id, type, unit_id, bit_string, bits_on)
        data = (command_id, type, str(unit_id), str(bit_string), str(bits_on))
        return self.publish("digital_io", data, detail)

    def rsvp_request(self, rsvp_id: str, event_id: str, data: Sequence[str] = (),
                     choices: Sequence[str] = (), default_choice: str = "",
                     timeout_s: float = 0.0, alarm: bool = False) -> Event:
        """An RSVP the device asks (timeout_s in seconds); data: [rsvp_id, event_id, *data]."""
        detail = RsvpRequest(rsvp_id, alarm, event_id, tuple(data), tuple(choices),
                             default_choice, timeout_s)
        return self.publish("rsvp_request", (rsvp_id, event_id, *data), detail)

    def rsvp_answer(self, rsvp_id: str, choice: str, data: Sequence[str] = (),
                    timed_out: bool = False) -> Event:
        """How an RSVP was answered; data: [rsvp_id, choice, *data]."""
        detail = RsvpAnswer(rsvp_id, choice, tuple(data), timed_out)
        return self.publish("rsvp_answer", (rsvp_id, choice, *data), detail)

    def operator_message(self, text: str, source: str) -> Event:
        """A message for the operator; data: [text, source]."""
        return self.publish("operator_message", (text, source), OperatorMessage(text, source))

    def alarm_acknowledged(self, alarm_sequence: int, by: str, client: str = "",
                           on_behalf_of: str = "") -> Event:
        """An alarm was acknowledged; data: [alarm_sequence, by, client, on_behalf_of]."""
        detail = AlarmAcknowledged(alarm_sequence, by, client, on_behalf_of)
        return self.publish("alarm_acknowledged", (str(alarm_sequence), by, client, on_behalf_of),
                            detail)

    def publish(self, event_id: str, data: Sequence[str], detail: Detail) -> Event:
        """Number, stamp, keep and fan out one event. Prefer the typed helpers above."""
        _check(isinstance(detail, _PUBLISHED), f"cannot publish a {type(detail).__name__}")
        data = tuple(_clip(d) for d in data[:16])
        detail = _clipped(detail)
        with self._lock:
            # Numbered and stamped under the lock, so sequence order is time order.
            self._last_sequence += 1
            event = Event(self._last_sequence, self._clock(), event_id, data, detail)
            self._history.append(event)
            waiters = [waiter for subscriber in self._subscribers
                       if (waiter := subscriber.offer(event, self._clock)) is not None]
        _wake_all(waiters)
        return event

    def kept(self, sequence: int) -> Event | None:
        """The event numbered `sequence` while the history keeps it, else None."""
        with self._lock:
            if not self._history:
                return None
            index = sequence - self._history[0].sequence
            return self._history[index] if 0 <= index < len(self._history) else None

    # Subscribing.

    def subscribe(self, after_sequence: int | None = None) -> Subscription:
        """A new subscription: live events only, or the kept events after `after_sequence`
        first (preceded by an EventsLost for those no longer kept), then live ones.

        Raises SequenceOutOfRange if after_sequence is beyond the last published event.
        """
        with self._lock:
            replay = [] if after_sequence is None else self._replay_after(after_sequence)
            subscription = Subscription(self, self.buffer_size, replay)
            if self._closed:
                subscription.end()
            else:
                self._subscribers[subscription] = None
            return subscription

    def close(self) -> None:
        """End every subscription once it has delivered what is pending (then their get
        returns None); later ones start closed.

        Publishing still works, so a device core shutting down need not check.
        """
        with self._lock:
            self._closed = True
            subscribers, self._subscribers = self._subscribers, {}
            for subscription in subscribers:
                subscription.end(drain=True)

    def _replay_after(self, after: int) -> list[Event]:
        # Called with the lock held; kept sequences are contiguous, oldest first.
        if after < 0 or after > self._last_sequence:
            raise SequenceOutOfRange(
                f"after_sequence {after} is not in 0..{self._last_sequence}, the events of "
                f"this device so far (did it restart?)")
        oldest = self._history[0].sequence if self._history else self._last_sequence + 1
        replay = []
        if after + 1 < oldest:
            replay.append(_lost(after + 1, oldest - 1, self._clock()))
        start = max(after + 1, oldest) - oldest
        replay.extend(itertools.islice(self._history, start, None))
        return replay

    def unsubscribe(self, subscription: Subscription) -> None:
        """The subscription leaves the bus (Subscription.close)."""
        with self._lock:
            self._subscribers.pop(subscription, None)
