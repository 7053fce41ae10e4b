"""Hostile or stalled clients on the emulators' sockets (127.0.0.1) never block the emulated devices."""

from __future__ import annotations

import socket
import threading
import time

import can
import numpy as np

from bench.drivers.tcpcan import TcpCanBus
from bench.wire.tcpcan import pack, parse_channel, unpack
from mock_hw.emulators import start_emulator
from mock_hw.emulators.links import parse_socket_url
from mock_hw.emulators.testing import emulated_config


def _sync(k: int) -> bytes:
    return pack(can.Message(arbitration_id=0x080, data=[k & 0xFF], is_extended_id=False))


def _connect(channel: str, rcvbuf: int | None = None) -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    if rcvbuf is not None:  # before connect: the window the peer may fill stays small
        s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
    s.settimeout(5)
    s.connect(parse_channel(channel))
    s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    return s


def _drain(s: socket.socket, stop: threading.Event) -> None:
    s.settimeout(0.1)
    while not stop.is_set():
        try:
            if not s.recv(65536):
                return
        except (TimeoutError, socket.timeout):
            continue
        except OSError:
            return


def _wait(pred, timeout: float = 20.0) -> bool:  # noqa: ANN001
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(0.01)
    return pred()


def test_a_can_client_that_never_reads_is_dropped_and_does_not_freeze_the_devices():
    emu = start_emulator(emulated_config("tcp"))
    stop = threading.Event()
    try:
        channel = emu.host_config().hw["can"]["channel"]
        stalled = _connect(channel, rcvbuf=4096)  # connects, never reads
        host = _connect(channel)
        reader = threading.Thread(target=_drain, args=(host, stop), daemon=True)
        reader.start()
        n = 30000  # 10 s of SYNCs at 3 kHz: ~160 kB of status frames towards each client
        for k in range(1, n + 1):
            host.sendall(_sync(k))
            if k % 1000 == 0:  # keep the emulator's pace (it advances the plant per SYNC)
                assert _wait(lambda k=k: emu.stats["syncs"] >= k - 500), emu.stats
        assert _wait(lambda: emu.stats["syncs"] == n), emu.stats  # every SYNC served: never blocked
        assert emu.bus.dropped_clients >= 1  # the one that did not read
        stalled.close()
        host.close()
    finally:
        stop.set()
        emu.close()


def test_garbage_on_the_can_port_costs_only_that_client():
    """Random bytes are dropped with their sender at the first record: none of them reaches the
    drive or is relayed to the other clients as frames (docs/protocols.md)."""
    emu = start_emulator(emulated_config("tcp"))
    try:
        channel = emu.host_config().hw["can"]["channel"]
        listener = TcpCanBus(channel)  # a third node, as python-can's can.logger would be
        host = _connect(channel)
        junk = _connect(channel)
        assert _wait(lambda: len(emu.bus._clients) == 3)
        junk.sendall(np.random.default_rng(1).bytes(10_000))
        assert _wait(lambda: emu.stats["garbage_clients"] == 1), "the garbage sender was not dropped"
        junk.settimeout(5)
        try:
            got = junk.recv(1)
        except ConnectionResetError:
            got = b""
        assert got == b""  # closed by the emulator (EOF or reset)
        for k in range(1, 301):
            host.sendall(_sync(k))
        assert _wait(lambda: emu.stats["syncs"] == 300), emu.stats
        assert emu._thread is not None and emu._thread.is_alive() and emu.stats["bad_frames"] == 0
        ids = set()
        while (msg := listener.recv(0.2)) is not None:
            ids.add(msg.arbitration_id)
        assert ids <= {0x080, 0x180}, sorted(ids)  # SYNC relayed from the host, the drive's status: no garbage
        junk.close()
        host.close()
        listener.shutdown()
    finally:
        emu.close()


def test_tcp_can_records_only_what_pack_makes():
    rng = np.random.default_rng(7)
    refused = 0
    for _ in range(20_000):
        try:
            unpack(rng.bytes(16))
        except ValueError:
            refused += 1
    assert refused == 20_000
    for msg in (can.Message(arbitration_id=0x7FF, data=b"\x01\x02", is_extended_id=False),
                can.Message(arbitration_id=0x1FFFFFFF, data=bytes(range(8)), is_extended_id=True)):
        back = unpack(pack(msg))
        assert (back.arbitration_id, back.is_extended_id, bytes(back.data)) == (msg.arbitration_id,
                                                                               msg.is_extended_id, bytes(msg.data))


def test_a_second_serial_client_is_refused_while_the_host_is_connected():
    emu = start_emulator(emulated_config("tcp"))
    try:
        url = emu.host_config().hw["serial"]["port"]
        host = socket.create_connection(parse_socket_url(url), timeout=5)
        assert _wait(lambda: emu.serial.connected)
        second = socket.create_connection(parse_socket_url(url), timeout=5)
        second.settimeout(5)
        assert second.recv(1) == b""  # closed by the emulator at once
        assert _wait(lambda: emu.serial.refused == 1)
        emu.serial.write(b"frame")  # the host still gets the stream
        host.settimeout(5)
        assert host.recv(5) == b"frame"
        host.close()  # the host reconnecting after a cable pull is accepted again
        again = socket.create_connection(parse_socket_url(url), timeout=5)
        assert _wait(lambda: emu.serial.connections == 2)
        again.close()
        second.close()
    finally:
        emu.close()
