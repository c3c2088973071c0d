"""Typed messages of the ARROCH wire format (DESIGN §4).

Every message carries the envelope ``v`` (schema major version), ``type``, ``src`` (sender id),
``seq`` (per-sender counter) and ``stamp`` (seconds on the site clock). ``src``, ``seq`` and
``stamp`` default to empty values so code can build a message and let the publisher
(:class:`runtime.service.Service`) stamp it.

Messages are ``msgspec`` Structs: each field's type carries its limits (:mod:`protocol.schema`),
which msgspec checks as it decodes (:mod:`protocol.codec`). ``type`` is the Struct's tag (the
class name); ``v`` is an ordinary field whose default is the class's ``VERSION``.

Trajectories travel as rows ``[t, x, y, theta]`` rather than maps: about 3x cheaper to
encode, and the row length is checked on decode.
"""

from typing import Annotated, Any, ClassVar

from msgspec import UNSET, Meta, Struct, UnsetType, field

from .actions import Action
from .asp_terms import ConstraintTerms
from .errors import ProtocolError
from .events import EVENT_KINDS, EventData, event_data
from .schema import Choice, Float, Ident, Int, List, Map, Rows, Scalar, Str

# Bounds shared by several messages. Site coordinates are metres; 10 km covers any building.
COORD = 10_000.0
ANGLE = 1_000.0  # radians; unwrapped headings stay far below this
TIME = 1e10  # seconds on the site clock (sim time from 0, or Unix time)
MAX_TRAJECTORY = 20_000

ACTIONS = tuple(a.value for a in Action)  # the domain's actions, as robots, planner and simulator name them
ROBOT_STATES = ("idle", "moving", "waiting_at_door", "loading", "unloading", "done", "failed")
PRIMITIVE_KINDS = ("line", "polyline", "polygon", "circle", "text", "arrow")
LINE_STYLES = ("solid", "xray", "dashed")
AWAITING = ("", "plan", "feedback", "command", "camera")  # what a paused lockstep simulator waits for (Clock)
# What a study participant does (ParticipantAction.act); see that class.
PARTICIPANT_ACTS = (
    "go_to_door",
    "open_door",
    "back_to_desk",
    "task_done",
    "view",
    "puzzle_move",
    "feedback",
    "consent",
    "mark",
)
PAGE_VIEWS = ("", "puzzle", "ar", "map")
HUMAN_PLACES = ("desk", "to_door", "at_door", "back")  # HumanState.place
QUESTIONNAIRES = ("arroch-q", "nasa-tlx")


class Message(Struct, kw_only=True, tag_field="type", tag=True):
    """Envelope fields common to all messages. ``TYPE`` is the class name, which msgspec writes
    as ``type`` (the tag)."""

    TYPE: ClassVar[str] = ""
    VERSION: ClassVar[int] = 1
    MAX_SIZE: ClassVar[int] = 1024 * 1024  # encoded bytes accepted on decode

    def __init_subclass__(cls, **kwargs: object) -> None:
        super().__init_subclass__(**kwargs)
        cls.TYPE = cls.__name__

    v: int = 1  # the schema major version; the decoder refuses one above the class's VERSION
    src: Str(128) = ""
    seq: Int(0, 2**63 - 1) = 0
    stamp: Float(-TIME, TIME) = 0.0


# ---------------------------------------------------------------------------- nested records


class PlanStep(Struct, kw_only=True):
    """One action of a robot's plan, with its planned start and end on the site clock."""

    action: Choice(*ACTIONS)
    args: List(Ident, 8) = []
    start: Float(-TIME, TIME)
    end: Float(-TIME, TIME)
    action_id: Int(0, 2**31) = 0


class PlannedOpening(Struct, kw_only=True):
    """A door opening the plan asks of the human: door ``door`` open during [start, end)."""

    door: Ident
    start: Float(-TIME, TIME)
    end: Float(-TIME, TIME)
    robots: List(Ident, 1000) = []


class Constraint(Struct, kw_only=True):
    """One active constraint: the library entry and its validated parameters, its window, its ASP,
    and what that ASP states as fields (``terms``: the planner reads them, never the text; None
    from a sender older than them)."""

    id: Ident
    kind: Ident
    params: Map(Scalar, 32) = {}
    start: Float(-TIME, TIME)
    end: Float(-TIME, TIME)
    asp: Str(65536)
    origin: Str(128) = ""  # who asked for it (Feedback src)
    terms: ConstraintTerms | None = None


LIBRARY_MAX_ENTRIES = 100
LIBRARY_MAX_PARAMS = 16
LIBRARY_MAX_CHOICES = 1000
LIBRARY_MAX_LABEL = 80
LIBRARY_MAX_HELP = 300
LIBRARY_PARAM_TYPES = ("int", "door", "room", "opening", "constraint")
LIBRARY_EFFECTS = ("add", "cancel")
LibraryId = Ident  # an entry's, a parameter's or a choice's id
Label = Str(LIBRARY_MAX_LABEL)


class LibraryParam(Struct, kw_only=True):
    """A parameter of a library entry: ``min``/``max`` for an int, the site's ``choices`` for a
    door/room/opening (``source`` "site"), none for a constraint id (``source`` "constraints", the
    choices are the live ConstraintSet's ids)."""

    name: LibraryId
    type: Choice(*LIBRARY_PARAM_TYPES)
    label: Label
    help: Str(LIBRARY_MAX_HELP) = ""
    min: int | UnsetType = UNSET
    max: int | UnsetType = UNSET
    choices: List(LibraryId, LIBRARY_MAX_CHOICES) | None | UnsetType = UNSET
    source: Choice("site", "constraints") | UnsetType = UNSET


class LibraryWindow(Struct, kw_only=True):
    """An entry's window: the int parameter ``param`` gives its minutes, or it lasts ``minutes``
    (one of the two: the restrictor's library loader checks that, and that an int parameter's range
    is ordered, when it reads the file)."""

    param: LibraryId | UnsetType = UNSET
    minutes: int | UnsetType = UNSET


class LibraryEntry(Struct, kw_only=True):
    """One entry as a client shows it; ``usable``: every symbol parameter has a choice on the site."""

    id: LibraryId
    label: Label
    help: Str(LIBRARY_MAX_HELP) = ""
    effect: Choice(*LIBRARY_EFFECTS)
    window: LibraryWindow | None = None
    usable: bool
    params: List(LibraryParam, LIBRARY_MAX_PARAMS) = []


class Primitive(Struct, kw_only=True):
    """A 2-D drawing instruction in image pixels, for thin clients."""

    kind: Choice(*PRIMITIVE_KINDS)
    points: Rows(2, 4096, -1e6, 1e6) = []
    color: List(Int(0, 255), 4) = field(default_factory=lambda: [255, 255, 255, 255])
    width: Float(0.0, 100.0) = 2.0
    radius: Float(0.0, 1e5) = 0.0
    text: Str(256) = ""
    style: Choice(*LINE_STYLES) = "solid"
    layer: Str(64) = ""  # e.g. robot id, "status", "door"


# ---------------------------------------------------------------------------- messages


class Clock(Message):
    time: Float(0.0, TIME)
    mode: Choice("realtime", "rate", "lockstep", "wall") = "realtime"
    rate: Float(0.0, 1e6) = 1.0
    world_version: Int(0, 2**63 - 1) = 0
    paused: bool = False
    # Lockstep, while paused: what the simulator waits for - "plan" (one answering world_version and
    # at least constraints_version), "feedback" (the ack of the human's feedback), "command" (a
    # robot's command of the plan it has), "camera" (the overlay of a frame it holds); "" otherwise.
    # The planner plans the moment the simulator waits for a plan, and holds while it waits for a
    # feedback's ack (a new constraint set follows).
    awaiting: Choice(*AWAITING) = ""
    constraints_version: Int(0, 2**63 - 1) = 0


class RobotPose(Message):
    robot: Ident
    x: Float(-COORD, COORD)
    y: Float(-COORD, COORD)
    theta: Float(-ANGLE, ANGLE)
    # "v" is the envelope's schema version, so the linear velocity travels as "vel".
    vel: Float(-100.0, 100.0) = 0.0
    omega: Float(-100.0, 100.0) = 0.0


class RobotStatus(Message):
    robot: Ident
    state: Choice(*ROBOT_STATES)
    plan_id: Int(0, 2**63 - 1) = 0
    action_id: Int(0, 2**31) = 0  # 0: no action
    action: Str(32) = ""
    args: List(Ident, 8) = []
    progress: Float(0.0, 1.0) = 0.0
    carrying: List(Ident, 1000) = []
    delivered: List(Ident, 100_000) = []
    waiting_door: Str(64) = ""
    detail: Str(512) = ""
    world_version: Int(0, 2**63 - 1) = 0


class RobotCommand(Message):
    robot: Ident
    plan_id: Int(0, 2**63 - 1)
    action_id: Int(0, 2**31)
    action: Choice(*ACTIONS, "stop")
    args: List(Ident, 8) = []
    trajectory: Rows(4, MAX_TRAJECTORY, -TIME, TIME) = []
    duration: Float(0.0, 1e6) = 0.0  # for load/unload: time spent in place after the path


MAX_WAY = 1000  # points of a way a robot asks another to clear (3 m at 0.1 m, and the ways a chain adds)


class DoorwayHold(Struct, kw_only=True):
    """An opening a robot holds for its crossing (one crossing robot at a time), where its centre was
    when it got it, and whether it has been in the opening's lane since."""

    opening: Ident
    at: List(Float(-COORD, COORD), 2, lengths=(2,))
    entered: bool = False


class MakeWayAsk(Struct, kw_only=True):
    """A robot's request that robot ``asked`` get off ``way`` (points [x, y] of the asker's way
    ahead), asked at ``since`` and last renewed at ``renewed``; ``root``: the robot whose way a chain
    of requests clears ("" when it is the asker's own)."""

    asked: Ident
    way: Rows(2, MAX_WAY, -COORD, COORD) = []
    since: Float(-TIME, TIME)
    renewed: Float(-TIME, TIME)
    root: Ident = ""


class RobotTraffic(Message):
    """What one robot's executor tells the others about the traffic rules it follows
    (runtime/executor/traffic.py): the robot it stops for (right of way), the robot it waits for
    (queues and cycles), the opening its gothrough crosses and whether it asks for it or holds it,
    and the requests to make way it made. Robot processes (``arroch robot``) publish it on every
    change and once a second, and merge the others' into their executor's tables; "" means none."""

    robot: Ident
    blocked_by: Ident = ""
    waits_for: Ident = ""
    crossing: Ident = ""  # the opening the robot's command goes through
    asking: Ident = ""  # the opening it asks to cross (it waits for it)
    asked_at: Float(-TIME, TIME) = 0.0  # site time it asked
    holds: List(DoorwayHold, 8) = []
    asks: List(MakeWayAsk, 32) = []


class TeamPlan(Message):
    plan_id: Int(0, 2**63 - 1)
    world_version: Int(0, 2**63 - 1) = 0
    constraints_version: Int(0, 2**63 - 1) = 0
    method: Str(32) = "iidp"
    makespan: Float(0.0, TIME) = 0.0
    door_openings: Int(0, 2**31) = 0
    solve_time: Float(0.0, 1e6) = 0.0
    iterations: Int(0, 2**31) = 0
    robots: Map(list[PlanStep], 10_000) = {}
    openings: List(PlannedOpening, 10_000) = []
    diagnostic: Str(4096) = ""


class Intent(Message):
    robot: Ident
    plan_id: Int(0, 2**63 - 1) = 0
    action_id: Int(0, 2**31) = 0
    action: Str(32) = ""
    args: List(Ident, 8) = []
    trajectory: Rows(4, MAX_TRAJECTORY, -TIME, TIME) = []


class DoorState(Message):
    door: Ident
    open: bool
    by: Str(64) = ""  # "human", a robot id, "sensor", or ""
    until: Float(0.0, TIME) = 0.0  # when a human opening is due to end; 0 if unknown
    world_version: Int(0, 2**63 - 1) = 0


class Feedback(Message):
    """A choice from the constraint library. ``params`` holds the entry's parameters, unchecked here:
    the restrictor validates them against the library and the site."""

    kind: Str(64)
    params: Map(Scalar, 32) = {}


class FeedbackAck(Message):
    to: Str(128)  # the Feedback's src
    feedback_seq: Int(0, 2**63 - 1)
    accepted: bool
    reason: Str(1024) = ""
    constraint_id: Str(64) = ""
    constraints_version: Int(0, 2**63 - 1) = 0


class ConstraintSet(Message):
    version: Int(0, 2**63 - 1)
    constraints: List(Constraint, 10_000) = []
    asp: Str(1024 * 1024) = ""  # all active constraints' ASP, ready for the solver


class ConstraintLibrary(Message):
    """A restrictor's answer on ``constraints/library``: which site its choices are for, and its
    entries (:mod:`protocol.constraint_library`)."""

    MAX_SIZE: ClassVar[int] = 256 * 1024  # the packaged library for the office site is ~2 kB
    site: Str(64)
    entries: List(LibraryEntry, LIBRARY_MAX_ENTRIES) = []


class CameraFrame(Message):
    MAX_SIZE: ClassVar[int] = 16 * 1024 * 1024
    camera: Ident
    jpeg: Annotated[bytes, Meta(max_length=16 * 1024 * 1024)]
    width: Int(1, 16384)
    height: Int(1, 16384)
    intrinsics: List(Float(-1e6, 1e6), 4, lengths=(4,))  # fx, fy, cx, cy
    distortion: List(Float(-1e6, 1e6), 5, lengths=(5,)) = field(default_factory=lambda: [0.0] * 5)  # k1 k2 p1 p2 k3
    # The device's gravity at capture in the camera frame (OpenCV axes, pointing down, m/s²), as its
    # accelerometer measured it; empty when unknown. Optional: frames without it decode as before.
    gravity: List(Float(-1000.0, 1000.0), 3, lengths=(0, 3)) = []


class CameraTruth(Message):
    camera: Ident
    frame_seq: Int(0, 2**63 - 1)  # seq of the CameraFrame it belongs to
    position: List(Float(-COORD, COORD), 3, lengths=(3,))
    quaternion: List(Float(-1.0, 1.0), 4, lengths=(4,))  # x, y, z, w of R_world_camera


class Overlay(Message):
    camera: Ident
    frame_seq: Int(0, 2**63 - 1) = 0
    width: Int(0, 16384) = 0
    height: Int(0, 16384) = 0
    ok: bool = False
    position: List(Float(-COORD, COORD), 3, lengths=(0, 3)) = []  # empty when not ok
    quaternion: List(Float(-1.0, 1.0), 4, lengths=(0, 4)) = []
    tags: List(Int(0, 1_000_000), 1000) = []
    reprojection_rmse: Float(0.0, 1e6) = 0.0
    lost_age: Float(0.0, TIME) = 0.0  # seconds since the last good pose when not ok
    latency: Float(0.0, 1e6) = 0.0
    primitives: List(Primitive, 20_000) = []


class Event(Message):
    """Something that happened: ``door_opened``, ``delivered``, ``mission_done``, ``plan_conflict``, ...

    ``data`` is the kind's record (:mod:`protocol.events`): built with one, the Event takes its
    ``kind`` from it (``Event(data=Delivered(...), robot="r0")``); decoded or built with a map, the
    map is checked and turned into that record."""

    kind: Choice(*EVENT_KINDS) = ""
    robot: Str(64) = ""
    door: Str(64) = ""
    object: Str(64) = ""
    data: Any = None

    def __post_init__(self) -> None:
        if isinstance(self.data, EventData):
            if self.kind and self.kind != self.data.KIND:
                raise ProtocolError("kind", f"{self.kind!r} does not match its data, a {self.data.KIND!r}")
            self.kind = self.data.KIND
        else:
            self.data = event_data(self.kind, self.data)


class ParticipantAction(Message):
    """What a study participant did on her tablet page, or what the experimenter marked on the
    console. Everything she does crosses the wire as one of these, so the run's recording holds it.

    ``act``:

    - ``go_to_door`` (``door``): she leaves her desk for that door (virtual world: her avatar walks);
    - ``open_door`` (``door``): she opens it (virtual world: the press-and-hold at the door completed);
    - ``back_to_desk``: she turns back without opening (the walk back after opening is automatic);
    - ``task_done``: her own task (the puzzle) is complete;
    - ``view`` (``view``): the page now shows ``puzzle``, ``ar`` or ``map``; time away from her task
      is measured from these;
    - ``puzzle_move`` (``piece``, ``correct``, ``placed`` of ``total``): one move of the puzzle;
    - ``feedback`` (``door``, ``minutes``, ``note`` = the library entry's kind): she sent feedback;
    - ``consent`` (``note`` = ``given`` or ``refused``): her answer on the consent screen;
    - ``mark`` (``note``): the experimenter marked an event.
    """

    participant: Ident  # pseudonymous id (e.g. P03): never a name
    act: Choice(*PARTICIPANT_ACTS)
    trial: Str(64) = ""  # the study plan's trial id
    door: Str(64) = ""
    view: Choice(*PAGE_VIEWS) = ""
    piece: Int(-1, 100_000) = -1
    correct: bool = False
    placed: Int(0, 100_000) = 0
    total: Int(0, 100_000) = 0
    minutes: Int(0, 1440) = 0
    note: Str(512) = ""
    wall: Float(0.0, TIME) = 0.0  # the page's wall clock (Unix seconds) when she did it


class QuestionnaireAnswers(Message):
    """A participant's answers after a trial: ``arroch-q`` (the paper's Q1-Q5, 1-5) or ``nasa-tlx``
    (raw TLX, six scales 0-100)."""

    participant: Ident
    instrument: Choice(*QUESTIONNAIRES)
    trial: Str(64) = ""
    answers: Map(Int(0, 100), 64) = {}
    wall: Float(0.0, TIME) = 0.0


class HumanState(Message):
    """Where the human is as the simulator has her: at her ``desk``, walking ``to_door``,
    ``at_door`` (it can be opened now), or walking ``back``. In participant mode the page shows the
    door controls from it."""

    mode: Choice("simulated", "participant", "sensor") = "simulated"
    place: Choice(*HUMAN_PLACES) = "desk"
    door: Str(64) = ""  # the door she walks to, stands at or comes back from
    doors: List(Ident, 64) = []  # the doors she operates
    x: Float(-COORD, COORD) = 0.0
    y: Float(-COORD, COORD) = 0.0
    theta: Float(-ANGLE, ANGLE) = 0.0
    task_done: bool = False
    paused: bool = False  # the experimenter paused the trial: site time stands still
    open_time: Float(0.0, 1e4) = 0.0  # site seconds the press-and-hold at a door lasts


class StudyControl(Message):
    """The experimenter's console to the world: ``pause`` or ``resume`` site time, ``abort`` the trial."""

    command: Choice("pause", "resume", "abort")
    trial: Str(64) = ""
    reason: Str(512) = ""


ALL_MESSAGES: tuple[type[Message], ...] = (
    Clock,
    RobotPose,
    RobotStatus,
    RobotCommand,
    RobotTraffic,
    TeamPlan,
    Intent,
    DoorState,
    Feedback,
    FeedbackAck,
    ConstraintSet,
    ConstraintLibrary,
    CameraFrame,
    CameraTruth,
    Overlay,
    Event,
    ParticipantAction,
    QuestionnaireAnswers,
    HumanState,
    StudyControl,
)

BY_TYPE: dict[str, type[Message]] = {cls.TYPE: cls for cls in ALL_MESSAGES}
