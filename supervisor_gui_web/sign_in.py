"""Who is signed in to the web supervisor.

A person signs in with a role token from a token folder in the format `landscape-cell
tokens` writes and the device servers read (viewer.tokens, operator.tokens, admin.tokens;
`<token> [name]` a line; server/auth.py's TokenStore reads it here too). The backend checks
the token, then keeps a sign-in under a random 256-bit id, which the browser holds in an
HttpOnly cookie (http_guard.py); the page never holds the token. The token itself is kept
only when it must be forwarded to devices that use tokens.

A sign-in ends when its person signs out, when it was idle for `idle_s` (no request and no
page of theirs open: an open page keeps it), or `max_age_s` after it began, whatever the
person does. Its `ended` event tells the pages still open, which then close.
"""
from __future__ import annotations

import asyncio
import logging
import secrets
import time
from dataclasses import dataclass, field

from landscape.server.security.auth import Identity, Role, TokenStore, Unauthenticated

log = logging.getLogger(__name__)

DEFAULT_IDLE_S = 30 * 60.0
DEFAULT_MAX_AGE_S = 12 * 3600.0
MAX_SIGN_INS = 256        # open sign-ins at once; only a holder of a valid token adds one
FAILURE_LOG_PERIOD_S = 60.0


class SignInRefused(Exception):
    """The token is not one of the folder's (or the supervisor is full); the message says
    which, and never repeats the token."""


@dataclass
class SignIn:
    id: str                       # 256 random bits, URL-safe: the cookie's value
    name: str                     # the token's name in its file: who the devices see
    role: Role
    token: str | None             # kept only when forwarded to the devices
    began: float                  # time.monotonic()
    last_seen: float
    pages: int = 0                # WebSockets of this sign-in open now
    ended: asyncio.Event = field(default_factory=asyncio.Event)
    why_ended: str = ""

    @property
    def role_label(self) -> str:
        return self.role.label


class SignIns:
    """The sign-ins of one supervisor. `clock` is time.monotonic (a test may pass its own)."""

    def __init__(self, tokens: TokenStore, *, forward_tokens: bool,
                 idle_s: float = DEFAULT_IDLE_S, max_age_s: float = DEFAULT_MAX_AGE_S,
                 clock=time.monotonic):
        if idle_s <= 0 or max_age_s <= 0:
            raise ValueError("sign-in idle and maximum times are positive seconds")
        self._tokens = tokens
        self._forward = forward_tokens
        self.idle_s, self.max_age_s = idle_s, max_age_s
        self._clock = clock
        self._open: dict[str, SignIn] = {}
        self._failures = _FailureLog()

    def sign_in(self, token: str, peer: str) -> SignIn:
        """A new sign-in for `token`; SignInRefused if the folder does not hold it."""
        try:
            identity: Identity = self._tokens.identify([("authorization", f"Bearer {token}")])
        except Unauthenticated:
            self._failures.add(peer)
            raise SignInRefused("this token is not one of the supervisor's: sign in with a "
                                "token from viewer.tokens, operator.tokens or admin.tokens")
        self.sweep()
        if len(self._open) >= MAX_SIGN_INS:
            raise SignInRefused(f"{MAX_SIGN_INS} sign-ins are open: sign out elsewhere first")
        now = self._clock()
        record = SignIn(secrets.token_urlsafe(32), identity.name, identity.role,
                        token if self._forward else None, now, now)
        self._open[record.id] = record
        log.info("%s signed in (%s) from %s", loggable(identity.name), identity.role.label,
                 peer)
        return record

    def find(self, sign_in_id: str | None) -> SignIn | None:
        """The live sign-in of a cookie's value (its use noted), or None."""
        record = self._open.get(sign_in_id or "")
        if record is None:
            return None
        why = self._expired(record, self._clock())
        if why:
            self._end(record, why)
            return None
        self.touch(record)
        return record

    def touch(self, record: SignIn) -> None:
        """The person did something (a request, a frame from their page)."""
        record.last_seen = self._clock()

    def by_role(self) -> dict[str, int]:
        """People signed in now, by role label (read by /metrics from another thread)."""
        counts: dict[str, int] = {}
        for record in list(self._open.values()):
            counts[record.role_label] = counts.get(record.role_label, 0) + 1
        return counts

    def pages(self) -> int:
        """Pages open now, over every sign-in."""
        return sum(record.pages for record in list(self._open.values()))

    def sign_out(self, record: SignIn) -> None:
        self._end(record, "signed out")

    def page_opened(self, record: SignIn) -> None:
        record.pages += 1

    def page_closed(self, record: SignIn) -> None:
        record.pages -= 1
        self.touch(record)

    def sweep(self) -> None:
        """Ends every expired sign-in (their open pages are told through `ended`)."""
        now = self._clock()
        for record in list(self._open.values()):
            why = self._expired(record, now)
            if why:
                self._end(record, why)

    def _expired(self, record: SignIn, now: float) -> str:
        if now - record.began >= self.max_age_s:
            return f"the sign-in ended after {_duration(self.max_age_s)}: sign in again"
        if record.pages == 0 and now - record.last_seen >= self.idle_s:
            return f"the sign-in was idle for {_duration(self.idle_s)}: sign in again"
        return ""

    def _end(self, record: SignIn, why: str) -> None:
        if self._open.pop(record.id, None) is None:
            return
        record.why_ended = why
        record.ended.set()
        log.info("%s (%s): %s", loggable(record.name), record.role.label, why)


def _duration(seconds: float) -> str:
    for unit, size in (("h", 3600), ("min", 60)):
        if seconds >= size:
            return f"{seconds / size:.3g} {unit}"
    return f"{seconds:.3g} s"


def loggable(text: str) -> str:
    """`text` with control characters and anything beyond ASCII escaped: no name can forge
    a log line or move the terminal's cursor."""
    return text.encode("unicode_escape").decode("ascii")


class _FailureLog:
    """Refused sign-ins, one log line per peer per period with the count, not one per try."""

    def __init__(self, period_s: float = FAILURE_LOG_PERIOD_S, clock=time.monotonic):
        self._period, self._clock = period_s, clock
        self._peers: dict[str, tuple[float, int]] = {}   # peer -> (line written at, since)

    def add(self, peer: str) -> None:
        now = self._clock()
        for known, (written, count) in list(self._peers.items()):
            if now - written >= self._period:
                del self._peers[known]
                if count:
                    log.warning("refused %d more sign-ins from %s", count, known)
        if peer in self._peers:
            written, count = self._peers[peer]
            self._peers[peer] = (written, count + 1)
            return
        self._peers[peer] = (now, 0)
        log.warning("refused a sign-in from %s: unknown token (further refusals from it are "
                    "counted, not logged, for %g s)", peer, self._period)
