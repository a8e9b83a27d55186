"""Every key expression and every message on the bus, with its encoding and validation.

Encoding: a msgpack map ``{"_v": SCHEMA_VERSION, "_t": <type tag>, <field>: <value>, ...}``.
numpy arrays travel as raw little-endian bytes of a fixed dtype; their trailing shape is part of
the schema, so only the leading length is implied by the byte count. Decoding is strict: a wrong
version, type tag, field name, field type, array length or a NaN (and ±inf where not allowed)
raises :class:`DecodeError`, which receivers count and log instead of crashing.

Field names follow the ROS messages people know (sensor_msgs/LaserScan, nav_msgs/Odometry,
geometry_msgs/Twist, nav_msgs/Path) where one fits.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import typing
import zlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Annotated, Any, ClassVar, TypeVar

import msgpack
import numpy as np

SCHEMA_VERSION = 6
DEFAULT_FLEET = "default"
# what a robot's control steps were spent on, in the order of RobotStatus.time_s
# (see agents.time_use.step_kind)
TIME_KINDS = ("sweep", "edge", "transit", "turn", "yield", "hold", "escape", "idle", "other")

M = TypeVar("M", bound="Message")


class DecodeError(ValueError):
    """A payload that is not a valid message of the expected type."""


@dataclass(frozen=True)
class Arr:
    """Schema of an array field: dtype, trailing shape, whether ±inf is allowed (NaN never is)."""

    dtype: str
    tail: tuple[int, ...] = ()
    allow_inf: bool = False


@dataclass(frozen=True)
class Num:
    """Schema of a float field that may be infinite (never NaN)."""

    allow_inf: bool = True


# ---------------------------------------------------------------------------------------------
# Key expressions


class Keys:
    """Key expressions of one fleet: ``fleet/<fleet>/...``."""

    def __init__(self, fleet: str = DEFAULT_FLEET) -> None:
        if not fleet or any(c in fleet for c in "/*$?#"):
            raise ValueError(f"invalid fleet name {fleet!r}: no '/', '*', '$', '?' or '#'")
        self.fleet = fleet
        self.root = f"fleet/{fleet}"

    def robot(self, robot: str, topic: str) -> str:
        return f"{self.root}/robot/{robot}/{topic}"

    def clock(self) -> str:
        return f"{self.root}/sim/clock"

    def coverage(self) -> str:
        return f"{self.root}/sim/coverage"

    def collisions(self) -> str:
        return f"{self.root}/sim/collision"

    def sim_spawn(self) -> str:
        return f"{self.root}/sim/spawn"

    def sim_report(self) -> str:
        return f"{self.root}/sim/report"

    def coverage_image(self) -> str:
        return f"{self.root}/sim/coverage_image"

    def plan(self, robot: str) -> str:
        return f"{self.root}/coord/plan/{robot}"

    def coord_state(self) -> str:
        return f"{self.root}/coord/state"

    def call(self) -> str:
        return f"{self.root}/coord/call"

    def bids(self, robot: str) -> str:
        return f"{self.root}/coord/bids/{robot}"

    def all_bids(self) -> str:
        return f"{self.root}/coord/bids/*"

    def award(self, robot: str) -> str:
        return f"{self.root}/coord/award/{robot}"

    def ack(self, robot: str) -> str:
        return f"{self.root}/coord/ack/{robot}"

    def events(self) -> str:
        return f"{self.root}/coord/events"

    def floor_map(self) -> str:
        return f"{self.root}/coord/map"

    def explored_map(self) -> str:
        return f"{self.root}/coord/explored"

    def docks(self) -> str:
        return f"{self.root}/coord/docks"

    def placement(self, robot: str) -> str:
        return f"{self.root}/coord/placement/{robot}"

    def ops(self, verb: str) -> str:
        return f"{self.root}/ops/{verb}"

    def alive(self, role: str, ident: str) -> str:
        return f"{self.root}/alive/{role}/{ident}"

    def alive_all(self, role: str = "*") -> str:
        return f"{self.root}/alive/{role}/*"

    def all_robots(self, topic: str) -> str:
        return f"{self.root}/robot/*/{topic}"

    @staticmethod
    def robot_of(key: str) -> str:
        """The robot id in ``fleet/<f>/robot/<id>/<topic>``, ``.../coord/bids/<id>``,
        ``.../coord/award/<id>``, ``.../coord/ack/<id>`` or ``.../coord/placement/<id>``."""
        parts = str(key).split("/")
        if len(parts) > 3 and parts[2] == "robot":
            return parts[3]
        if len(parts) > 4 and parts[2] == "coord" and parts[3] in _ROBOT_FAMILIES:
            return parts[-1]
        return ""


_ROBOT_FAMILIES = ("bids", "award", "ack", "placement")
_ID_KEYS = ("plan", "award", "ack", "bids", "placement")


def key_class(key: str) -> str:
    """What kind of key ``key`` is, without its fleet and ids: ``fleet/<f>/robot/robot-3/truth``
    → ``robot/*/truth``; an id after ``coord/plan/``, ``award/``, ``ack/``, ``bids/`` or
    ``placement/`` becomes ``*`` too."""
    parts = str(key).split("/")[2:]
    if len(parts) >= 3 and parts[0] == "robot":
        parts[1] = "*"
    elif len(parts) >= 3 and parts[0] == "coord" and parts[1] in _ID_KEYS:
        parts[2:] = ["*"]
    return "/".join(parts)


# ---------------------------------------------------------------------------------------------
# Messages


@dataclass(frozen=True, eq=False)
class Message:
    TYPE: ClassVar[str] = ""

    def encode(self) -> bytes:
        return encode(self)

    def __eq__(self, other: object) -> bool:
        if type(other) is not type(self):
            return NotImplemented
        for f in dataclasses.fields(self):
            a, b = getattr(self, f.name), getattr(other, f.name)
            if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
                if not np.array_equal(a, b):
                    return False
            elif a != b:
                return False
        return True

    __hash__ = None  # type: ignore[assignment]


@dataclass(frozen=True, eq=False)
class Clock(Message):
    """Sim time (s), the requested real-time factor, and whether the sim is waiting for agents."""

    TYPE: ClassVar[str] = "clock"
    stamp: float
    speed: float
    waiting: bool = False


@dataclass(frozen=True, eq=False)
class LaserScan(Message):
    """sensor_msgs/LaserScan; ``ranges`` is inf where there was no return."""

    TYPE: ClassVar[str] = "scan"
    stamp: float
    angle_min: float
    angle_increment: float
    range_min: float
    range_max: float
    ranges: Annotated[np.ndarray, Arr("<f4", (), allow_inf=True)]


@dataclass(frozen=True, eq=False)
class Odometry(Message):
    """nav_msgs/Odometry in the odometry frame (the world frame at spawn) with body velocities."""

    TYPE: ClassVar[str] = "odom"
    stamp: float
    x: float
    y: float
    theta: float
    v: float
    w: float


@dataclass(frozen=True, eq=False)
class BatteryState(Message):
    """sensor_msgs/BatteryState, reduced: ``percentage`` the charge as a fraction of a full
    one (0..1, as ROS gives it), ``charging`` whether a dock is charging it (sim → its
    agent, with robot.battery on)."""

    TYPE: ClassVar[str] = "battery"
    stamp: float
    percentage: float
    charging: bool = False


@dataclass(frozen=True, eq=False)
class Twist(Message):
    """cmd_vel. ``stamp`` is the sim time of the newest sensor data the command answers."""

    TYPE: ClassVar[str] = "cmd_vel"
    stamp: float
    v: float
    w: float


@dataclass(frozen=True, eq=False)
class PoseEstimate(Message):
    """geometry_msgs/PoseWithCovarianceStamped in 2D: covariance over (x, y, theta), row-major."""

    TYPE: ClassVar[str] = "pose"
    stamp: float
    x: float
    y: float
    theta: float
    covariance: Annotated[np.ndarray, Arr("<f8")] = field(default_factory=lambda: np.zeros(9))
    source: str = "odometry"


@dataclass(frozen=True, eq=False)
class TruthPose(Message):
    """The true pose of a robot (sim → dashboard and report only)."""

    TYPE: ClassVar[str] = "truth"
    stamp: float
    x: float
    y: float
    theta: float


@dataclass(frozen=True, eq=False)
class Intent(Message):
    """The next seconds of planned trajectory: rows of (t, x, y) with absolute sim times; and
    how far the robot is along its plan: ``waypoint`` is the index of the waypoint it heads for
    in plan ``plan_id`` (the plan's length once it is done, -1 without a plan)."""

    TYPE: ClassVar[str] = "intent"
    stamp: float
    points: Annotated[np.ndarray, Arr("<f8", (3,))]
    plan_id: int = -1
    waypoint: int = -1


@dataclass(frozen=True, eq=False)
class RobotStatus(Message):
    """What an agent is doing: state, task, progress along its path, and how many waypoints of
    it were given up as unreachable (``skipped``). ``plan_id`` is the plan it drives and
    ``swept`` (one 0/1 per piece of that plan's task, see :class:`Plan`) the pieces it has swept
    by its own pose estimate, so the coordinator knows the exact remainder of the task.
    ``time_s`` is the sim time its control steps have spent on each of ``TIME_KINDS`` since it
    started. ``decode_errors`` and ``implausible`` count the messages its agent dropped as
    malformed and as implausible. ``charge`` is its battery's last reading (a fraction of a
    full charge; -1 without a battery sensor heard) and ``charging`` whether a dock charges it."""

    TYPE: ClassVar[str] = "status"
    stamp: float
    state: str
    task: str
    progress: float
    waypoint: int
    waypoints: int
    distance_m: float
    decode_errors: int = 0
    skipped: int = 0
    plan_id: int = -1
    swept: Annotated[np.ndarray, Arr("|u1")] = field(
        default_factory=lambda: np.zeros(0, dtype=np.uint8)
    )
    time_s: Annotated[np.ndarray, Arr("<f8")] = field(
        default_factory=lambda: np.zeros(0, dtype=np.float64)
    )
    implausible: int = 0
    charge: float = -1.0
    charging: bool = False


@dataclass(frozen=True, eq=False)
class Heartbeat(Message):
    """Sent on wall time by a live agent's own thread, whatever the sim clock does: silence
    for ``coordinator.heartbeat_timeout_s`` means a hung agent. ``ready`` is false while the
    agent cannot take work (it has not localized)."""

    TYPE: ClassVar[str] = "heartbeat"
    stamp: float
    seq: int
    ready: bool


# what a Plan is for: sweeping won tasks, or an errand to a dock or to wait by one
PLAN_KINDS = ("clean", "dock", "wait")
ERRAND_KINDS = ("dock", "wait")


@dataclass(frozen=True, eq=False)
class Plan(Message):
    """A waypoint path (nav_msgs/Path in 2D) for one robot; ``task`` names the job it serves.

    ``sweep_from`` is the index of the waypoint where the sweep begins (before it: the transit
    to it); the segments from there on are the pieces of the tasks it sweeps, in the direction
    driven. A plan may chain several tasks of the robot's queue that follow on without a
    transit: ``chain`` names them in order and ``chain_starts`` gives the waypoint where each
    one's sweep begins (the first is ``sweep_from``; an empty chain means just ``task``).

    A transit planned in space and time (``fleet up --deconfliction``) runs through points of
    transit-graph cells (``fleet.coordinator.transits``) and carries its order of passage
    (``planners.dependencies``): the robot heads for waypoint ``wait_at[i]`` only once robot
    ``wait_for[i]`` has reached waypoint ``wait_passed[i]`` of its plan ``wait_plan[i]`` (or
    drives another plan since).

    ``kind`` says what the plan is for (``PLAN_KINDS``): ``clean`` sweeps the tasks it names,
    tasks of the job the robot has won; ``dock`` takes the robot onto a dock to charge and
    ``wait`` to a waiting spot by a taken dock, errands that sweep nothing and whose ``task`` is
    only a name."""

    TYPE: ClassVar[str] = "plan"
    stamp: float
    plan_id: int
    task: str
    waypoints: Annotated[np.ndarray, Arr("<f8", (2,))]
    sweep_from: int = 0
    chain: list[str] = field(default_factory=list)
    chain_starts: Annotated[np.ndarray, Arr("<i4")] = field(
        default_factory=lambda: np.zeros(0, dtype=np.int32)
    )
    wait_at: Annotated[np.ndarray, Arr("<i4")] = field(
        default_factory=lambda: np.zeros(0, dtype=np.int32)
    )
    wait_for: list[str] = field(default_factory=list)
    wait_plan: Annotated[np.ndarray, Arr("<i4")] = field(
        default_factory=lambda: np.zeros(0, dtype=np.int32)
    )
    wait_passed: Annotated[np.ndarray, Arr("<i4")] = field(
        default_factory=lambda: np.zeros(0, dtype=np.int32)
    )
    kind: str = "clean"

    @property
    def errand(self) -> bool:
        """Whether the plan is an errand to a dock (``dock`` or ``wait``), no work of the job."""
        return self.kind in ERRAND_KINDS


@dataclass(frozen=True, eq=False)
class AuctionCall(Message):
    """Auction round ``round`` (``coord/call``): every lot on sale, K of them, in one message —
    each one's id, its two ends, its estimated cleaning time and area, and what it is worth
    beyond its work in seconds a bid takes off (``gains_s``: an exploring fleet's frontier, its
    expected information; 0 for cleaning). ``bidders`` are the robots in the market when the
    round was called (a bid from another is refused as from a robot not in the market; empty:
    anyone). Agents answer with one :class:`Bids`."""

    TYPE: ClassVar[str] = "auction_call"
    stamp: float
    round: int
    lots: list[str]
    entries: Annotated[np.ndarray, Arr("<f8", (2,))]
    exits: Annotated[np.ndarray, Arr("<f8", (2,))]
    times_s: Annotated[np.ndarray, Arr("<f8")]
    areas_m2: Annotated[np.ndarray, Arr("<f8")]
    gains_s: Annotated[np.ndarray, Arr("<f8")]
    bidders: list[str] = field(default_factory=list)

    def consistent(self) -> bool:
        """Whether every per-lot array has one entry per lot."""
        k = len(self.lots)
        arrays = (self.entries, self.exits, self.times_s, self.areas_m2, self.gains_s)
        return all(len(a) == k for a in arrays)


@dataclass(frozen=True, eq=False)
class Bids(Message):
    """A robot's prices for the lots of round ``round`` (``coord/bids/<robot>``), all in one
    message, in the call's order less the lots it already holds: per lot, the marginal seconds
    of adding it to what the robot has won, its whole committed time with it, and which end it
    would enter by (``reverse``: the lot's exit; 0/1). ``declined`` (0/1): the robot cannot do
    the lot and then get to a dock on its charge; it answers, so the round need not wait for
    it, but never wins that lot. A robot with nothing to offer answers with no lots."""

    TYPE: ClassVar[str] = "bids"
    stamp: float
    round: int
    robot: str
    lots: list[str]
    marginal_s: Annotated[np.ndarray, Arr("<f8")]
    total_s: Annotated[np.ndarray, Arr("<f8")]
    reverse: Annotated[np.ndarray, Arr("<u1")]
    declined: Annotated[np.ndarray, Arr("<u1")]

    def consistent(self) -> bool:
        """Whether every per-lot array has one entry per lot."""
        k = len(self.lots)
        arrays = (self.marginal_s, self.total_s, self.reverse, self.declined)
        return all(len(a) == k for a in arrays)


@dataclass(frozen=True, eq=False)
class Docks(Message):
    """The world's docks, served by the coordinator on ``coord/docks``: rows of (x, y,
    theta), the pose of a robot standing on each (facing away from it); none, a world without
    docks."""

    TYPE: ClassVar[str] = "docks"
    stamp: float
    poses: Annotated[np.ndarray, Arr("<f8", (3,))]


@dataclass(frozen=True, eq=False)
class Award(Message):
    """A robot's whole queue of won tasks (``coord/award/<robot>``), in driving order, each
    with its ends as it will drive them and its time; ``seq`` grows with every change. A task
    missing from a newer award has gone elsewhere; an empty queue means no work."""

    TYPE: ClassVar[str] = "award"
    stamp: float
    seq: int
    robot: str
    tasks: list[str]
    entries: Annotated[np.ndarray, Arr("<f8", (2,))]
    exits: Annotated[np.ndarray, Arr("<f8", (2,))]
    times_s: Annotated[np.ndarray, Arr("<f8")]


@dataclass(frozen=True, eq=False)
class AwardAck(Message):
    """The agent has taken award ``seq`` (``coord/ack/<robot>``)."""

    TYPE: ClassVar[str] = "award_ack"
    stamp: float
    seq: int
    robot: str


@dataclass(frozen=True, eq=False)
class FleetEvent(Message):
    """A change of the job for views and reports (``coord/events``): ``kind`` is one of
    planned (tasks made), joined, lost, reopened (a lost robot's task back in the market),
    rejoined, awarded, reassigned (a reopened task won again), withdrawn (an unstarted task
    taken back to balance the fleet), done (a task), finished (the job), resumed (a restarted
    coordinator), auction (one auction ended: how many lots, how long); ``wall`` is Unix
    time."""

    TYPE: ClassVar[str] = "event"
    stamp: float
    wall: float
    kind: str
    robot: str
    task: str
    detail: str


@dataclass(frozen=True, eq=False)
class OpsRequest(Message):
    """An operator's request to the process that launched the fleet (``ops/<verb>``), e.g.
    respawn of ``name``; for ``dock``, the dock to send it to (``dock``, an index into the
    world's docks; −1: the one the coordinator picks)."""

    TYPE: ClassVar[str] = "ops_request"
    sender: str
    verb: str
    name: str
    dock: int = -1


@dataclass(frozen=True, eq=False)
class OpsReply(Message):
    TYPE: ClassVar[str] = "ops_reply"
    ok: bool
    error: str


@dataclass(frozen=True, eq=False)
class FleetState(Message):
    """The coordinator's view of the job: its phase (planning: making the first plan, which
    the simulator's clock waits for; gathering, auction, cleaning, done, or incomplete:
    finished with work no robot could reach), the robots it plans for, those with
    no work left, those lost, and how many tasks are open (not held by a live robot),
    assigned, done and left out (blocked by a lost robot's body, or unreachable); and how many
    messages it has dropped as malformed (``decode_errors``) and as implausible."""

    TYPE: ClassVar[str] = "fleet_state"
    stamp: float
    phase: str
    robots: list[str]
    done: list[str]
    lost: list[str] = field(default_factory=list)
    tasks_open: int = 0
    tasks_assigned: int = 0
    tasks_done: int = 0
    tasks_left_out: int = 0
    decode_errors: int = 0
    implausible: int = 0


@dataclass(frozen=True, eq=False)
class Collision(Message):
    """A contact: ``kind`` is "wall" or "robot"; ``other`` is the other robot or ""."""

    TYPE: ClassVar[str] = "collision"
    stamp: float
    kind: str
    robot: str
    other: str
    x: float
    y: float


@dataclass(frozen=True, eq=False)
class CoverageSummary(Message):
    """Ground-truth cleaning progress and per-robot counters (sim → dashboard and report), and
    how many messages the simulator has dropped as malformed and as implausible. With
    robot.battery on, per robot too: its ``charge`` now and ``min_charge`` (fractions), the
    ``charges`` it began on a dock, its ``charging_s`` (sim s) and whether it stands ``docked``
    (1) now; empty arrays with batteries off."""

    TYPE: ClassVar[str] = "coverage"
    stamp: float
    wall_s: float
    coverage: float
    repetition: float
    cleanable_m2: float
    robots: list[str]
    path_length_m: Annotated[np.ndarray, Arr("<f8")]
    turns: Annotated[np.ndarray, Arr("<i4")]
    wall_collisions: Annotated[np.ndarray, Arr("<i4")]
    robot_collisions: Annotated[np.ndarray, Arr("<i4")]
    decode_errors: int = 0
    implausible: int = 0
    charge: Annotated[np.ndarray, Arr("<f8")] = field(default_factory=lambda: np.zeros(0))
    min_charge: Annotated[np.ndarray, Arr("<f8")] = field(default_factory=lambda: np.zeros(0))
    charges: Annotated[np.ndarray, Arr("<i4")] = field(
        default_factory=lambda: np.zeros(0, dtype=np.int32)
    )
    charging_s: Annotated[np.ndarray, Arr("<f8")] = field(default_factory=lambda: np.zeros(0))
    docked: Annotated[np.ndarray, Arr("|u1")] = field(
        default_factory=lambda: np.zeros(0, dtype=np.uint8)
    )


@dataclass(frozen=True, eq=False)
class Request(Message):
    """A query that carries no arguments but who asks (report, coverage image, current plan)."""

    TYPE: ClassVar[str] = "request"
    sender: str


@dataclass(frozen=True, eq=False)
class SpawnRequest(Message):
    """Place robot ``robot`` at (x, y, theta); with ``rejoin`` a respawned agent takes over the
    body its robot left in the world instead (the pose is then not used). With ``own_frame``
    the robot's odometry starts at (0, 0, 0) where it is placed, as a robot's wheel odometry
    starts wherever it is switched on; otherwise at the pose (a robot that knows its dock)."""

    TYPE: ClassVar[str] = "spawn"
    robot: str
    x: float
    y: float
    theta: float
    rejoin: bool = False
    own_frame: bool = False


@dataclass(frozen=True, eq=False)
class SpawnReply(Message):
    """``ok`` false with ``error`` set when the pose is not free (or, on a rejoin, there is no
    body to rejoin); x, y, theta the pose granted (on a rejoin: the request's, never the body's
    true pose, which a robot cannot know); ``stamp`` the sim time when it answered, from
    which the agent's clock starts."""

    TYPE: ClassVar[str] = "spawn_reply"
    ok: bool
    error: str
    x: float
    y: float
    theta: float
    stamp: float = -1.0


@dataclass(frozen=True, eq=False)
class CoverageImage(Message):
    """The ground-truth visit-count grid of the main brushes (uint16, row 0 = lowest y), the
    cleanable mask, and the cells the robots' side brushes have touched (empty when the robots
    have none)."""

    TYPE: ClassVar[str] = "coverage_image"
    stamp: float
    resolution: float
    origin_x: float
    origin_y: float
    rows: int
    cols: int
    visits: Annotated[np.ndarray, Arr("<u2")]
    cleanable: Annotated[np.ndarray, Arr("|u1")]
    side: Annotated[np.ndarray, Arr("|u1")] = field(
        default_factory=lambda: np.zeros(0, dtype=np.uint8)
    )

    def side_mask(self) -> np.ndarray:
        """(rows, cols) the cells a side brush has touched."""
        if not len(self.side):
            return np.zeros((self.rows, self.cols), dtype=bool)
        return self.side.reshape(self.rows, self.cols) > 0

    def swept(self) -> np.ndarray:
        """(rows, cols) the cells either brush has swept."""
        return (self.visits.reshape(self.rows, self.cols) > 0) | self.side_mask()


@dataclass(frozen=True, eq=False)
class MapPatches(Message):
    """Changed tiles of a robot's SLAM map (nav_msgs/OccupancyGrid values: int8, −1 unknown,
    0..100 occupancy percent), zlib-compressed.

    The map is ``rows`` × ``cols`` cells of ``resolution`` m, cell (0, 0) at the origin, row 0 =
    lowest y. Patch i is the ``tile`` × ``tile`` block whose lower-left cell is
    (``patch_rows[i]``, ``patch_cols[i]``); ``data`` is the zlib stream of all blocks' cells,
    block after block, row-major. ``full`` means the receiver must drop its copy first (first
    message, or the map grew). ``seq`` counts messages so a receiver can notice a gap and ask
    for the whole map. ``own_frame`` means the map is in the robot's own frame, not yet the
    fleet's: the robot started with no known pose and has not been placed (:class:`Placement`).
    """

    TYPE: ClassVar[str] = "map_patches"
    stamp: float
    seq: int
    full: bool
    rows: int
    cols: int
    resolution: float
    origin_x: float
    origin_y: float
    tile: int
    patch_rows: Annotated[np.ndarray, Arr("<i4")]
    patch_cols: Annotated[np.ndarray, Arr("<i4")]
    data: Annotated[np.ndarray, Arr("|u1")]
    own_frame: bool = False

    @classmethod
    def pack(
        cls,
        stamp: float,
        seq: int,
        full: bool,
        shape: tuple[int, int],
        resolution: float,
        origin: tuple[float, float],
        tile: int,
        blocks: Sequence[tuple[int, int, np.ndarray]],
        own_frame: bool = False,
    ) -> MapPatches:
        """Build a message from (row, col, tile × tile int8 block) triples."""
        cells = b"".join(np.ascontiguousarray(b, dtype=np.int8).tobytes() for _, _, b in blocks)
        return cls(
            stamp,
            seq,
            full,
            shape[0],
            shape[1],
            resolution,
            origin[0],
            origin[1],
            tile,
            np.array([r for r, _, _ in blocks], dtype=np.int32),
            np.array([c for _, c, _ in blocks], dtype=np.int32),
            np.frombuffer(zlib.compress(cells, 6), dtype=np.uint8),
            own_frame,
        )

    @functools.cached_property
    def blocks(self) -> np.ndarray:
        """The patches' cells as an int8 array (patches, tile, tile), inflated once (decode
        checks them); raises DecodeError if the data does not hold exactly that many cells."""
        n = len(self.patch_rows) * self.tile * self.tile
        inflater = zlib.decompressobj()
        try:
            raw = inflater.decompress(self.data.tobytes(), n + 1)
        except zlib.error as e:
            raise DecodeError(f"{self.TYPE}.data: not a zlib stream ({e})") from None
        if len(raw) != n or not inflater.eof:
            raise DecodeError(f"{self.TYPE}.data: expected {n} cells after decompression")
        return np.frombuffer(raw, dtype=np.int8).reshape(-1, self.tile, self.tile).copy()


@dataclass(frozen=True, eq=False)
class Placement(Message):
    """Where a robot that started with no known pose stands in the fleet's frame
    (``coord/placement/<robot>``): ``x``, ``y``, ``theta`` carry its own map frame into the
    fleet's (a point p of its map lies at R(theta)·p + (x, y)), found by matching its map with
    the merged one; ``score`` and ``overlap_m2`` are the match's (``planners.map_match``)."""

    TYPE: ClassVar[str] = "placement"
    stamp: float
    robot: str
    x: float
    y: float
    theta: float
    score: float
    overlap_m2: float


MESSAGES: dict[str, type[Message]] = {
    cls.TYPE: cls
    for cls in (
        Clock,
        LaserScan,
        Odometry,
        BatteryState,
        Twist,
        PoseEstimate,
        TruthPose,
        Intent,
        RobotStatus,
        Plan,
        FleetState,
        Collision,
        CoverageSummary,
        Request,
        SpawnRequest,
        SpawnReply,
        CoverageImage,
        MapPatches,
        Placement,
        Heartbeat,
        AuctionCall,
        Bids,
        Docks,
        Award,
        AwardAck,
        FleetEvent,
        OpsRequest,
        OpsReply,
    )
}


# ---------------------------------------------------------------------------------------------
# Encoding


@dataclass(frozen=True)
class _FieldSpec:
    name: str
    kind: Any
    meta: Any


_SPECS: dict[type, tuple[_FieldSpec, ...]] = {}


def _specs(cls: type[Message]) -> tuple[_FieldSpec, ...]:
    specs = _SPECS.get(cls)
    if specs is None:
        hints = typing.get_type_hints(cls, include_extras=True)
        out = []
        for f in dataclasses.fields(cls):
            tp = hints[f.name]
            meta = None
            if typing.get_origin(tp) is Annotated:
                tp, meta = typing.get_args(tp)[0], typing.get_args(tp)[1]
            out.append(_FieldSpec(f.name, tp, meta))
        specs = _SPECS[cls] = tuple(out)
    return specs


def _encode_value(spec: _FieldSpec, value: Any) -> Any:
    if isinstance(spec.meta, Arr):
        arr = np.ascontiguousarray(value, dtype=np.dtype(spec.meta.dtype))
        return arr.tobytes()
    if spec.kind is float:
        return float(value)
    if spec.kind is int:
        return int(value)
    if spec.kind is list[str]:
        return list(value)
    return value


def encode(msg: Message) -> bytes:
    """Serialize a message; see the module docstring for the format."""
    out: dict[str, Any] = {"_v": SCHEMA_VERSION, "_t": msg.TYPE}
    for spec in _specs(type(msg)):
        out[spec.name] = _encode_value(spec, getattr(msg, spec.name))
    return msgpack.packb(out, use_bin_type=True)


def _decode_value(cls: type[Message], spec: _FieldSpec, raw: Any) -> Any:
    where = f"{cls.TYPE}.{spec.name}"
    if isinstance(spec.meta, Arr):
        if not isinstance(raw, bytes):
            raise DecodeError(f"{where}: expected bytes, got {type(raw).__name__}")
        dt = np.dtype(spec.meta.dtype)
        per_row = dt.itemsize * math.prod(spec.meta.tail)
        if len(raw) % per_row:
            raise DecodeError(
                f"{where}: {len(raw)} bytes is not a whole number of {per_row}-byte rows"
            )
        arr = np.frombuffer(raw, dtype=dt).reshape((-1, *spec.meta.tail)).copy()
        if arr.dtype.kind == "f":
            if np.isnan(arr).any():
                raise DecodeError(f"{where}: NaN is not allowed")
            if not spec.meta.allow_inf and np.isinf(arr).any():
                raise DecodeError(f"{where}: infinite values are not allowed")
        return arr.astype(dt.newbyteorder("="))
    if spec.kind is float:
        if isinstance(raw, bool) or not isinstance(raw, (int, float)):
            raise DecodeError(f"{where}: expected a number, got {type(raw).__name__}")
        value = float(raw)
        if math.isnan(value):
            raise DecodeError(f"{where}: NaN is not allowed")
        allow_inf = isinstance(spec.meta, Num) and spec.meta.allow_inf
        if math.isinf(value) and not allow_inf:
            raise DecodeError(f"{where}: infinite values are not allowed")
        return value
    if spec.kind is int:
        if isinstance(raw, bool) or not isinstance(raw, int):
            raise DecodeError(f"{where}: expected an integer, got {type(raw).__name__}")
        return raw
    if spec.kind is bool:
        if not isinstance(raw, bool):
            raise DecodeError(f"{where}: expected a boolean, got {type(raw).__name__}")
        return raw
    if spec.kind is str:
        if not isinstance(raw, str):
            raise DecodeError(f"{where}: expected a string, got {type(raw).__name__}")
        return raw
    if spec.kind == list[str]:
        # the types of a long list at C speed: a call's 500 lot ids are decoded by every robot
        if not isinstance(raw, list) or not set(map(type, raw)) <= {str}:
            raise DecodeError(f"{where}: expected a list of strings")
        return list(raw)
    raise DecodeError(f"{where}: unsupported field type")  # pragma: no cover - schema bug


def decode(payload: bytes | bytearray | memoryview, cls: type[M]) -> M:
    """Parse ``payload`` as a message of type ``cls``; raises DecodeError on any mismatch."""
    try:
        data = msgpack.unpackb(bytes(payload), raw=False, strict_map_key=True)
    except Exception as e:
        raise DecodeError(f"{cls.TYPE}: not a msgpack payload ({type(e).__name__}: {e})") from None
    if not isinstance(data, dict):
        raise DecodeError(f"{cls.TYPE}: expected a map, got {type(data).__name__}")
    version = data.get("_v")
    if type(version) is not int or version != SCHEMA_VERSION:
        raise DecodeError(f"{cls.TYPE}: schema version {version!r}, expected {SCHEMA_VERSION}")
    if data.get("_t") != cls.TYPE:
        raise DecodeError(f"expected a {cls.TYPE!r} message, got type {data.get('_t')!r}")
    specs = _specs(cls)
    names = {s.name for s in specs}
    extra = sorted(str(k) for k in data if k not in names and k not in ("_v", "_t"))
    if extra:
        raise DecodeError(f"{cls.TYPE}: unknown field {extra[0]!r}")
    kwargs = {}
    for spec in specs:
        if spec.name not in data:
            raise DecodeError(f"{cls.TYPE}.{spec.name}: missing")
        kwargs[spec.name] = _decode_value(cls, spec, data[spec.name])
    try:
        msg = cls(**kwargs)
    except (TypeError, ValueError) as e:
        raise DecodeError(f"{cls.TYPE}: {e}") from None
    _check_shapes(msg)
    return msg


def _check_shapes(msg: Message) -> None:
    """Cross-field checks that the schema alone does not express."""
    if isinstance(msg, CoverageSummary):
        n = len(msg.robots)
        for name in ("path_length_m", "turns", "wall_collisions", "robot_collisions"):
            if len(getattr(msg, name)) != n:
                raise DecodeError(
                    f"coverage.{name}: {len(getattr(msg, name))} values for {n} robots"
                )
    elif isinstance(msg, PoseEstimate) and msg.covariance.shape != (9,):
        raise DecodeError("pose.covariance: expected 9 values (a row-major 3×3 matrix)")
    elif isinstance(msg, CoverageImage):
        cells = msg.rows * msg.cols
        if msg.rows < 0 or msg.cols < 0 or len(msg.visits) != cells or len(msg.cleanable) != cells:
            raise DecodeError(f"coverage_image: arrays do not hold rows × cols = {cells} cells")
        if len(msg.side) not in (0, cells):
            raise DecodeError(f"coverage_image.side: {len(msg.side)} cells, not 0 or {cells}")
    elif isinstance(msg, MapPatches):
        _check_map_patches(msg)
    elif isinstance(msg, Award):
        n = len(msg.tasks)
        if len(msg.entries) != n or len(msg.exits) != n or len(msg.times_s) != n:
            raise DecodeError(f"award: entries, exits and times_s must each have {n} rows")
    elif isinstance(msg, Plan):
        _check_plan(msg)


def _check_plan(msg: Plan) -> None:
    """A plan's indices within its path, its chain's starts one per task, and its parallel
    ``wait_*`` fields (the order of passage) one entry per wait each."""
    last = max(len(msg.waypoints) - 1, 0)
    if not 0 <= msg.sweep_from <= last:
        raise DecodeError(f"plan.sweep_from: {msg.sweep_from} is not a waypoint index")
    starts = msg.chain_starts
    if len(starts) != len(msg.chain):
        raise DecodeError(f"plan.chain_starts: {len(starts)} starts for {len(msg.chain)} tasks")
    if len(starts) and (
        starts[0] != msg.sweep_from or np.any(np.diff(starts) < 0) or starts[-1] > last
    ):
        raise DecodeError("plan.chain_starts: must begin at sweep_from and rise within the path")
    n = len(msg.wait_at)
    for name in ("wait_for", "wait_plan", "wait_passed"):
        if len(getattr(msg, name)) != n:
            raise DecodeError(
                f"plan.{name}: {len(getattr(msg, name))} entries for {n} in wait_at"
                " (the order of passage is one row per wait)"
            )


MAX_MAP_TILE = 1024
MAX_MAP_CELLS = 1 << 20


def _check_map_patches(msg: MapPatches) -> None:
    where = msg.TYPE
    if not (
        1 <= msg.tile <= MAX_MAP_TILE
        and 0 <= msg.rows <= MAX_MAP_CELLS
        and 0 <= msg.cols <= MAX_MAP_CELLS
    ):
        raise DecodeError(f"{where}: tile or map size out of range")
    if msg.rows % msg.tile or msg.cols % msg.tile:
        raise DecodeError(f"{where}: map {msg.rows} × {msg.cols} is not whole tiles of {msg.tile}")
    if not msg.resolution > 0:
        raise DecodeError(f"{where}.resolution: must be > 0")
    if len(msg.patch_rows) != len(msg.patch_cols):
        raise DecodeError(f"{where}: {len(msg.patch_rows)} patch rows, {len(msg.patch_cols)} cols")
    for name, arr, limit in (
        ("patch_rows", msg.patch_rows, msg.rows),
        ("patch_cols", msg.patch_cols, msg.cols),
    ):
        if len(arr) and (arr.min() < 0 or arr.max() > limit - msg.tile or (arr % msg.tile).any()):
            raise DecodeError(f"{where}.{name}: patches must be whole tiles inside the map")
    blocks = msg.blocks
    if len(blocks) and (blocks.min() < -1 or blocks.max() > 100):
        raise DecodeError(f"{where}.data: cells must be -1 (unknown) or 0..100")
