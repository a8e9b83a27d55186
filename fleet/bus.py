"""The Zenoh session every fleet process opens, with typed publish/subscribe and liveliness.

* Processes open a **client** session connected to one or more routers (``--connect``);
  ``fleet router`` (and ``fleet up``, embedded) runs a session in **router** mode.
* Multicast scouting is off unless asked for, so separate fleets on one machine never meet.
* A Zenoh config file (``zenoh_config``) may add what a secured router needs: TLS files, a
  user and password (``fleet certs`` writes them); mode, endpoints and scouting are set here.
* Control traffic (plans, cmd_vel, spawn) is reliable with congestion control BLOCK; sensor
  streams use DROP so a slow subscriber never stalls the simulator.
* A malformed payload is counted per key and logged (the first and every 100th per key), never
  raised. A well-formed message its receiver finds implausible (a stamp far ahead of its clock,
  a pose jump no robot can drive, a sender not in the job) is dropped through
  :meth:`Bus.drop_implausible`: counted per key class, logged the same way, naming the sender.
* A reply to a query that does not decode is counted and the next reply waited for.
* A handler that raises costs the message it was handling, never the process
  (:meth:`Bus.handler_failed`: counted per kind, the traceback logged the first time).
"""

from __future__ import annotations

import contextlib
import json
import logging
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any, TypeVar

import zenoh

from fleet.protocol import DEFAULT_FLEET, DecodeError, Keys, Message, decode, key_class

log = logging.getLogger(__name__)

M = TypeVar("M", bound=Message)

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"


def make_config(
    mode: str = "client",
    connect: Iterable[str] = (),
    listen: Iterable[str] = (),
    multicast: bool = False,
    zenoh_config: Path | None = None,
) -> zenoh.Config:
    """A Zenoh config: ``mode`` client, peer or router; endpoints like ``tcp/127.0.0.1:7447``;
    on top of the JSON5 file ``zenoh_config`` when given (ValueError names it if unreadable)."""
    if mode not in ("client", "peer", "router"):
        raise ValueError(f"mode must be client, peer or router, got {mode!r}")
    conf = zenoh.Config() if zenoh_config is None else _config_file(zenoh_config)
    conf.insert_json5("mode", json.dumps(mode))
    conf.insert_json5("scouting/multicast/enabled", json.dumps(multicast))
    connect = list(connect)
    listen = list(listen)
    for ep in connect + listen:
        validate_endpoint(ep)
    if connect:
        conf.insert_json5("connect/endpoints", json.dumps(connect))
    if listen:
        conf.insert_json5("listen/endpoints", json.dumps(listen))
    if mode == "client":
        # Keep retrying the router for a while instead of failing at once when it starts late.
        conf.insert_json5("connect/timeout_ms", "10000")
    return conf


def _config_file(path: Path) -> zenoh.Config:
    if not path.is_file():
        raise ValueError(f"Zenoh config {path}: no such file")
    try:
        return zenoh.Config.from_file(str(path))
    except Exception as e:  # zenoh raises ZError for syntax and schema errors
        raise ValueError(f"Zenoh config {path}: {e}") from None


def validate_endpoint(endpoint: str) -> None:
    """Reject endpoints that are not ``proto/host:port`` with a clear message."""
    proto, sep, rest = endpoint.partition("/")
    host, colon, port = rest.rpartition(":")
    if not sep or proto not in ("tcp", "udp", "tls", "quic", "ws", "unixsock-stream") or not host:
        raise ValueError(f"bad Zenoh endpoint {endpoint!r}: expected e.g. tcp/127.0.0.1:7447")
    if proto != "unixsock-stream" and (
        not colon or not port.isdigit() or not 0 < int(port) < 65536
    ):
        raise ValueError(f"bad Zenoh endpoint {endpoint!r}: the port must be 1–65535")


def open_router(listen: Iterable[str], zenoh_config: Path | None = None) -> zenoh.Session:
    """Open a Zenoh session in router mode listening on ``listen``."""
    return zenoh.open(make_config("router", listen=listen, zenoh_config=zenoh_config))


class Bus:
    """One process's connection to the fleet: typed pub/sub, queries and liveliness."""

    def __init__(
        self,
        role: str,
        ident: str,
        connect: Iterable[str] = (DEFAULT_ENDPOINT,),
        fleet: str = DEFAULT_FLEET,
        mode: str = "client",
        zenoh_config: Path | None = None,
    ) -> None:
        self.keys = Keys(fleet)
        self.role = role
        self.ident = ident
        self.session = zenoh.open(make_config(mode, connect=connect, zenoh_config=zenoh_config))
        self.decode_errors: Counter[str] = Counter()
        self.implausible: Counter[str] = Counter()
        self.handler_errors: Counter[str] = Counter()
        self._lock = threading.Lock()
        self._publishers: dict[str, zenoh.Publisher] = {}
        self._handles: list[Any] = []
        # set once close() begins: callbacks still in flight hand nothing on
        self.closed = threading.Event()
        self._token = self.session.liveliness().declare_token(self.keys.alive(role, ident))

    def close(self) -> None:
        """Close the session. From the moment this begins, messages and tokens still delivered
        (zenoh may run a callback after its subscriber is undeclared) are ignored, and a handler
        that fails meanwhile (publishing on the closing session) is not an error: an object
        that lives on after its bus, a finished test's coordinator say, hears nothing more."""
        self.closed.set()
        for h in self._handles:
            with contextlib.suppress(Exception):
                h.undeclare()
        self._handles.clear()
        self._token.undeclare()
        self.session.close()

    def __enter__(self) -> Bus:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def publish(self, key: str, msg: Message, control: bool = False) -> None:
        """Publish ``msg`` on ``key``; ``control`` selects reliable + BLOCK, else DROP."""
        pub = self._publishers.get(key)
        if pub is None:
            cc = zenoh.CongestionControl.BLOCK if control else zenoh.CongestionControl.DROP
            pri = zenoh.Priority.INTERACTIVE_HIGH if control else zenoh.Priority.DATA
            pub = self.session.declare_publisher(key, congestion_control=cc, priority=pri)
            self._publishers[key] = pub
        pub.put(msg.encode())

    def drop_malformed(self, key: str, err: DecodeError) -> None:
        """Count and log (the first and every 100th time per key) a payload that did not
        decode."""
        with self._lock:
            self.decode_errors[key] += 1
            n = self.decode_errors[key]
        if n == 1 or n % 100 == 0:
            log.warning("dropped malformed payload on %s (%d so far): %s", key, n, err)

    def drop_implausible(self, key: str, sender: str, why: str, n: int = 1) -> None:
        """Count ``n`` well-formed messages on ``key`` from ``sender`` that their receiver
        dropped as implausible, per key class; log the first and every 100th per class."""
        cls = key_class(key)
        with self._lock:
            before = self.implausible[cls]
            self.implausible[cls] += n
            total = self.implausible[cls]
        if before == 0 or total // 100 > before // 100:
            log.warning(
                "dropped %d implausible message(s) on %s from %s (%d so far): %s",
                n,
                cls,
                sender or "an unknown sender",
                total,
                why,
            )

    def handler_failed(self, kind: str) -> None:
        """Count a message of ``kind`` (a key class, or a loop's name) whose handler raised;
        call it from the ``except`` block. The message is lost, never the process: the
        traceback is logged the first time per kind, a line every 100th. Once the bus is
        closing, a failing handler (publishing on the closing session) is not counted."""
        if self.closed.is_set():
            return
        with self._lock:
            self.handler_errors[kind] += 1
            n = self.handler_errors[kind]
        if n == 1:
            log.exception("handling a message of %s failed; the message is dropped", kind)
        elif n % 100 == 0:
            log.error("handling a message of %s failed again (%d so far)", kind, n)

    def dropped(self) -> tuple[int, int]:
        """(malformed, implausible) messages this process dropped so far."""
        with self._lock:
            return sum(self.decode_errors.values()), sum(self.implausible.values())

    def subscribe(self, key: str, cls: type[M], callback: Callable[[str, M], None]) -> None:
        """Call ``callback(key, message)`` for each valid ``cls`` message on ``key``."""

        def on_sample(sample: zenoh.Sample) -> None:
            if self.closed.is_set():
                return
            k = str(sample.key_expr)
            try:
                msg = decode(sample.payload.to_bytes(), cls)
            except DecodeError as e:
                self.drop_malformed(k, e)
                return
            try:
                callback(k, msg)
            except Exception:
                self.handler_failed(key_class(k))

        self._handles.append(self.session.declare_subscriber(key, on_sample))

    def serve(self, key: str, cls: type[M], handler: Callable[[M], Message]) -> None:
        """Answer queries on ``key``: decode the request, reply with ``handler``'s message.

        A handler raises LookupError for "nothing to give yet" (an error reply, no log line);
        any other exception is logged with its traceback and also answered as an error."""

        def on_query(query: zenoh.Query) -> None:
            if self.closed.is_set():
                return
            k = str(query.key_expr)
            try:
                req = decode(query.payload.to_bytes() if query.payload else b"", cls)
            except DecodeError as e:
                self.drop_malformed(k, e)
                query.reply_err(str(e))
                return
            try:
                reply = handler(req)
            except LookupError as e:
                query.reply_err(str(e))
                return
            except Exception as e:
                self.handler_failed(key_class(k))
                query.reply_err(str(e))
                return
            query.reply(k, reply.encode())

        self._handles.append(self.session.declare_queryable(key, on_query))

    def request(self, key: str, msg: Message, reply_cls: type[M], timeout: float = 5.0) -> M:
        """Send a query and return the first valid reply; raises TimeoutError or RuntimeError.
        A reply that does not decode is counted and dropped. A query nothing serves ends at
        once, without waiting for ``timeout``."""
        start = time.monotonic()
        for reply in self.session.get(key, payload=msg.encode(), timeout=timeout):
            if reply.ok is None:
                raise RuntimeError(f"{key}: {reply.err.payload.to_string()}")
            try:
                return decode(reply.ok.payload.to_bytes(), reply_cls)
            except DecodeError as e:
                self.drop_malformed(key, e)
        waited = time.monotonic() - start
        raise TimeoutError(f"{key}: no valid reply after {waited:.1f} s (timeout {timeout} s)")

    def watch_alive(
        self,
        role: str,
        on_join: Callable[[str], None],
        on_leave: Callable[[str], None],
    ) -> None:
        """Track liveliness tokens of ``role`` (``*`` for all); existing ones are reported too."""

        def on_sample(sample: zenoh.Sample) -> None:
            if self.closed.is_set():
                return
            ident = str(sample.key_expr).rsplit("/", 1)[-1]
            try:
                if sample.kind == zenoh.SampleKind.PUT:
                    on_join(ident)
                else:
                    on_leave(ident)
            except Exception:
                self.handler_failed("liveliness")

        sub = self.session.liveliness().declare_subscriber(
            self.keys.alive_all(role), on_sample, history=True
        )
        self._handles.append(sub)
