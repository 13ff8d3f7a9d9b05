"""The event bus and EventService.Subscribe: order, resume, loss, fan-out, round trip.

The bus tests are pure Python; the service tests use a real device server on loopback and
real channels. The device publishes its own events (state changes, alarms) on the same bus,
so service tests check the whole stream's order and look for their own events within it.
"""
from __future__ import annotations

import asyncio
import itertools
import threading
import time

import grpc
import pytest

from landscape.server.events import bus as events
from landscape.server.events.bus import EventBus, Phase, Severity
from landscape.v1 import event_service_pb2 as pb
from landscape.v1 import event_service_pb2_grpc

DEADLINE_S = 20.0   # a liveness bound for waits, never a performance claim


def wait_until(predicate, what: str, timeout: float = DEADLINE_S) -> None:
    end = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < end, f"timed out waiting until {what}"
        time.sleep(0.002)


def drain(subscription: events.Subscription) -> list[events.Event]:
    out = []
    while (event := subscription.get(timeout=0)) is not None:
        out.append(event)
    return out


def seqs(evs) -> list[int]:
    return [e.sequence for e in evs]


class FakeClock:
    def __init__(self, start: float = 1_700_000_000.0, step: float = 0.25):
        self._times = itertools.count()
        self.start, self.step = start, step

    def __call__(self) -> float:
        return self.start + self.step * next(self._times)


# -- The bus alone ---------------------------------------------------------------------------

def publish_one_of_each(bus: EventBus) -> list[events.Event]:
    return [
        bus.command("c1", "MoveAbsolute", Phase.STARTED, point_name="p1"),
        bus.command("c1", "PathMove", Phase.TAG_REACHED, point_name="path", tag_name="t3",
                    tag_index=3),
        bus.command("c1", "MoveAbsolute", Phase.FAILED, point_name="p1", message="collision"),
        bus.command("c1", "MoveAbsolute", Phase.DONE, point_name="p1"),
        bus.alarm(Severity.CRITICAL, -5, "e-stop pressed", command_id="c1"),
        bus.state_change("DEVICE_STATE_MOVING", "DEVICE_STATE_PAUSED", "StopMotion"),
        bus.digital_io("c2", "rising", 1, 0b1010, 0b1110),
        bus.rsvp_request("r1", "gripper_slipping", ["part7"], ["retry", "abort"], "abort",
                         timeout_s=2.5, alarm=True),
        bus.rsvp_answer("r1", "retry", ["part7", "slow"], timed_out=False),
    ]


EXPECTED_SEED = [   # (event_id, data) of publish_one_of_each
    ("command_started", ("c1", "p1")),
    ("tag_reached", ("c1", "t3")),
    ("command_failed", ("c1", "collision")),
    ("command_done", ("c1", "p1")),
    ("alarm", ("-5", "e-stop pressed", "c1")),
    ("state_changed", ("DEVICE_STATE_MOVING", "DEVICE_STATE_PAUSED", "StopMotion")),
    ("digital_io", ("c2", "rising", "1", "10", "14")),
    ("rsvp_request", ("r1", "gripper_slipping", "part7")),
    ("rsvp_answer", ("r1", "retry", "part7", "slow")),
]


def test_events_are_numbered_from_1_stamped_by_the_clock_and_carry_the_seed_arguments():
    bus = EventBus(clock=FakeClock())
    published = publish_one_of_each(bus)
    assert seqs(published) == list(range(1, 10))
    assert [e.time for e in published] == [1_700_000_000.0 + 0.25 * i for i in range(9)]
    assert [(e.event_id, e.data) for e in published] == EXPECTED_SEED
    assert published[1].detail == events.CommandEvent("c1", "PathMove", Phase.TAG_REACHED,
                                                      "path", "t3", 3, "")
    assert published[7].detail == events.RsvpRequest("r1", True, "gripper_slipping", ("part7",),
                                                      ("retry", "abort"), "abort", 2.5)
    assert bus.last_sequence == 9


def test_a_bad_value_fails_in_the_publisher_and_is_not_numbered():
    bus = EventBus()
    with pytest.raises(ValueError):
        bus.digital_io("c", "rising", 1, 2**32, 0)
    with pytest.raises(ValueError):
        bus.command("c", "MoveAbsolute", "done")
    assert bus.last_sequence == 0


def test_a_live_subscriber_gets_what_is_published_after_it_subscribed():
    bus = EventBus()
    bus.state_change("A", "B")
    with bus.subscribe() as sub:
        bus.state_change("B", "C")
        assert seqs(drain(sub)) == [2]
        assert sub.get(timeout=0.01) is None


def test_resume_replays_the_kept_events_then_goes_live():
    bus = EventBus()
    for i in range(10):
        bus.state_change("A", "B", str(i))
    with bus.subscribe(after_sequence=4) as sub:
        bus.state_change("B", "C")
        assert seqs(drain(sub)) == list(range(5, 12))
    with bus.subscribe(after_sequence=11) as sub:       # up to date: live only
        assert drain(sub) == []


def test_resume_seam_under_a_concurrent_publisher_neither_skips_nor_repeats():
    bus = EventBus(buffer=100_000)
    total, subs = 20_000, []
    publisher = threading.Thread(target=lambda: [bus.state_change("A", "B") for _ in range(total)])
    publisher.start()
    for k in range(1, 9):   # resume from half-way back, while events keep coming
        wait_until(lambda: bus.last_sequence >= k * total // 10, "events published")
        after = bus.last_sequence // 2
        subs.append((after, bus.subscribe(after_sequence=after)))
    publisher.join(DEADLINE_S)
    for after, sub in subs:
        assert seqs(drain(sub)) == list(range(after + 1, total + 1))
        sub.close()


def test_resume_after_events_no_longer_kept_gets_events_lost_first():
    bus = EventBus(history=5)
    for _ in range(12):
        bus.state_change("A", "B")
    with bus.subscribe(after_sequence=2) as sub:
        got = drain(sub)
    assert got[0].detail == events.EventsLost(3, 7)
    assert (got[0].event_id, got[0].data, got[0].sequence) == ("events_lost", ("3", "7"), 7)
    assert seqs(got[1:]) == [8, 9, 10, 11, 12]


def test_resume_after_a_sequence_not_yet_reached_is_refused():
    bus = EventBus()
    bus.state_change("A", "B")
    with pytest.raises(events.SequenceOutOfRange):
        bus.subscribe(after_sequence=2)
    with pytest.raises(events.SequenceOutOfRange):
        bus.subscribe(after_sequence=-1)


def test_a_full_subscriber_loses_its_pending_events_and_is_told_exactly_which():
    bus = EventBus(buffer=4)
    with bus.subscribe() as stalled, bus.subscribe() as reader:
        seen = []
        for _ in range(10):
            bus.state_change("A", "B")
            seen += drain(reader)   # the reader keeps up; the stalled one reads nothing
        # 1-4 fill the buffer; 5 drops 1-4; 6, 7 fill it again; 8 drops 5-7, merged with 1-4.
        got = drain(stalled)
        assert got[0].detail == events.EventsLost(1, 7) and got[0].sequence == 7
        assert seqs(got[1:]) == [8, 9, 10]
        bus.state_change("A", "B")                 # then it continues live
        assert seqs(drain(stalled)) == [11]
        assert seqs(seen + drain(reader)) == list(range(1, 12))


def covered_sequences(evs) -> list[int]:
    """The sequences a subscriber got or was told it lost, in the order it learned of them."""
    covered = []
    for event in evs:
        if isinstance(event.detail, events.EventsLost):
            covered += range(event.detail.first_sequence, event.detail.last_sequence + 1)
        else:
            covered.append(event.sequence)
    return covered


def test_a_stalled_subscriber_never_blocks_the_publisher():
    bus = EventBus(buffer=8)
    stalled, reader = bus.subscribe(), bus.subscribe()
    total = 20_000
    publisher = threading.Thread(target=lambda: [bus.state_change("A", "B") for _ in range(total)])
    read = []

    def consume():
        for event in reader:
            read.append(event)
            if event.sequence == total:
                return

    consumer = threading.Thread(target=consume)
    consumer.start()
    publisher.start()
    publisher.join(DEADLINE_S)
    assert not publisher.is_alive()
    consumer.join(DEADLINE_S)
    # What each got, and the losses it was told of, partition 1..total exactly.
    assert covered_sequences(drain(stalled)) == list(range(1, total + 1))
    assert covered_sequences(read) == list(range(1, total + 1))


def test_closing_the_bus_ends_every_subscription():
    bus = EventBus()
    sub = bus.subscribe()
    bus.state_change("A", "B")
    ended, got = threading.Event(), []
    waiter = threading.Thread(target=lambda: (got.extend(sub), ended.set()))
    waiter.start()
    bus.close()
    waiter.join(DEADLINE_S)
    assert ended.is_set() and sub.closed and sub.get(timeout=0) is None
    assert [e.event_id for e in got] == ["state_changed"]   # what was pending still went out
    assert bus.subscriber_count == 0
    assert bus.subscribe().get(timeout=0) is None       # later ones start closed
    assert bus.state_change("A", "B").sequence == 2     # publishing still works


def test_waiting_async_readers_wake_in_the_order_they_subscribed():
    # Woken in a set's hash order instead, 50 gRPC streams cost the server's loop 10-12 us
    # more per delivery (issue 31 item 6).
    bus = EventBus()
    subscriptions = [bus.subscribe() for _ in range(40)]
    for early in subscriptions[::3]:   # some leave and come back: last in the order now
        early.close()
    subscriptions = [s for s in subscriptions if not s.closed] + [bus.subscribe()
                                                                  for _ in range(14)]

    async def readers():
        woken = []

        async def read(index, subscription):
            await subscription.next_async()
            woken.append(index)

        tasks = [asyncio.create_task(read(i, s)) for i, s in enumerate(reversed(subscriptions))]
        await asyncio.sleep(0)   # every reader waits
        await asyncio.to_thread(bus.operator_message, "hello", "test")
        await asyncio.gather(*tasks)
        return woken

    assert asyncio.run(readers()) == list(range(len(subscriptions)))[::-1]


def test_closing_a_subscription_unsubscribes_it():
    bus = EventBus()
    with bus.subscribe():
        assert bus.subscriber_count == 1
    assert bus.subscriber_count == 0


# -- EventService over gRPC ------------------------------------------------------------------

@pytest.fixture
def stub(channel):
    return event_service_pb2_grpc.EventServiceStub(channel)


def subscribe(stub, after: int | None = None):
    request = pb.SubscribeRequest() if after is None else pb.SubscribeRequest(after_sequence=after)
    return stub.Subscribe(request, timeout=60)


def read_until(stream, last_sequence: int) -> list[pb.Event]:
    out = []
    for response in stream:
        out.append(response.event)
        if response.event.sequence >= last_sequence:
            return out
    raise AssertionError(f"stream ended before sequence {last_sequence}")


def test_every_kind_of_event_survives_the_round_trip(server, stub):
    bus = server.bus
    bus.state_change("X", "Y")     # something to resume after, whatever the device published
    base = bus.last_sequence
    stream = subscribe(stub, after=base)
    published = publish_one_of_each(bus)
    by_sequence = {e.sequence: e for e in read_until(stream, published[-1].sequence)}
    stream.cancel()
    for sent in published:
        got = by_sequence[sent.sequence]
        assert (got.event_id, tuple(got.data)) == (sent.event_id, sent.data)
        assert abs(got.time.ToNanoseconds() / 1e9 - sent.time) < 1e-6
    got = [by_sequence[e.sequence] for e in published]
    assert [g.WhichOneof("detail") for g in got] == [
        "command", "command", "command", "command", "alarm", "state_change", "digital_io",
        "rsvp_request", "rsvp_answer"]
    assert got[1].command == pb.CommandEvent(
        command_id="c1", command="PathMove", phase=pb.CommandEvent.PHASE_TAG_REACHED,
        point_name="path", tag_name="t3", tag_index=3)
    assert got[2].command.phase == pb.CommandEvent.PHASE_FAILED
    assert got[2].command.message == "collision"
    assert got[4].alarm == pb.Alarm(severity=pb.ALARM_SEVERITY_CRITICAL, code=-5,
                                    message="e-stop pressed", command_id="c1")
    assert got[5].state_change == pb.StateChange(
        from_state="DEVICE_STATE_MOVING", to_state="DEVICE_STATE_PAUSED", reason="StopMotion")
    assert got[6].digital_io == pb.DigitalIOSignal(command_id="c2", type="rising", unit_id=1,
                                                   bit_string=0b1010, bits_on=0b1110)
    assert got[7].rsvp_request == pb.RsvpRequest(
        rsvp_id="r1", alarm=True, event_id="gripper_slipping", data=["part7"],
        choices=["retry", "abort"], default_choice="abort", timeout_ms=2500)
    assert got[8].rsvp_answer == pb.RsvpAnswer(rsvp_id="r1", choice="retry",
                                               data=["part7", "slow"])


def test_twenty_subscribers_see_the_same_sequence_from_two_publishers(server):
    bus, n_clients, per_publisher, burst = server.bus, 20, 500, 100
    progress = [0] * n_clients
    streams: list[list[pb.Event]] = [[] for _ in range(n_clients)]
    end_marker = "end of test"

    async def client(i: int) -> None:
        async with grpc.aio.insecure_channel(server.target) as ch:   # a connection each
            stub = event_service_pb2_grpc.EventServiceStub(ch)
            async for response in stub.Subscribe(pb.SubscribeRequest(after_sequence=0)):
                streams[i].append(response.event)      # from the first event on
                progress[i] = response.event.sequence
                if response.event.state_change.reason == end_marker:
                    return

    async def all_clients() -> None:
        await asyncio.gather(*(client(i) for i in range(n_clients)))

    published: list[list[events.Event]] = [[], []]

    def publisher(k: int) -> None:
        # Bursts well inside a subscriber's buffer, then let the slowest client catch up:
        # the test is about order and completeness, not about outrunning Python clients.
        for start in range(0, per_publisher, burst):
            for i in range(start, start + burst):
                published[k].append(bus.command(f"p{k}-{i}", "MoveAbsolute", Phase.DONE, "pt"))
            last = published[k][-1].sequence
            wait_until(lambda: min(progress) >= last, "every client caught up")

    # The clients share one asyncio thread: far cheaper than 20 threads in this process.
    clients = threading.Thread(target=asyncio.run, args=(all_clients(),))
    publishers = [threading.Thread(target=publisher, args=(k,)) for k in range(2)]
    for t in [clients, *publishers]:   # clients subscribe while the publishers run
        t.start()
    for t in publishers:
        t.join(DEADLINE_S)
    end = bus.state_change("S", "S", end_marker)
    clients.join(DEADLINE_S)

    reference = [(e.sequence, e.event_id, tuple(e.data)) for e in streams[0]]
    assert [r[0] for r in reference] == list(range(1, end.sequence + 1))   # in order, no gaps
    for stream in streams[1:]:
        assert [(e.sequence, e.event_id, tuple(e.data)) for e in stream] == reference
    by_sequence = {r[0]: r for r in reference}
    for events_of_one_publisher in published:
        assert len(events_of_one_publisher) == per_publisher
        for e in events_of_one_publisher:
            assert by_sequence[e.sequence] == (e.sequence, e.event_id, e.data)
    assert not any(e.WhichOneof("detail") == "events_lost" for s in streams for e in s)


def test_resume_over_grpc_gives_exactly_the_missed_events_then_live_ones(server, stub):
    bus = server.bus
    before = bus.subscriber_count
    first = [bus.state_change("A", "B", str(i)) for i in range(10)]
    stream = subscribe(stub, after=first[4].sequence)
    wait_until(lambda: bus.subscriber_count == before + 1, "subscribed")
    later = [bus.state_change("B", "C", str(i)) for i in range(5)]
    got = read_until(stream, later[-1].sequence)
    stream.cancel()
    assert [e.sequence for e in got] == list(range(first[5].sequence, later[-1].sequence + 1))
    mine = {e.sequence for e in first[5:] + later}
    assert [(e.sequence, e.state_change.reason) for e in got if e.sequence in mine] == \
           [(e.sequence, e.detail.reason) for e in first[5:] + later]


def test_resume_over_grpc_after_events_no_longer_kept_starts_with_events_lost(server, stub):
    bus = server.bus
    for _ in range(bus.history_size + 50):
        bus.state_change("A", "B")
    oldest_kept = bus.last_sequence - bus.history_size + 1
    stream = subscribe(stub, after=0)
    lost, first_kept = next(stream).event, next(stream).event
    stream.cancel()
    assert lost.WhichOneof("detail") == "events_lost"
    assert (lost.events_lost.first_sequence, lost.events_lost.last_sequence) == \
           (1, oldest_kept - 1)
    assert first_kept.sequence == oldest_kept


def test_resume_after_a_sequence_the_device_never_reached_is_out_of_range(server, stub):
    with pytest.raises(grpc.RpcError) as err:
        next(subscribe(stub, after=server.bus.last_sequence + 1_000))
    assert err.value.code() == grpc.StatusCode.OUT_OF_RANGE


def test_a_client_that_stops_reading_loses_events_but_slows_nobody(server):
    bus, total = server.bus, 2_000
    # A small HTTP/2 window (no BDP growth), so the stalled client backs up to the server
    # soon and the bus buffer, not the transport, takes the excess.
    stalled_ch = grpc.insecure_channel(server.target, options=[("grpc.http2.bdp_probe", 0)])
    healthy_ch = grpc.insecure_channel(server.target)
    before = bus.subscriber_count
    start = bus.last_sequence
    stalled = subscribe(event_service_pb2_grpc.EventServiceStub(stalled_ch), after=start)
    healthy = [subscribe(event_service_pb2_grpc.EventServiceStub(healthy_ch), after=start)
               for _ in range(2)]
    wait_until(lambda: bus.subscriber_count == before + 3, "all subscribed")
    progress = [start] * len(healthy)
    received: list[list[int]] = [[] for _ in healthy]

    def read(i: int) -> None:
        for response in healthy[i]:
            received[i].append(response.event.sequence)
            progress[i] = response.event.sequence
            if response.event.state_change.reason == "end of test":
                return

    readers = [threading.Thread(target=read, args=(i,)) for i in range(len(healthy))]
    for t in readers:
        t.start()
    padding = "x" * 1_000    # big events fill the stalled client's window quickly
    for i in range(total):
        event = bus.alarm(Severity.INFO, 1, padding, command_id=str(i))
        if i % 100 == 99:    # paced to the healthy readers, never to the stalled one
            wait_until(lambda: min(progress) >= event.sequence, "healthy readers caught up")
    last = bus.state_change("S", "S", "end of test").sequence
    for t in readers:
        t.join(DEADLINE_S)
    for got in received:       # the healthy ones get everything, in order
        assert got == list(range(start + 1, last + 1))

    got = read_until(stalled, last)
    covered = []
    for event in got:
        if event.WhichOneof("detail") == "events_lost":
            covered += range(event.events_lost.first_sequence, event.events_lost.last_sequence + 1)
        else:
            covered.append(event.sequence)
    assert any(e.WhichOneof("detail") == "events_lost" for e in got)
    assert covered == list(range(start + 1, last + 1))   # told exactly what it lost
    stalled_ch.close()
    healthy_ch.close()


def test_closing_the_channel_ends_the_server_side_subscription(server):
    bus = server.bus
    before = bus.subscriber_count
    ch = grpc.insecure_channel(server.target)
    stream = subscribe(event_service_pb2_grpc.EventServiceStub(ch))
    wait_until(lambda: bus.subscriber_count == before + 1, "subscribed")
    ch.close()
    wait_until(lambda: bus.subscriber_count == before, "the subscription ended")
    with pytest.raises(grpc.RpcError):
        next(stream)


def test_cancelling_the_call_ends_the_server_side_subscription(server, stub):
    bus = server.bus
    before = bus.subscriber_count
    stream = subscribe(stub)
    wait_until(lambda: bus.subscriber_count == before + 1, "subscribed")
    stream.cancel()
    wait_until(lambda: bus.subscriber_count == before, "the subscription ended")


def test_closing_the_bus_ends_the_streams_cleanly(server, stub):
    before = server.bus.subscriber_count
    stream = subscribe(stub)
    wait_until(lambda: server.bus.subscriber_count == before + 1, "subscribed")
    server.bus.close()
    assert list(stream) == []          # ends with OK, no error
    assert stream.code() == grpc.StatusCode.OK


def test_the_lock_holder_posts_a_message_every_subscriber_sees(server):
    from support import locked_session, stubs
    holder = locked_session(server, "operator-console")
    try:
        _, _, events = stubs(holder.channel)
        stream = events.Subscribe(pb.SubscribeRequest(), timeout=10)
        reply = events.PostMessage(pb.PostMessageRequest(text="part 7 is cracked"), timeout=5)
        event = next(r.event for r in stream if r.event.HasField("operator_message"))
        stream.cancel()
        assert event.sequence == reply.sequence
        assert (event.operator_message.text, event.operator_message.source) == (
            "part 7 is cracked", "operator-console")
        with grpc.insecure_channel(server.target) as channel:   # without the lease: refused
            with pytest.raises(grpc.RpcError) as refused:
                stubs(channel)[2].PostMessage(pb.PostMessageRequest(text="spam"), timeout=5)
            assert refused.value.code() is grpc.StatusCode.PERMISSION_DENIED
    finally:
        holder.close()


def test_a_subscriber_learns_it_is_subscribed_before_any_event(server, stub):
    """The headers come once the subscription is in place, so a client can wait for them (as
    grpc's wait_for_connection does) before it acts, even on a device where nothing happens."""
    stream = subscribe(stub)
    done = threading.Event()
    threading.Thread(target=lambda: (stream.initial_metadata(), done.set()), daemon=True).start()
    assert done.wait(10), "no headers while no event was published"
    assert server.bus.subscriber_count >= 1
    stream.cancel()
