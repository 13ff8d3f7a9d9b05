"""Issue 29: `make run` starts the bridges the cell file turns on. A launched cell with the
Foxglove bridge and the OPC UA server on, and /metrics of every service: each answers its
own protocol's client, and the cell stops cleanly."""
from __future__ import annotations

import asyncio
import re
import signal
import sys
import urllib.request
from pathlib import Path

import pytest
from asyncua import Client
from prometheus_client.parser import text_string_to_metric_families

from test_launcher import _device, launch  # noqa: F401 (the launcher's fixture)

sys.path.insert(0, str(Path(__file__).parents[1] / "bridges"))
from foxglove_client import FoxgloveClient  # noqa: E402

KINDS = r"(device server|CRCL gateway|web supervisor|Foxglove bridge|OPC UA server)"
SUMMARY = re.compile(r"\|\s+(\S+)\s+" + KINDS + r"\s+(\S+).*\(pid (\d+)\)")
METRICS = re.compile(r"^(\S+)\s+\|.*metrics(?::| on) (http://\S+/metrics)")


@pytest.mark.slow   # a cell of processes
def test_make_run_starts_the_bridges_the_cell_file_turns_on(launch):  # noqa: F811
    cell = launch(_device("arm1") + "[gateway]\nport = 0\n[supervisor]\nport = 0\n"
                  "[metrics]\nport = 0\n[foxglove]\nenabled = true\nport = 0\n"
                  "[opcua]\nenabled = true\nport = 0\n")
    cell.wait_for(r"is up; Ctrl-C stops it")
    cell.wait_for(r"OPC UA server")   # the summary's lines follow its first, the last is this
    services = {}
    for line in cell.output:
        match = SUMMARY.search(line)
        if match:
            services[match[1]] = (match[2], match[3])
    assert services["foxglove"][0] == "Foxglove bridge", cell.text()
    assert services["opcua"][0] == "OPC UA server", cell.text()

    scrapes = {}
    for line in cell.output:
        match = METRICS.search(line)
        if match:
            text = urllib.request.urlopen(match[2], timeout=10).read().decode()
            scrapes[match[1]] = {f.name for f in text_string_to_metric_families(text)}
    assert {"arm1", "gateway", "supervisor"} <= set(scrapes), cell.text()
    assert "landscape_device_state" in scrapes["arm1"]
    assert "landscape_crcl_connections" in scrapes["gateway"]
    assert all("process_resident_memory_bytes" in names for names in scrapes.values())

    fox = FoxgloveClient(int(services["foxglove"][1].rsplit(":", 1)[1]))
    try:
        sub = fox.subscribe("/arm1/tf")
        _, transforms = next(fox.messages(sub))
        assert len(transforms.transforms) == 7
    finally:
        fox.close()

    async def browse():
        async with Client(services["opcua"][1]) as client:
            index = await client.get_namespace_index("http://opcfoundation.org/UA/Robotics/")
            return index > 0
    assert asyncio.run(browse())

    cell.process.send_signal(signal.SIGTERM)
    assert cell.finish() == 0, cell.text()
    for name in ("foxglove", "opcua"):
        assert f"cell       | {name} stopped (exit code 0)" in cell.output, cell.text()
