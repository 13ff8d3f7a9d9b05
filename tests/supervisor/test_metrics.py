"""The web supervisor's /metrics (`--metrics-port`): beside its process figures, the people
signed in by role, the pages they have open, and whether each device answers it; a scrape,
parsed with prometheus-client's parser, follows a sign-in, a page and a device out of reach."""
from __future__ import annotations

import asyncio
import math
import socket
import urllib.request

from prometheus_client.parser import text_string_to_metric_families

from dashboard_support import SpawnedDashboard, open_page
from support import wait_until


def scrape(url: str) -> dict[tuple[str, tuple], float]:
    text = urllib.request.urlopen(url, timeout=10).read().decode()
    return {(s.name, tuple(sorted(s.labels.items()))): s.value
            for family in text_string_to_metric_families(text) for s in family.samples}


def test_a_scrape_counts_the_people_their_pages_and_the_devices_that_answer(cell_server,
                                                                            people):
    with socket.socket() as probe:   # a port nothing listens on
        probe.bind(("127.0.0.1", 0))
        nowhere = f"127.0.0.1:{probe.getsockname()[1]}"
    running = SpawnedDashboard({"arm1": cell_server.target, "arm2": nowhere}, people,
                               "--metrics-port", "0")
    try:
        url = running.process.stdout.readline().split()[-1]
        assert url.endswith("/metrics"), url
        first = scrape(url)
        assert first[("process_resident_memory_bytes", ())] > 0
        assert first.get(("landscape_supervisor_pages", ())) == 0
        answering = lambda: scrape(url).get(
            ("landscape_supervisor_device_answering", (("device", "arm1"),)), math.nan)
        wait_until(lambda: answering() == 1.0, timeout=30)
        assert scrape(url)[("landscape_supervisor_device_answering",
                            (("device", "arm2"),))] == 0.0

        async def with_a_page() -> dict:
            http, ws = await open_page(running.url, people.token("olga"))
            async with http, ws:   # counted once the supervisor has taken the socket
                await asyncio.to_thread(wait_until, lambda: scrape(url).get(
                    ("landscape_supervisor_pages", ())) == 1, 10)
                return await asyncio.to_thread(scrape, url)
        seen = asyncio.run(with_a_page())
        assert seen[("landscape_supervisor_sign_ins", (("role", "operator"),))] == 1
        assert seen[("landscape_supervisor_pages", ())] == 1
        wait_until(lambda: scrape(url)[("landscape_supervisor_pages", ())] == 0, timeout=10)
    finally:
        assert running.stop() == 0
