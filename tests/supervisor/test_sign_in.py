"""The pure parts of signing in: sign-ins and their ends (on a clock the test moves), and the
origins the supervisor calls its own."""
from __future__ import annotations

import pytest

from landscape.server.security.auth import Role, TokenStore
from landscape.supervisor.origins import OriginPolicy, normalize, own_origins
from landscape.supervisor.sign_in import SignInRefused, SignIns


class Clock:
    def __init__(self):
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


def sign_ins(people, clock, forward=False) -> SignIns:
    return SignIns(TokenStore.load(people.folder), forward_tokens=forward, idle_s=60.0,
                   max_age_s=600.0, clock=clock)


def test_a_token_of_the_folder_signs_its_person_in_under_a_fresh_random_id(people):
    clock = Clock()
    registry = sign_ins(people, clock)
    first = registry.sign_in(people.token("olga"), "127.0.0.1")
    second = registry.sign_in(people.token("olga"), "127.0.0.1")
    assert (first.name, first.role) == ("olga", Role.OPERATOR)
    assert first.id != second.id and len(first.id) >= 43   # 256 bits, URL-safe base64
    assert first.token is None                             # not forwarded: not kept
    assert sign_ins(people, clock, forward=True).sign_in(people.token("vera"), "x").token \
        == people.token("vera")
    assert registry.find(first.id) is first and registry.find("forged") is None


def test_an_unknown_token_is_refused_without_repeating_it(people):
    with pytest.raises(SignInRefused) as refused:
        sign_ins(people, Clock()).sign_in("not-a-token-of-the-folder-0123", "10.0.0.9")
    assert "not-a-token" not in str(refused.value)


def test_a_sign_in_ends_when_idle_with_no_page_open_and_at_its_maximum_age(people):
    clock = Clock()
    registry = sign_ins(people, clock)
    idle = registry.sign_in(people.token("olga"), "p")
    watching = registry.sign_in(people.token("vera"), "p")
    registry.page_opened(watching)
    clock.now += 61
    assert registry.find(idle.id) is None and idle.ended.is_set()
    assert "idle for 1 min" in idle.why_ended
    assert registry.find(watching.id) is watching          # an open page keeps it
    clock.now += 540
    registry.sweep()
    assert watching.ended.is_set() and "after 10 min" in watching.why_ended


def test_signing_out_ends_the_sign_in_and_tells_its_pages(people):
    registry = sign_ins(people, Clock())
    record = registry.sign_in(people.token("ada"), "p")
    registry.sign_out(record)
    assert record.ended.is_set() and record.why_ended == "signed out"
    assert registry.find(record.id) is None


@pytest.mark.parametrize("text, origin", [
    ("HTTP://LocalHost:8080", "http://localhost:8080"), ("https://panel.lan:443/", "https://panel.lan"),
    ("http://[::1]:80", "http://[::1]"), ("http://10.0.0.2:8080", "http://10.0.0.2:8080")])
def test_origins_are_compared_as_browsers_write_them(text, origin):
    assert normalize(text) == origin


@pytest.mark.parametrize("text", ["panel.lan", "ftp://panel.lan", "http://panel.lan/page",
                                  "http://user@panel.lan", "http://panel.lan:99999", "null"])
def test_what_is_not_an_origin_is_refused(text):
    with pytest.raises(ValueError, match="an origin is"):
        normalize(text)


def test_its_own_origin_is_where_it_serves_and_on_loopback_every_loopback_name():
    assert set(own_origins("127.0.0.1", 8080)) == {
        "http://127.0.0.1:8080", "http://localhost:8080", "http://[::1]:8080"}
    assert own_origins("cell1.lan", 8080) == ("http://cell1.lan:8080",)
    policy = OriginPolicy(own_origins("127.0.0.1", 8080), ("https://panel.lan",))
    assert policy.allows("http://localhost:8080") and policy.allows("https://panel.lan")
    assert not policy.allows("http://127.0.0.1:9999") and not policy.allows("null")
