"""Issue 28 item 2, the alarm list, in Debian's headless Chromium on the real backend and real
device servers: each arm's alarms with who acknowledged them (the device's record, its
AlarmAcknowledged events, shown to everyone signed in and to any other client), their count in the status bar, and the device's questions answered
from the list. On a cell of one arm and of two. Screenshots go to var/screenshots."""
from __future__ import annotations

import grpc

from dashboard_support import Page
from landscape.server.device.states import State
from landscape.v1 import event_service_pb2, event_service_pb2_grpc
from support import wait_until

ESTOP_ALARM = "#alarms li.alarm", "e-stop pressed: motion stopped, drives off"


def _estop_alarm(page: Page):
    return page.page.locator(ESTOP_ALARM[0], has_text=ESTOP_ALARM[1]).first


def _acknowledgements(target: str) -> list:
    """The AlarmAcknowledged events the device keeps, as any other client reads them."""
    found = []
    with grpc.insecure_channel(target) as channel:
        call = event_service_pb2_grpc.EventServiceStub(channel).Subscribe(
            event_service_pb2.SubscribeRequest(after_sequence=0), timeout=2)
        try:
            for reply in call:   # the kept events, then live ones until the deadline
                if reply.event.HasField("alarm_acknowledged"):
                    found.append(reply.event.alarm_acknowledged)
        except grpc.RpcError as error:
            if error.code() is not grpc.StatusCode.DEADLINE_EXCEEDED:
                raise
    return found


def test_alarms_are_acknowledged_for_everyone_and_questions_answered_from_the_list(
        chromium, dashboard, cell_server):
    olga = Page(chromium, dashboard)
    vera = Page(chromium, dashboard, name="vera")           # a viewer watches
    olga.take_control()
    olga.click("estop-arm1")
    olga.shows("st-state", "error")
    for page in (olga, vera):
        page.expect(_estop_alarm(page)).to_contain_text("critical 102")
        page.expect(page.status("alarms")).to_have_class("st-alarms alert")
    assert _estop_alarm(vera).locator("button").is_disabled()   # acknowledging is an operator's
    before = olga.status("alarms").inner_text()
    _estop_alarm(olga).locator("button", has_text="Acknowledge").click()
    for page in (olga, vera):
        page.expect(_estop_alarm(page)).to_contain_text("acknowledged by olga")
        page.expect(page.status("alarms")).not_to_have_text(before)
    acks = _acknowledgements(cell_server.target)   # the device's, for every client
    assert [(a.client, a.on_behalf_of) for a in acks] == [("supervisor", "olga")]
    olga.screenshot("alarms-acknowledged")
    # The device asks the lock holder whether to reset: put aside, then answered in the list.
    olga.click("btn-estop-release")
    dialog = olga.page.locator("#rsvp")
    olga.expect(dialog).to_be_visible()
    olga.page.keyboard.press("Escape")
    olga.expect(dialog).to_be_hidden()
    question = olga.page.locator("#alarms li", has_text="reset now?")
    question.locator("button[data-choice='reset']").click()
    olga.expect(question).to_contain_text("answered “reset”")
    vera.expect(vera.page.locator("#alarms li", has_text="reset now?")).to_contain_text("answered “reset”")
    wait_until(lambda: cell_server.device.state is State.INACTIVE, timeout=15)
    # Acknowledge all: nothing left to acknowledge, on both pages.
    olga.click("btn-ack-all")
    for page in (olga, vera):
        page.expect(page.status("alarms")).to_have_text("0 alarms")
    vera.close()
    olga.close()


def test_each_arm_keeps_its_own_alarms(chromium, two_arm_dashboard, two_arm_servers):
    page = Page(chromium, two_arm_dashboard)
    page.click("estop-arm2")
    page.expect(page.status("alarms", "arm2")).to_have_text("1 alarm")
    page.expect(page.status("alarms", "arm1")).to_have_text("0 alarms")
    page.expect(page.page.locator("#alarms li")).to_have_count(0)     # arm1's list
    page.status("alarms", "arm2").click()                               # arm2's, from its row
    page.shows("panels-device", "arm2")
    page.expect(_estop_alarm(page)).to_be_visible()
    page.expect(page.page.locator("#panel-alarms")).to_be_in_viewport()
    wait_until(lambda: two_arm_servers[1].device.state is State.ERROR, timeout=10)
    assert two_arm_servers[0].device.state is State.UNLOCKED
    page.close()
