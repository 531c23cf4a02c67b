"""The HIL bench touches nothing it was not asked to: --bus udp_multicast keeps its frames on the host by
socket options (joined and sent on the loopback interface, TTL 0), never through the routing table; the
explicit --multicast route adds only the bench group's /32 and undoes it at exit, also after SIGTERM.

The root checks run in a fresh network namespace set up like a lab PC (loopback without the multicast
flag, a NIC with the default route and no multicast route): the runs leave `ip route` and `ip link`
exactly as they were, and no frame leaves through the NIC.
"""
from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import sys
import textwrap

import pytest

from tests.support import ROOT


def test_host_only_bus_keeps_its_frames_on_the_loopback_interface():
    import can

    from reeve_fmu.hil.buses import make_bus

    a = make_bus("udp_multicast", port=44871)
    b = make_bus("udp_multicast", port=44871)
    try:
        s = a._multicast._socket
        assert socket.inet_ntoa(s.getsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, 4)) == "127.0.0.1"
        assert s.getsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL) == 0
        assert s.getsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP) == 1
        a.send(can.Message(arbitration_id=0x123, data=b"\x01\x02", is_extended_id=False))
        m = b.recv(2.0)
        assert m is not None and m.arbitration_id == 0x123 and bytes(m.data) == b"\x01\x02"
    finally:
        a.shutdown()
        b.shutdown()
    with pytest.raises(ValueError, match="--multicast 'wan'"):
        make_bus("udp_multicast", multicast="wan")


NETNS_SCRIPT = r'''
import json, os, signal, subprocess, sys, time

def ip(*a):
    return subprocess.run(["ip", *a], capture_output=True, text=True, check=True).stdout

# a lab PC: lo up without the multicast flag, a NIC with the default route, no multicast route
ip("link", "set", "lo", "up")
ip("link", "add", "nic0", "type", "veth", "peer", "name", "nic1")
ip("addr", "add", "10.9.0.2/24", "dev", "nic0")
ip("link", "set", "nic0", "up")
ip("link", "set", "nic1", "up")
ip("route", "add", "default", "via", "10.9.0.1")

def snapshot():
    return {{"route": ip("route", "show", "table", "all"), "link": ip("link")}}

import socket
# every frame of nic0 (outgoing frames reach ETH_P_ALL taps only), IPv4 ones counted below
cap = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(0x0003))
cap.bind(("nic0", 0))
cap.setblocking(False)

def nic_tx():
    """IPv4 packets (UDP, IGMP, ...) sent through nic0 since the last call (the kernel's own IPv6 router
    solicitations are not the bench's)."""
    time.sleep(0.5)                  # let the capture see what was just sent
    n = 0
    while True:
        try:
            frame, addr = cap.recvfrom(65536)
        except BlockingIOError:
            return n
        n += addr[2] == socket.PACKET_OUTGOING and frame[12:14] == b"\x08\x00"

from reeve_fmu.hil.buses import bench_route
from reeve_fmu.hil.runners import HilConfig, run_hil

def settled():
    """The snapshot once the kernel's own IPv6 autoconfiguration of the new links is done."""
    a = snapshot()
    for _ in range(30):
        time.sleep(1.0)
        b = snapshot()
        if a == b and "tentative" not in ip("-6", "addr"):
            return b
        a = b
    return a

out = {{"before": settled()}}
nic_tx()
cfg = HilConfig(bus="udp_multicast", plant="in-process", t_end=0.3, out=None, compare=False, record=False)
s = run_hil(cfg, log=None)
out["host"] = {{"after": snapshot(), "tx": nic_tx(), "steps": s["steps"],
               "controller": s["controller_stats"]["stopped"]}}
from reeve_fmu.hil.buses import multicast_probe
multicast_probe(multicast="lan")          # the control: python-can's own sockets use the default route
out["lan_tx"] = nic_tx()
lines = []
s = run_hil(HilConfig(**{{**cfg.__dict__, "multicast": "route"}}), log=lines.append)
out["route"] = {{"after": snapshot(), "console": lines, "steps": s["steps"]}}
# SIGTERM while the route is set: the finally block still removes it
pid = os.fork()
if pid == 0:
    with bench_route(log=lambda m: None):
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(5)
    os._exit(0)
_, status = os.waitpid(pid, 0)
out["sigterm"] = {{"after": snapshot(), "exit": os.waitstatus_to_exitcode(status)}}
print("JSON" + json.dumps(out))
'''


@pytest.fixture(scope="module")
def netns_run(tmp_path_factory):
    if not (hasattr(os, "geteuid") and os.geteuid() == 0 and shutil.which("unshare") and shutil.which("ip")):
        pytest.skip("needs root, unshare and ip (a fresh network namespace)")
    script = tmp_path_factory.mktemp("netns") / "bench_netns.py"
    script.write_text(NETNS_SCRIPT.format(), encoding="utf-8")
    p = subprocess.run(["unshare", "-n", sys.executable, str(script)], capture_output=True, text=True, timeout=900,
                       cwd=ROOT, env=dict(os.environ, PYTHONPATH=str(ROOT)))
    line = next((ln for ln in p.stdout.splitlines() if ln.startswith("JSON")), None)
    if line is None and "Operation not permitted" in p.stderr:
        pytest.skip(f"no network namespace here: {p.stderr[-300:]}")
    assert line is not None, p.stdout[-3000:] + p.stderr[-3000:]
    return json.loads(line[4:])


def test_a_udp_multicast_run_as_root_changes_no_route_and_no_link(netns_run):
    r = netns_run
    assert r["host"]["steps"] == 300 and r["host"]["controller"] == "done"     # the run really exchanged frames
    assert r["host"]["after"] == r["before"]                     # ip route (all tables) and ip link: identical
    assert r["host"]["tx"] == 0                          # no IPv4 packet (frame, IGMP join) left through the NIC
    assert r["lan_tx"] > 0                               # ... as python-can's own sockets (--multicast lan) do


def test_the_route_option_adds_only_the_bench_group_says_so_and_undoes_it(netns_run):
    r = netns_run
    assert r["route"]["steps"] == 300
    assert r["route"]["console"] == ["network: ip link set lo multicast on (undone at exit)",
                                     "network: ip route add 239.74.163.2/32 dev lo (undone at exit)",
                                     "network: ip route del 239.74.163.2/32 dev lo",
                                     "network: ip link set lo multicast off"]
    assert r["route"]["after"] == r["before"]
    assert r["sigterm"]["exit"] == 128 + 15 and r["sigterm"]["after"] == r["before"]
