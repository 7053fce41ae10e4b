"""Transport endpoints of the emulators: serial (socket:// server or pty pair) and Modbus TCP server.

Every server binds 127.0.0.1 only. ``port = 0`` takes a free ephemeral port (tests); the bound
address is in ``url`` / ``port`` afterwards.
"""

from __future__ import annotations

import asyncio
import contextlib
import contextvars
import errno
import logging
import os
import select
import socket
import threading
import tty
from collections.abc import Awaitable, Callable
from typing import Any

from bench.wire.tcpcan import parse_channel, pack, REC, unpack

LOOPBACK = "127.0.0.1"

# pymodbus logs a port it cannot bind (and a dropped client) itself; the emulator says it in one line of its own
# (`ModbusTcpEndpoint`), so pymodbus' messages would only repeat it on stderr (as the drivers' client does:
# bench.drivers.modbus)
logging.getLogger("pymodbus").setLevel(logging.CRITICAL)


def free_port() -> int:
    return free_ports(1)[0]


def free_ports(n: int) -> list[int]:
    """n distinct free loopback ports (all held open while choosing, so they differ)."""
    socks = []
    try:
        for _ in range(n):
            s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            s.bind((LOOPBACK, 0))
            socks.append(s)
        return [s.getsockname()[1] for s in socks]
    finally:
        for s in socks:
            s.close()


def _listen(host: str, port: int, backlog: int, what: str) -> socket.socket:
    """A listening TCP socket on host:port; a port in use is an OSError naming it (and the link)."""
    srv = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    try:
        srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        srv.bind((host, port))
        srv.listen(backlog)
    except OSError as exc:
        srv.close()
        raise OSError(exc.errno, f"cannot listen on {host}:{port} ({what}): {exc.strerror or exc}") from None
    return srv


def parse_socket_url(url: str) -> tuple[str, int]:
    """``socket://HOST:PORT`` -> (host, port); the host must be loopback."""
    if not url.startswith("socket://"):
        raise ValueError(f"not a socket:// URL: {url!r}")
    host, _, port = url[len("socket://"):].partition(":")
    port = port.split("?")[0]
    if host not in (LOOPBACK, "localhost"):
        raise ValueError(f"emulators serve loopback only (127.0.0.1), got host {host!r}")
    return LOOPBACK, int(port)


class SerialEndpoint:
    """The device side of a serial link.

    ``socket://127.0.0.1:PORT`` (pyserial's TCP URL): a TCP server on loopback, one client at a
    time: a new client is accepted once the old one has closed (the host reconnecting), refused
    while it is alive (``refused``), so a second program cannot knock the host off. ``pty``: a pseudo-terminal
    pair; the host opens ``url`` (the slave device path). Writes never block the emulator: with
    no client, or a full buffer, the bytes are dropped (counted in ``dropped_bytes``).
    """

    def __init__(self, url: str) -> None:
        self.dropped_bytes = 0
        self._client: socket.socket | None = None
        self._lock = threading.Lock()
        self._accept_lock = threading.Lock()
        self._stop = threading.Event()
        self._srv: socket.socket | None = None
        self._master: int | None = None
        self._slave: int | None = None
        self.connections = 0
        self.refused = 0
        if url == "pty":
            self._master, self._slave = os.openpty()
            tty.setraw(self._master)
            tty.setraw(self._slave)
            os.set_blocking(self._master, False)
            self.url = os.ttyname(self._slave)
            return
        host, port = parse_socket_url(url)
        srv = _listen(host, port, 1, "serial")
        srv.setblocking(False)
        self._srv = srv
        self.port = srv.getsockname()[1]
        self.url = f"socket://{LOOPBACK}:{self.port}"
        self._thread = threading.Thread(target=self._accept, name="emu-serial-accept", daemon=True)
        self._thread.start()

    def _accept(self) -> None:
        assert self._srv is not None
        while not self._stop.is_set():
            self.accept_pending(0.1)

    def accept_pending(self, timeout: float) -> bool:
        """Accept a waiting connection (up to ``timeout`` s); True if one was accepted."""
        srv = self._srv
        if srv is None:
            return False
        try:
            if not select.select([srv], [], [], timeout)[0]:
                return False
        except (OSError, ValueError):
            return False
        with self._accept_lock:  # the accept thread and write() may both see it readable
            try:
                conn, _ = srv.accept()
            except (BlockingIOError, TimeoutError, OSError):
                return self._client is not None
            if self._client is not None and self._alive(self._client):
                conn.close()  # one host at a time: a second client must not knock the first off
                self.refused += 1
                return True
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            conn.setblocking(False)
            with self._lock:
                old, self._client = self._client, conn
                self.connections += 1
            if old is not None:
                old.close()
            return True

    @staticmethod
    def _alive(c: socket.socket) -> bool:
        """False once the peer closed (EOF or error); a host that reconnects has closed its old socket."""
        try:
            if not select.select([c], [], [], 0)[0]:
                return True
            return c.recv(1, socket.MSG_PEEK) != b""
        except (BlockingIOError, InterruptedError):
            return True
        except OSError:
            return False

    @property
    def connected(self) -> bool:
        return self._master is not None or self._client is not None

    def wait_connected(self, timeout: float) -> bool:
        end = timeout
        step = 0.005
        while not self.connected and end > 0:
            self._stop.wait(step)
            end -= step
        return self.connected

    def write(self, data: bytes, wait: float = 0.0) -> None:
        """Send to the host; with no host connected, wait up to ``wait`` s for one first."""
        if self._client is None and wait > 0.0 and self._master is None:
            # the accept thread takes the connection; waiting on the listening socket here instead
            # raced with it (it accepted first, then this select slept the whole `wait`)
            self.wait_connected(wait)
        if self._master is not None:
            try:
                os.write(self._master, data)
            except (BlockingIOError, OSError):
                self.dropped_bytes += len(data)
            return
        c = self._client
        if c is None:
            self.dropped_bytes += len(data)
            return
        try:
            n = c.send(data)
            if n < len(data):
                self.dropped_bytes += len(data) - n
        except BlockingIOError:
            self.dropped_bytes += len(data)
        except OSError:
            self.disconnect()
            self.dropped_bytes += len(data)

    def read_available(self) -> bytes:
        """Bytes the host sent (not used by the front-end protocol; kept for completeness)."""
        c = self._client
        if c is None or not select.select([c], [], [], 0)[0]:
            return b""
        try:
            return c.recv(4096)
        except OSError:
            return b""

    def disconnect(self) -> None:
        """Drop the current client (fault injection: cable pulled); the host may reconnect."""
        with self._lock:
            c, self._client = self._client, None
        if c is not None:
            try:
                c.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            c.close()

    def close(self) -> None:
        self._stop.set()
        self.disconnect()
        if self._srv is not None:
            self._srv.close()
            self._thread.join(timeout=1.0)
        for fd in (self._master, self._slave):
            if fd is not None:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self._master = self._slave = None


Action = Callable[[int, int, int, int, list[int], Any], Awaitable[Any]]
_PEER: contextvars.ContextVar[object | None] = contextvars.ContextVar("modbus_peer", default=None)


def modbus_peer() -> object | None:
    """The client connection whose request a `ModbusTcpEndpoint` action is serving (None outside one)."""
    return _PEER.get()


def _server_class() -> type:
    """pymodbus' TCP server whose connections tell the action who asks (`modbus_peer`) and say when they go."""
    from pymodbus.server import ModbusTcpServer
    from pymodbus.server.requesthandler import ServerRequestHandler

    class Connection(ServerRequestHandler):
        async def handle_request(self) -> None:
            _PEER.set(self)  # this request's task only
            await super().handle_request()

        def callback_disconnected(self, exc: Exception | None) -> None:
            super().callback_disconnected(exc)
            gone = getattr(self.server, "on_disconnect", None)
            if gone is not None:
                gone(self)

    class Server(ModbusTcpServer):
        on_disconnect: Callable[[object], None] | None = None

        def callback_new_connection(self) -> Connection:
            return Connection(self, self.trace_packet, self.trace_pdu, self.trace_connect)

    return Server


class ModbusTcpEndpoint:
    """A pymodbus Modbus TCP server on 127.0.0.1, in its own thread and event loop.

    ``addresses`` are the holding-register wire addresses the device serves; ``action`` (pymodbus
    SimDevice action) sees every access and keeps the live values (bench.drivers.modbus); during it,
    `modbus_peer` names the client connection, and ``on_disconnect(peer)`` is called when one closes.
    """

    def __init__(self, port: int, unit: int, addresses: list[int], action: Action,
                 on_disconnect: Callable[[object], None] | None = None) -> None:  # fmt: skip
        from pymodbus.simulator import DataType, SimData, SimDevice

        server_class = _server_class()

        self.port = port or free_port()
        simdata = [SimData(a, values=0, datatype=DataType.REGISTERS) for a in sorted(set(addresses))]
        device = SimDevice(unit, simdata=simdata, action=action)
        self._loop = asyncio.new_event_loop()
        self._ready = threading.Event()
        self._error: BaseException | None = None

        async def main() -> None:
            self.server = server_class(device, address=(LOOPBACK, self.port))
            self.server.on_disconnect = on_disconnect
            # listen first, then report ready: a port another program holds fails here, at once (the
            # check by connecting afterwards reached that program and took it for the emulator)
            try:
                await self.server.serve_forever(background=True)
            except RuntimeError:  # pymodbus: "Could not start listen" (it logs the OSError itself)
                raise OSError(errno.EADDRINUSE, f"cannot listen on {LOOPBACK}:{self.port} (Modbus TCP): "
                              "the port is in use") from None  # fmt: skip
            self._ready.set()
            with contextlib.suppress(asyncio.CancelledError):
                await self.server.serving

        def run() -> None:
            asyncio.set_event_loop(self._loop)
            try:
                self._loop.run_until_complete(main())
            except BaseException as exc:  # noqa: BLE001 - reported to the starter
                self._error = exc
                self._ready.set()

        self._thread = threading.Thread(target=run, name="emu-modbus", daemon=True)
        self._thread.start()
        self._ready.wait(5.0)
        if self._error is not None:
            raise self._error
        self._wait_listening()

    def _wait_listening(self, timeout: float = 5.0) -> None:
        import time

        end = time.monotonic() + timeout
        while time.monotonic() < end:
            try:
                with socket.create_connection((LOOPBACK, self.port), timeout=0.2):
                    return
            except OSError:
                time.sleep(0.01)
        raise ConnectionError(f"Modbus emulator did not start on {LOOPBACK}:{self.port}")

    def close(self) -> None:
        if self._loop.is_running():
            fut = asyncio.run_coroutine_threadsafe(self.server.shutdown(), self._loop)
            try:
                fut.result(timeout=3.0)
            except Exception:  # noqa: BLE001
                pass
        self._thread.join(timeout=3.0)
        if not self._loop.is_running():
            self._loop.close()


class TcpCanServerBus:
    """The emulator's end of the loopback TCP CAN link (bench.drivers.tcpcan, records of bench.wire.tcpcan): a
    python-can-like bus (``send``, ``recv``, ``shutdown``) that serves 127.0.0.1:PORT. Frames sent go to every
    client, and the controller's frames are relayed to the others: a listening client such as
    python-can's ``can.logger -i tcp -c 127.0.0.1:PORT`` sees all traffic, as on a real bus.

    One controller at a time: the first client to send a frame controls the devices until it
    disconnects; another client that sends meanwhile is dropped at its first frame, which reaches
    no one (counted in ``stats["refused_controllers"]``), so a second host cannot command the drive.

    Sending never blocks the device loop: each client has an output buffer, written with
    non-blocking sends; a client that does not read and falls `MAX_BACKLOG` bytes behind (about a
    second of traffic) is dropped, like a CAN node that went bus-off. Bytes that do not frame
    (garbage) are dropped with their client.
    """

    MAX_BACKLOG = 64 * 1024

    def __init__(self, channel: str, stats: dict[str, int] | None = None) -> None:
        host, port = parse_channel(channel)
        srv = _listen(host, port, 4, "CAN")
        srv.setblocking(False)
        self._srv = srv
        self.port = srv.getsockname()[1]
        self.channel = f"{LOOPBACK}:{self.port}"
        self._clients: dict[socket.socket, bytearray] = {}  # received bytes not yet framed
        self._out: dict[socket.socket, bytearray] = {}  # bytes not yet sent
        self._pending: list[Any] = []
        self._controller: socket.socket | None = None  # the client whose frames reach the devices
        self.dropped_clients = 0
        self.stats = stats if stats is not None else {}  # "garbage_clients": dropped for bytes that do not frame
        self.stats.setdefault("garbage_clients", 0)
        self.stats.setdefault("refused_controllers", 0)  # dropped for sending while another client controls

    def send(self, msg: Any, timeout: float | None = None) -> None:
        self._broadcast(pack(msg))

    def _broadcast(self, rec: bytes, source: socket.socket | None = None) -> None:
        """To every client but ``source``: a bus, on which every node sees every frame (can.logger too)."""
        for c in list(self._clients):
            if c is source:
                continue
            out = self._out[c]
            out += rec
            try:
                n = c.send(out)
                del out[:n]
            except BlockingIOError:
                pass
            except OSError:
                self._drop(c)
                continue
            if len(out) > self.MAX_BACKLOG:  # a client that does not read: never let it block the devices
                self._drop(c)

    def _drop(self, c: socket.socket) -> None:
        if c is self._controller:
            self._controller = None
        if self._clients.pop(c, None) is not None:
            self.dropped_clients += 1
        self._out.pop(c, None)
        c.close()

    def recv(self, timeout: float | None = None) -> Any:
        import time

        end = None if timeout is None else time.perf_counter() + timeout
        while True:
            if self._pending:
                return self._pending.pop(0)
            left = None if end is None else max(0.0, end - time.perf_counter())
            ready = select.select([self._srv, *self._clients], [], [], left)[0]
            if not ready:
                return None
            for s in ready:
                if s is self._srv:
                    try:
                        conn, _ = self._srv.accept()
                    except OSError:
                        continue
                    conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                    # a bounded kernel buffer (no autotuning to MBs), so a client that stops reading
                    # shows up in our backlog within about a second of traffic
                    conn.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, 32 * 1024)
                    conn.setblocking(False)
                    self._clients[conn], self._out[conn] = bytearray(), bytearray()
                    continue
                try:
                    data = s.recv(65536)
                except BlockingIOError:
                    continue
                except OSError:
                    data = b""
                if not data:
                    self._drop(s)
                    continue
                buf = self._clients[s]
                buf += data
                try:
                    while len(buf) >= REC.size:
                        rec = bytes(buf[: REC.size])
                        msg = unpack(rec)  # garbage raises at its first record: nothing of it is used
                        if self._controller is None:
                            self._controller = s
                        elif self._controller is not s:  # a second host: refused, not relayed, not heard
                            self.stats["refused_controllers"] += 1
                            self._drop(s)
                            break
                        self._pending.append(msg)
                        del buf[: REC.size]
                        if len(self._clients) > 1:
                            self._broadcast(rec, source=s)
                except Exception:  # noqa: BLE001 - bytes that do not frame: that client goes
                    self.stats["garbage_clients"] += 1
                    self._drop(s)

    def shutdown(self) -> None:
        for c in list(self._clients):
            self._drop(c)
        self._srv.close()
