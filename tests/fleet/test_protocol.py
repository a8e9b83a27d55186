"""Wire protocol: every message round-trips; every malformed payload is a DecodeError.

Plus one real-bus test over a loopback Zenoh router: a garbage payload is counted and dropped
without losing the next valid message, and liveliness join/leave is observed.
"""

from __future__ import annotations

import dataclasses
import threading
import typing
import zlib
from collections.abc import Callable
from typing import Annotated, Any

import msgpack
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from waits import wait_until

from fleet.bus import Bus, validate_endpoint
from fleet.protocol import (
    MESSAGES,
    SCHEMA_VERSION,
    Arr,
    Award,
    CoverageImage,
    CoverageSummary,
    DecodeError,
    LaserScan,
    MapPatches,
    Message,
    Num,
    Plan,
    PoseEstimate,
    Request,
    Twist,
    decode,
    encode,
)
from fleet.supervisor.launcher import free_port

ALL = sorted(MESSAGES.values(), key=lambda c: c.TYPE)
FAST = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])

# ---------------------------------------------------------------------------------------------
# Strategies built from the dataclass schemas


def _fields(cls: type[Message]) -> list[tuple[str, Any, Any]]:
    """(name, type, schema meta) of each field, read from the annotations."""
    hints = typing.get_type_hints(cls, include_extras=True)
    out = []
    for name in (f.name for f in dataclasses.fields(cls)):
        tp, meta = hints[name], None
        if typing.get_origin(tp) is Annotated:
            tp, meta = typing.get_args(tp)[0], typing.get_args(tp)[1]
        out.append((name, tp, meta))
    return out


TEXT = st.text(st.characters(blacklist_categories=("Cs",)), max_size=12)


def _array(meta: Arr, length: int | st.SearchStrategy[int] | None = None) -> st.SearchStrategy:
    dt = np.dtype(meta.dtype)
    if dt.kind == "f":
        elements = st.floats(width=dt.itemsize * 8, allow_nan=False, allow_infinity=meta.allow_inf)
    else:
        info = np.iinfo(dt)
        elements = st.integers(int(info.min), int(info.max))
    lead = st.integers(0, 12) if length is None else length
    shape = (
        lead.map(lambda n: (n, *meta.tail))
        if isinstance(lead, st.SearchStrategy)
        else (
            lead,
            *meta.tail,
        )
    )
    return hnp.arrays(dt, shape, elements=elements)


def _scalar(tp: Any, meta: Any) -> st.SearchStrategy:
    if tp is float:
        allow_inf = isinstance(meta, Num) and meta.allow_inf
        return st.floats(allow_nan=False, allow_infinity=allow_inf)
    if tp is bool:
        return st.booleans()
    if tp is int:
        return st.integers(-(2**63), 2**63 - 1)
    if tp is str:
        return TEXT
    if tp == list[str]:
        return st.lists(TEXT, max_size=5)
    raise AssertionError(f"no strategy for field type {tp!r}")


@st.composite
def messages(draw: st.DrawFn, cls: type[Message]) -> Message:
    """A valid ``cls`` message, keeping the cross-field constraints of ``_check_shapes``."""
    if cls is MapPatches:
        return draw(map_patches())
    fixed: dict[str, Any] = {}
    lengths: dict[str, int] = {}
    if cls is CoverageSummary:
        fixed["robots"] = draw(st.lists(TEXT, max_size=5))
        n = len(fixed["robots"])
        lengths = dict.fromkeys(
            ("path_length_m", "turns", "wall_collisions", "robot_collisions"), n
        )
    elif cls is PoseEstimate:
        lengths["covariance"] = 9
    elif cls is Award:
        fixed["tasks"] = draw(st.lists(TEXT, max_size=5))
        lengths = dict.fromkeys(("entries", "exits", "times_s"), len(fixed["tasks"]))
    elif cls is Plan:
        fixed["sweep_from"] = 0
        fixed["chain"] = []
        fixed["wait_for"] = draw(st.lists(TEXT, max_size=5))
        lengths = dict.fromkeys(("wait_at", "wait_plan", "wait_passed"), len(fixed["wait_for"]))
        lengths["chain_starts"] = 0
    elif cls is CoverageImage:
        fixed["rows"] = draw(st.integers(0, 6))
        fixed["cols"] = draw(st.integers(0, 6))
        cells = fixed["rows"] * fixed["cols"]
        lengths = dict.fromkeys(("visits", "cleanable"), cells)
        lengths["side"] = draw(st.sampled_from((0, cells)))
    kwargs = {}
    for name, tp, meta in _fields(cls):
        if name in fixed:
            kwargs[name] = fixed[name]
        elif isinstance(meta, Arr):
            kwargs[name] = draw(_array(meta, lengths.get(name)))
        else:
            kwargs[name] = draw(_scalar(tp, meta))
    return cls(**kwargs)


@st.composite
def map_patches(draw: st.DrawFn) -> MapPatches:
    tile = draw(st.integers(1, 4))
    rows, cols = draw(st.integers(1, 4)) * tile, draw(st.integers(1, 4)) * tile
    cells = [(r, c) for r in range(0, rows, tile) for c in range(0, cols, tile)]
    chosen = draw(st.lists(st.sampled_from(cells), unique=True, max_size=len(cells)))
    blocks = [
        (r, c, draw(hnp.arrays(np.int8, (tile, tile), elements=st.integers(-1, 100))))
        for r, c in chosen
    ]
    return MapPatches.pack(
        draw(_scalar(float, None)),
        draw(st.integers(0, 2**31)),
        draw(st.booleans()),
        (rows, cols),
        draw(st.floats(0.01, 1.0)),
        (draw(_scalar(float, None)), draw(_scalar(float, None))),
        tile,
        blocks,
    )


def _any_message() -> st.SearchStrategy[Message]:
    return st.sampled_from(ALL).flatmap(messages)


# ---------------------------------------------------------------------------------------------
# Round trip


@pytest.mark.parametrize("cls", ALL, ids=lambda c: c.TYPE)
@FAST
@given(data=st.data())
def test_every_message_round_trips(cls: type[Message], data: st.DataObject) -> None:
    msg = data.draw(messages(cls))
    back = decode(encode(msg), cls)
    assert type(back) is cls
    assert back == msg
    for name, _, meta in _fields(cls):
        if isinstance(meta, Arr):
            arr = getattr(back, name)
            assert arr.dtype == np.dtype(meta.dtype).newbyteorder("=")
            assert arr.shape[1:] == meta.tail
            assert arr.flags.writeable


def test_laser_scan_keeps_inf_ranges() -> None:
    scan = LaserScan(1.0, -3.14, 0.01, 0.1, 6.0, np.array([1.5, np.inf, 0.2], dtype=np.float32))
    back = decode(scan.encode(), LaserScan)
    assert np.isinf(back.ranges[1]) and back.ranges[0] == np.float32(1.5)


def test_registry_holds_every_message_under_its_tag() -> None:
    assert len(MESSAGES) >= 16
    for tag, cls in MESSAGES.items():
        assert tag == cls.TYPE and issubclass(cls, Message)


# ---------------------------------------------------------------------------------------------
# Malformed payloads


@FAST
@given(payload=st.binary(max_size=200), cls=st.sampled_from(ALL))
def test_random_bytes_raise_decode_error(payload: bytes, cls: type[Message]) -> None:
    with pytest.raises(DecodeError):
        decode(payload, cls)


MSGPACK_VALUES = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-(2**63), 2**64 - 1)
    | st.floats()
    | TEXT
    | st.binary(max_size=40),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(TEXT, inner, max_size=4),
    max_leaves=8,
)


@FAST
@given(cls=st.sampled_from(ALL), data=st.data())
def test_random_field_values_decode_or_raise_decode_error(
    cls: type[Message], data: st.DataObject
) -> None:
    """Right envelope, arbitrary msgpack values in the fields: a message or DecodeError only."""
    raw = {"_v": SCHEMA_VERSION, "_t": cls.TYPE}
    for name, _, _ in _fields(cls):
        raw[name] = data.draw(MSGPACK_VALUES, label=name)
    try:
        msg = decode(msgpack.packb(raw, use_bin_type=True), cls)
    except DecodeError:
        return
    assert type(msg) is cls


def _valid_map(msg: Message) -> dict[str, Any]:
    return msgpack.unpackb(encode(msg), raw=False)


def _pack(raw: dict[str, Any]) -> bytes:
    return msgpack.packb(raw, use_bin_type=True)


def _first(cls: type[Message], pred: Callable[[Any, Any], bool]) -> str | None:
    for name, tp, meta in _fields(cls):
        if pred(tp, meta):
            return name
    return None


def _is_float(tp: Any, meta: Any) -> bool:
    return tp is float


def _is_finite_float(tp: Any, meta: Any) -> bool:
    return tp is float and not (isinstance(meta, Num) and meta.allow_inf)


def _is_float_array(tp: Any, meta: Any) -> bool:
    return isinstance(meta, Arr) and np.dtype(meta.dtype).kind == "f"


def _is_finite_float_array(tp: Any, meta: Any) -> bool:
    return _is_float_array(tp, meta) and not meta.allow_inf


def _is_int(tp: Any, meta: Any) -> bool:
    return tp is int


def _is_str(tp: Any, meta: Any) -> bool:
    return tp is str


def _is_bool(tp: Any, meta: Any) -> bool:
    return tp is bool


def _is_str_list(tp: Any, meta: Any) -> bool:
    return tp == list[str]


def _is_array(tp: Any, meta: Any) -> bool:
    return isinstance(meta, Arr)


def _is_wide_array(tp: Any, meta: Any) -> bool:
    return isinstance(meta, Arr) and np.dtype(meta.dtype).itemsize * int(np.prod(meta.tail)) > 1


def _corrupt_field(cls: type[Message], pred: Callable[[Any, Any], bool], value: Any) -> bytes:
    """A valid message of ``cls`` with the first field matching ``pred`` set to ``value``."""
    name = _first(cls, pred)
    assert name is not None
    raw = _valid_map(_example(cls))
    raw[name] = value(raw[name]) if callable(value) else value
    return _pack(raw)


def _example(cls: type[Message]) -> Message:
    """A fixed valid message of ``cls`` with non-empty arrays."""
    if cls is MapPatches:
        blocks = [(0, 2, np.full((2, 2), 50, np.int8)), (2, 0, np.full((2, 2), -1, np.int8))]
        return MapPatches.pack(1.5, 4, True, (4, 6), 0.05, (1.5, 1.5), 2, blocks)
    kwargs: dict[str, Any] = {}
    for name, tp, meta in _fields(cls):
        if isinstance(meta, Arr):
            n = {"covariance": 9, "visits": 6, "cleanable": 6, "side": 6}.get(name, 2)
            kwargs[name] = np.ones((n, *meta.tail), dtype=meta.dtype)
        elif tp == list[str]:
            kwargs[name] = ["r0", "r1"]
        elif name == "sweep_from":
            kwargs[name] = 1
        elif name == "chain_starts":
            kwargs[name] = np.array([1, 1], dtype=np.int32)
        elif name == "rows":
            kwargs[name] = 2
        elif name == "cols":
            kwargs[name] = 3
        else:
            kwargs[name] = {float: 1.5, int: 4, bool: True, str: "a"}[tp]
    msg = cls(**kwargs)
    assert decode(encode(msg), cls) == msg
    return msg


def _with_value(cls: type[Message], raw: bytes, what: str) -> bytes:
    """Prepend one row holding ``what`` to the first float array of ``cls``."""
    name = _first(cls, _is_float_array)
    meta = {n: m for n, _, m in _fields(cls)}[name]
    row = np.full((1, *meta.tail), float(what), dtype=meta.dtype)
    return row.tobytes() + raw


def _envelope(cls: type[Message], **changes: Any) -> bytes:
    return _pack({**_valid_map(_example(cls)), **changes})


def _without(cls: type[Message], key: str) -> bytes:
    return _pack({k: v for k, v in _valid_map(_example(cls)).items() if k != key})


Applies = Callable[[Any, Any], bool] | None
# name -> (the kind of field the mutation needs, or None for any message; payload builder)
MUTATIONS: dict[str, tuple[Applies, Callable[[type[Message]], bytes]]] = {
    "wrong version": (None, lambda c: _envelope(c, _v=SCHEMA_VERSION + 1)),
    "version as string": (None, lambda c: _envelope(c, _v=str(SCHEMA_VERSION))),
    "version as bool": (None, lambda c: _envelope(c, _v=True)),
    "version as float": (None, lambda c: _envelope(c, _v=float(SCHEMA_VERSION))),
    "no version": (None, lambda c: _without(c, "_v")),
    "unknown type tag": (None, lambda c: _envelope(c, _t="no_such_type")),
    "other message's tag": (
        None,
        lambda c: _envelope(c, _t=next(t for t in MESSAGES if t != c.TYPE)),
    ),
    "no type tag": (None, lambda c: _without(c, "_t")),
    "missing first field": (None, lambda c: _without(c, _fields(c)[0][0])),
    "missing last field": (None, lambda c: _without(c, _fields(c)[-1][0])),
    "unknown field": (None, lambda c: _envelope(c, extra_field=1.0)),
    "not a map": (None, lambda c: _pack([SCHEMA_VERSION, c.TYPE])),
    "list in first field": (None, lambda c: _envelope(c, **{_fields(c)[0][0]: [1, 2]})),
    "map in last field": (None, lambda c: _envelope(c, **{_fields(c)[-1][0]: {"a": 1}})),
    "bool where number": (_is_float, lambda c: _corrupt_field(c, _is_float, True)),
    "string where number": (_is_float, lambda c: _corrupt_field(c, _is_float, "1.0")),
    "float where integer": (_is_int, lambda c: _corrupt_field(c, _is_int, 2.0)),
    "bool where integer": (_is_int, lambda c: _corrupt_field(c, _is_int, True)),
    "number where string": (_is_str, lambda c: _corrupt_field(c, _is_str, 3)),
    "bytes where string": (_is_str, lambda c: _corrupt_field(c, _is_str, b"abc")),
    "int where bool": (_is_bool, lambda c: _corrupt_field(c, _is_bool, 1)),
    "non-string in list": (_is_str_list, lambda c: _corrupt_field(c, _is_str_list, ["a", 1])),
    "NaN in float field": (_is_float, lambda c: _corrupt_field(c, _is_float, float("nan"))),
    "inf in float field": (
        _is_finite_float,
        lambda c: _corrupt_field(c, _is_finite_float, float("inf")),
    ),
    "-inf in float field": (
        _is_finite_float,
        lambda c: _corrupt_field(c, _is_finite_float, float("-inf")),
    ),
    "NaN in array": (
        _is_float_array,
        lambda c: _corrupt_field(c, _is_float_array, lambda b: _with_value(c, b, "nan")),
    ),
    "inf in finite array": (
        _is_finite_float_array,
        lambda c: _corrupt_field(c, _is_finite_float_array, lambda b: _with_value(c, b, "inf")),
    ),
    "list where array": (_is_array, lambda c: _corrupt_field(c, _is_array, [1.0, 2.0])),
    "string where array": (_is_array, lambda c: _corrupt_field(c, _is_array, "\x00" * 8)),
    "array length not whole rows": (
        _is_wide_array,
        lambda c: _corrupt_field(c, _is_wide_array, lambda b: b + b"\0"),
    ),
}

CASES = [
    pytest.param(cls, name, id=f"{cls.TYPE}-{name}")
    for cls in ALL
    for name, (applies, _) in MUTATIONS.items()
    if applies is None or _first(cls, applies) is not None
]


@pytest.mark.parametrize(("cls", "mutation"), CASES)
def test_malformed_payload_raises_decode_error(cls: type[Message], mutation: str) -> None:
    payload = MUTATIONS[mutation][1](cls)
    with pytest.raises(DecodeError):
        decode(payload, cls)


def test_every_mutation_applies_to_some_message() -> None:
    for name, (applies, _) in MUTATIONS.items():
        assert applies is None or any(_first(c, applies) for c in ALL), name


def test_cross_field_shapes_are_checked() -> None:
    summary = _valid_map(
        CoverageSummary(
            0.0,
            0.0,
            0.5,
            0.1,
            10.0,
            ["r0", "r1"],
            np.zeros(2),
            np.zeros(2, np.int32),
            np.zeros(2, np.int32),
            np.zeros(2, np.int32),
        )
    )
    summary["turns"] = np.zeros(3, "<i4").tobytes()
    with pytest.raises(DecodeError, match="turns"):
        decode(_pack(summary), CoverageSummary)
    pose = _valid_map(PoseEstimate(0.0, 1.0, 2.0, 0.0))
    pose["covariance"] = np.zeros(8).tobytes()
    with pytest.raises(DecodeError, match="covariance"):
        decode(_pack(pose), PoseEstimate)
    image = _valid_map(
        CoverageImage(0.0, 0.05, 0.0, 0.0, 2, 3, np.zeros(6, np.uint16), np.ones(6, np.uint8))
    )
    image["cols"] = 4
    with pytest.raises(DecodeError):
        decode(_pack(image), CoverageImage)
    image["cols"], image["rows"] = -3, -2
    with pytest.raises(DecodeError):
        decode(_pack(image), CoverageImage)
    image["cols"], image["rows"] = 3, 2
    image["side"] = np.ones(5, np.uint8).tobytes()
    with pytest.raises(DecodeError, match=r"coverage_image\.side"):
        decode(_pack(image), CoverageImage)


@pytest.mark.parametrize("name", ["wait_for", "wait_plan", "wait_passed", "wait_at"])
def test_plan_wait_fields_of_other_lengths_are_refused_by_name(name: str) -> None:
    raw = _valid_map(_example(Plan))
    raw[name] = ["r0"] if name == "wait_for" else np.ones(1, "<i4").tobytes()
    shown = "wait_for" if name == "wait_at" else name
    with pytest.raises(DecodeError, match=f"plan.{shown}: "):
        decode(_pack(raw), Plan)


def test_map_patches_round_trip_their_cells_and_reject_bad_geometry() -> None:
    msg = _example(MapPatches)
    blocks = decode(encode(msg), MapPatches).blocks
    assert blocks.shape == (2, 2, 2) and blocks[0, 0, 0] == 50 and blocks[1, 1, 1] == -1
    bad = {
        "cols": 5,  # not whole tiles
        "patch_cols": np.array([2, 5], "<i4").tobytes(),  # a patch past the right edge
        "patch_rows": np.array([0], "<i4").tobytes(),  # fewer rows than cols
        "data": zlib.compress(b"\x00" * 7),  # cells for less than two patches
        "resolution": 0.0,
        "tile": 0,
        "rows": 2**40,
    }
    for name, value in bad.items():
        raw = _valid_map(msg)
        raw[name] = value
        with pytest.raises(DecodeError):
            decode(_pack(raw), MapPatches)
    raw = _valid_map(msg)
    raw["data"] = zlib.compress(np.full(8, 101, np.int8).tobytes())
    with pytest.raises(DecodeError, match=r"0\.\.100"):
        decode(_pack(raw), MapPatches)
    raw["data"] = b"not zlib at all"
    with pytest.raises(DecodeError, match="zlib"):
        decode(_pack(raw), MapPatches)


# ---------------------------------------------------------------------------------------------
# Endpoints


@pytest.mark.parametrize(
    "endpoint",
    [
        "",
        "127.0.0.1:7447",
        "tcp/127.0.0.1",
        "tcp/127.0.0.1:0",
        "tcp/127.0.0.1:65536",
        "tcp/127.0.0.1:port",
        "tcp/:7447",
        "http/127.0.0.1:7447",
    ],
)
def test_validate_endpoint_rejects_bad_endpoints(endpoint: str) -> None:
    with pytest.raises(ValueError, match="endpoint"):
        validate_endpoint(endpoint)


@pytest.mark.parametrize("endpoint", ["tcp/127.0.0.1:7447", "udp/localhost:1", "tcp/[::1]:65535"])
def test_validate_endpoint_accepts_good_endpoints(endpoint: str) -> None:
    validate_endpoint(endpoint)


# ---------------------------------------------------------------------------------------------
# Real bus over a loopback router


@pytest.mark.timeout(60)
def test_garbage_is_counted_and_next_message_still_arrives(router_endpoint: str) -> None:
    fleet = f"t{free_port()}"
    with (
        Bus("sim", "pub", connect=[router_endpoint], fleet=fleet) as pub,
        Bus("agent", "sub", connect=[router_endpoint], fleet=fleet) as sub,
    ):
        key = sub.keys.robot("r0", "cmd_vel")
        got: list[Twist] = []
        lock = threading.Lock()

        def on_twist(k: str, msg: Twist) -> None:
            assert k == key
            with lock:
                got.append(msg)

        sub.subscribe(key, Twist, on_twist)
        # Warm up until the subscription has reached the publisher through the router.
        assert wait_until(lambda: (pub.publish(key, Twist(-1.0, 0.0, 0.0)), bool(got))[1]), (
            "no message crossed the router"
        )
        assert sub.decode_errors[key] == 0
        pub.session.put(key, b"\x93not a message")
        pub.publish(key, Twist(7.0, 0.25, -0.5))
        assert wait_until(lambda: any(m.stamp == 7.0 for m in got)), (
            "valid message after garbage lost"
        )
        assert sub.decode_errors[key] == 1
        last = next(m for m in got if m.stamp == 7.0)
        assert (last.v, last.w) == (0.25, -0.5)


@pytest.mark.timeout(60)
def test_liveliness_join_and_leave(router_endpoint: str) -> None:
    fleet = f"t{free_port()}"
    joined: list[str] = []
    left: list[str] = []
    with (
        Bus("coordinator", "c", connect=[router_endpoint], fleet=fleet) as watcher,
        Bus("agent", "early", connect=[router_endpoint], fleet=fleet),
    ):
        watcher.watch_alive("agent", joined.append, left.append)
        assert wait_until(lambda: "early" in joined), f"existing token not reported: {joined}"
        late = Bus("agent", "late", connect=[router_endpoint], fleet=fleet)
        try:
            assert wait_until(lambda: "late" in joined), f"join not observed: {joined}"
        finally:
            late.close()
        assert wait_until(lambda: "late" in left), f"leave not observed: {left}"
        assert "c" not in joined, "watch_alive('agent') reported another role"
        assert "early" not in left


def test_a_handler_failing_as_its_bus_closes_is_no_error(
    router_endpoint: str, caplog: pytest.LogCaptureFixture
) -> None:
    """A coordinator that outlives its bus (a finished test's) may still be running a callback
    when the bus closes; its publishing on the closed session is not an error (one such error,
    logged during the next test, failed a test that asks for none)."""
    bus = Bus("coordinator", "c", connect=[router_endpoint], fleet=f"t{free_port()}")
    bus.close()
    assert bus.closed.is_set()
    with caplog.at_level("ERROR"):
        try:
            raise RuntimeError("session closed")
        except RuntimeError:
            bus.handler_failed("liveliness")
    assert not caplog.records and bus.handler_errors["liveliness"] == 0


@pytest.mark.timeout(60)
def test_implausible_messages_are_counted_by_key_class_and_a_garbage_reply_is_skipped(
    router_endpoint: str, caplog: pytest.LogCaptureFixture
) -> None:
    fleet = f"t{free_port()}"
    with (
        Bus("coordinator", "c", connect=[router_endpoint], fleet=fleet) as bus,
        Bus("sim", "s", connect=[router_endpoint], fleet=fleet) as server,
    ):
        k = bus.keys
        with caplog.at_level("WARNING", logger="fleet.bus"):
            bus.drop_implausible(k.robot("robot-1", "pose"), "robot-1", "a jump")
            bus.drop_implausible(k.robot("robot-2", "pose"), "robot-2", "a jump", n=2)
            bus.drop_implausible(k.clock(), "sim", "far ahead")
        assert bus.implausible == {"robot/*/pose": 3, "sim/clock": 1}
        assert bus.dropped() == (0, 4)
        # the first of each class is logged, naming the sender
        logged = [r.getMessage() for r in caplog.records]
        assert len(logged) == 2 and "from robot-1" in logged[0] and "from sim" in logged[1]

        key = k.sim_report()
        queryable = server.session.declare_queryable(key, lambda q: q.reply(key, b"\x93garbage"))

        def ask() -> bool:
            with pytest.raises(TimeoutError, match="no valid reply"):
                bus.request(key, Request("c"), CoverageSummary, timeout=0.5)
            return bus.decode_errors[key] > 0

        assert wait_until(ask, timeout=10.0), "no reply came"
        assert bus.dropped() == (bus.decode_errors[key], 4)
        queryable.undeclare()
