"""Bus construction, the udp_multicast probe and `--multicast route`.

`FastVirtualBus` is python-can's `virtual` interface with a cheaper send(). python-can's
VirtualBus.send() deep-copies every frame for every receiver, most of what one send + recv costs; a
1 kHz lock-step loop moves 4-5 frames per cycle, so that copy alone would eat much of the cycle budget
of the 2000 steps/s target (docs/performance.md, "HIL"). FastVirtualBus copies
the frame by constructing a new `can.Message` (fields are scalars and a bytearray) and is otherwise
the same class: it joins the same process-wide channel registry, so plain `can.Bus(interface="virtual")`
instances (e.g. a canopen Network) on the same channel exchange frames with it.
"""
from __future__ import annotations

import contextlib
import os
import queue
import random
import shutil
import socket
import subprocess
import threading
import time

import can
from can.interfaces.udp_multicast import bus as _udp
from can.interfaces.virtual import VirtualBus


class FastVirtualBus(VirtualBus):
    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        try:
            chan = self.channel
            own = self.queue
            own_too = self.receive_own_messages
            preserve = self.preserve_timestamps
            cid = self.channel_id
            self._check_if_open()
        except AttributeError:                 # python-can internals changed: fall back to the original
            return super().send(msg, timeout)
        ts = msg.timestamp if preserve else time.time()
        data = bytes(msg.data)
        all_sent = True
        for q in chan:
            if q is own and not own_too:
                continue
            m = can.Message(timestamp=ts, arbitration_id=msg.arbitration_id, is_extended_id=msg.is_extended_id,
                            is_remote_frame=msg.is_remote_frame, is_error_frame=msg.is_error_frame,
                            channel=cid, dlc=msg.dlc, data=data, is_fd=msg.is_fd, is_rx=q is not own,
                            bitrate_switch=msg.bitrate_switch, error_state_indicator=msg.error_state_indicator,
                            check=False)
            try:
                q.put(m, block=True, timeout=timeout)
            except queue.Full:
                all_sent = False
        if not all_sent:
            raise can.CanOperationError("Could not send message to one or more recipients")

    def send_batch(self, msgs, reuse: bool = False) -> None:
        """Send frames back to back with one wake-up per receiver (a receiving thread is woken once per
        cycle instead of once per frame: each wake-up costs a GIL hand-over, long under load).
        reuse=True: the caller gives up the Message objects, the last receiver gets them without a copy."""
        try:
            chan = self.channel
            own = self.queue
            own_too = self.receive_own_messages
            cid = self.channel_id
            self._check_if_open()
        except AttributeError:
            for m in msgs:
                self.send(m)
            return
        ts = time.time()
        targets = [q for q in chan if q is not own or own_too]
        for i, q in enumerate(targets):
            rx = q is not own
            if reuse and i == len(targets) - 1:
                frames = msgs
                for m in frames:
                    m.timestamp, m.channel, m.is_rx = ts, cid, rx
            else:
                frames = [can.Message(timestamp=ts, arbitration_id=m.arbitration_id, is_extended_id=m.is_extended_id,
                                      is_remote_frame=m.is_remote_frame, is_error_frame=m.is_error_frame,
                                      channel=cid, dlc=m.dlc, data=bytes(m.data), is_rx=rx, check=False)
                          for m in msgs]
            if q.maxsize > 0:                      # bounded queue: keep the blocking semantics
                for m in frames:
                    q.put(m)
                continue
            with q.not_empty:                      # queue.Queue's own condition (stdlib API)
                q.queue.extend(frames)
                q.unfinished_tasks += len(frames)
                q.not_empty.notify()


def send_batch(bus, msgs, reuse: bool = False) -> None:
    """bus.send_batch(msgs) where the bus has it (FastVirtualBus), else one send per frame. reuse=True:
    the Message objects are not used by the caller afterwards (saves a copy on the virtual bus)."""
    f = getattr(bus, "send_batch", None)
    if f is not None:
        f(msgs, reuse)
    else:
        for m in msgs:
            bus.send(m)


MULTICAST_GROUP = "239.74.163.2"          # python-can UdpMulticastBus.DEFAULT_GROUP_IPv4
DEFAULT_UDP_PORT = 43113
LOOPBACK = "127.0.0.1"
#: --multicast: host (the socket keeps the frames on this host), route (host, plus a /32 route of the
#: group to lo while the bench runs: root only, undone at exit), lan (python-can's sockets, TTL 1, the
#: default interface: a controller on another host of the LAN)
MULTICAST_MODES = ("host", "route", "lan")


class _HostOnlySocket(_udp.GeneralPurposeUdpMulticastBus):
    """python-can's multicast socket handler with a socket that keeps the traffic on this host."""

    def _create_socket(self, address_family):
        """Join the group on the loopback interface and send through it (IP_MULTICAST_IF), TTL 0, loop on:
        no IGMP report and no frame on any NIC, whatever the routing table says."""
        if address_family != socket.AF_INET:
            raise OSError("host-only multicast is IPv4 (a 224.0.0.0/4 group)")
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            lo = socket.inet_aton(LOOPBACK)
            sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 0)
            sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 1)
            sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, lo)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            if hasattr(socket, "SO_REUSEPORT"):
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
            try:
                sock.setsockopt(socket.SOL_SOCKET, _udp.SO_TIMESTAMPNS, 1)
                self.timestamp_nanosecond = True
            except OSError:
                self.timestamp_nanosecond = False
            sock.bind((self.group, self.port))          # the group's datagrams only
            sock.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP, socket.inet_aton(self.group) + lo)
            return sock
        except OSError as error:
            sock.close()
            raise can.CanInitializationError(f"host-only multicast socket on {self.group}: {error}") from error


class HostOnlyUdpMulticastBus(_udp.UdpMulticastBus):
    """python-can's udp_multicast bus (same wire format: it exchanges frames with any UdpMulticastBus of this
    host on the group) whose socket keeps the traffic on this host: joined and sent on the loopback
    interface, TTL 0. No route, link or system setting is needed or changed."""

    def __init__(self, channel: str = MULTICAST_GROUP, port: int = DEFAULT_UDP_PORT, fd: bool = True, **kwargs):
        _udp.is_msgpack_installed()
        can.BusABC.__init__(self, channel, **kwargs)
        self._multicast = _HostOnlySocket(channel, int(port), 0)
        self._can_protocol = can.CanProtocol.CAN_FD if fd else can.CanProtocol.CAN_20


def make_bus(kind: str, channel=None, port: int | None = None, multicast: str = "host", **kw):
    """A python-can bus: virtual (FastVirtualBus on `channel`), udp_multicast (IPv4 group, port; kept on this
    host unless multicast = "lan"), or any other python-can interface name (socketcan, pcan, ...) with
    `channel` and keyword arguments."""
    if kind == "virtual":
        return FastVirtualBus(channel=channel or "reeve_hil", receive_own_messages=False, **kw)
    if kind == "udp_multicast":
        if multicast not in MULTICAST_MODES:
            raise ValueError(f"--multicast {multicast!r}: one of {', '.join(MULTICAST_MODES)}")
        if multicast == "lan":
            return can.Bus(interface="udp_multicast", channel=channel or MULTICAST_GROUP,
                           port=int(port or DEFAULT_UDP_PORT), hop_limit=1, **kw)
        return HostOnlyUdpMulticastBus(channel=channel or MULTICAST_GROUP, port=int(port or DEFAULT_UDP_PORT), **kw)
    return can.Bus(interface=kind, channel=channel, **kw)


def multicast_probe(port: int | None = None, timeout: float = 1.0, multicast: str = "host") -> tuple[bool, str]:
    """Can two udp_multicast buses on this host exchange a frame? (ok, reason)."""
    import can

    port = port or random.randint(44000, 44999)
    a = b = None
    try:
        a = make_bus("udp_multicast", port=port, multicast=multicast)
        b = make_bus("udp_multicast", port=port, multicast=multicast)
        a.send(can.Message(arbitration_id=0x7FF, data=b"probe", is_extended_id=False))
        deadline = time.perf_counter() + timeout
        while time.perf_counter() < deadline:
            m = b.recv(max(0.0, deadline - time.perf_counter()))
            if m is not None and m.arbitration_id == 0x7FF:
                return True, "ok"
        return False, f"udp_multicast: a frame sent to {MULTICAST_GROUP} was not received within {timeout:g} s"
    except Exception as exc:  # CanInitializationError, OSError
        return False, f"udp_multicast: {type(exc).__name__}: {exc}"
    finally:
        for bus in (a, b):
            if bus is not None:
                try:
                    bus.shutdown()
                except Exception:
                    pass


def ensure_multicast(multicast: str = "host") -> tuple[bool, str]:
    """Is udp_multicast usable on this host? Probes with two buses; changes nothing (the host-only buses
    keep the frames on the loopback interface by their socket options). Returns (ok, reason)."""
    return multicast_probe(multicast=multicast)


def _ip(*args) -> subprocess.CompletedProcess:
    return subprocess.run([shutil.which("ip") or "ip", *args], capture_output=True, text=True, encoding="utf-8",
                          errors="replace", timeout=10)


class _Signals:
    """SIGTERM and SIGHUP raise SystemExit while the bench runs, so that `finally` blocks undo what was set up
    (Ctrl-C already raises KeyboardInterrupt); the previous handlers come back at exit."""

    SIGNALS = ("SIGTERM", "SIGHUP")

    def __enter__(self):
        import signal

        self.old = {}
        if threading.current_thread() is threading.main_thread():
            for name in self.SIGNALS:
                sig = getattr(signal, name, None)
                if sig is not None:
                    self.old[sig] = signal.signal(sig, self._raise)
        return self

    @staticmethod
    def _raise(signum, frame):
        raise SystemExit(128 + signum)

    def __exit__(self, *exc):
        import signal

        for sig, handler in self.old.items():
            signal.signal(sig, handler)
        return False


@contextlib.contextmanager
def bench_route(group: str = MULTICAST_GROUP, log=print):
    """--multicast route: while the bench runs, route the bench's own group (a /32, never a range) to lo,
    with lo's multicast flag on if it was off; said on the console and undone at exit, also after a fault,
    Ctrl-C, SIGTERM or SIGHUP. Root only; only what was not already so is changed and undone."""
    if not (hasattr(os, "geteuid") and os.geteuid() == 0) or shutil.which("ip") is None:
        raise ValueError("--multicast route changes the routing table: it needs root and the `ip` command "
                         "(the default --multicast host needs neither)")
    undo = []
    with _Signals():
        try:
            if "MULTICAST" not in _ip("link", "show", "lo").stdout.split(">")[0]:
                r = _ip("link", "set", "lo", "multicast", "on")
                if r.returncode != 0:
                    raise OSError(f"ip link set lo multicast on: {r.stderr.strip()}")
                undo.append(("link", "set", "lo", "multicast", "off"))
                log("network: ip link set lo multicast on (undone at exit)")
            if "dev lo" not in _ip("route", "show", "exact", f"{group}/32").stdout:
                r = _ip("route", "add", f"{group}/32", "dev", "lo")
                if r.returncode != 0:
                    raise OSError(f"ip route add {group}/32 dev lo: {r.stderr.strip()}")
                undo.append(("route", "del", f"{group}/32", "dev", "lo"))
                log(f"network: ip route add {group}/32 dev lo (undone at exit)")
            yield
        finally:
            for args in reversed(undo):
                r = _ip(*args)
                log(f"network: ip {' '.join(args)}" + ("" if r.returncode == 0 else f" FAILED: {r.stderr.strip()}"))
