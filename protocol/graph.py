"""The service graph, declared once: which service publishes, subscribes, serves and asks which key,
with which message type, and why.

This is the dataflow of a running site. ``arroch graph`` prints and draws it, ``docs/graph.md`` is
generated from it, and tests/integration/test_graph_declared.py starts the services against a router
and checks what each declares on Zenoh against it. Change a service's I/O, change it here.

Keys are written relative to the namespace (``arroch/<namespace>/``) as the builders of
:class:`protocol.keys.Keys` make them, with ``*`` where a service uses one concrete chunk of its
own (its robot, its camera, a feedback's sender). Keys starting with ``/`` are ROS 2 topics reached
through rmw_zenoh (:mod:`runtime.ros2`), which carry ROS 2 types rather than ARROCH messages.

Every :class:`runtime.service.Service` also serves ``stats/<name>/<instance>`` (its counters, as an
``Event`` of kind ``stats``) and holds a liveliness token ``@liveliness/<name>/<instance>``; those are
listed once here (:data:`FRAMEWORK`), not in each service. Who *may* publish a key in the secure
profile is the access-control table's business (services/supervisor/deployment/acl.py); a test
checks that every publication and queryable declared here is one its role is allowed.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from .keys import Keys
from .messages import (
    CameraFrame,
    CameraTruth,
    Clock,
    ConstraintSet,
    DoorState,
    Event,
    Feedback,
    FeedbackAck,
    HumanState,
    Intent,
    Message,
    Overlay,
    ParticipantAction,
    QuestionnaireAnswers,
    RobotCommand,
    RobotPose,
    RobotStatus,
    RobotTraffic,
    StudyControl,
    TeamPlan,
)

Direction = Literal["pub", "sub", "serve", "query"]
#: pub: puts on the key; sub: subscribes to it; serve: answers queries on it; query: asks it.
DIRECTIONS: tuple[Direction, ...] = ("pub", "sub", "serve", "query")
#: A payload that is no ARROCH message: the constraint library (msgpack of its entries) and ROS 2 types.
LIBRARY_PAYLOAD = "ConstraintLibrary (msgpack)"
RECORDED_PAYLOAD = "any recorded message"

_keys = Keys("namespace")  # the builders' keys, cut below the namespace prefix by _rel()


def _rel(key: str) -> str:
    return key.removeprefix(_keys.prefix + "/")


@dataclass(frozen=True)
class Endpoint:
    """One key a service uses: the direction, the key below ``arroch/<namespace>/`` (or a ROS 2
    topic), the payload (an ARROCH message class, or a description of a foreign payload), what it is
    for, and the command-line option or circumstance under which it exists (``""``: always)."""

    direction: Direction
    key: str
    payload: type[Message] | str
    purpose: str
    when: str = ""

    @property
    def payload_name(self) -> str:
        return self.payload if isinstance(self.payload, str) else self.payload.__name__

    @property
    def is_ros2(self) -> bool:
        """A ROS 2 topic (through rmw_zenoh), not an ARROCH key."""
        return self.key.startswith("/")


@dataclass(frozen=True)
class ServiceNode:
    """A process of the graph: its Service name (liveliness and stats keys), how it is started, the
    access-control role it runs as (``""``: none, a diagnostic tool), what it does, and its keys."""

    name: str
    command: str
    role: str
    summary: str
    endpoints: tuple[Endpoint, ...]

    def of(self, direction: Direction) -> list[Endpoint]:
        """Its endpoints in ``direction``, in declaration order."""
        return [e for e in self.endpoints if e.direction == direction]

    @property
    def conditions(self) -> set[str]:
        """Every ``when`` its endpoints name."""
        return {e.when for e in self.endpoints if e.when}


def pub(key: str, payload: type[Message] | str, purpose: str, when: str = "") -> Endpoint:
    return Endpoint("pub", _rel(key), payload, purpose, when)


def sub(key: str, payload: type[Message] | str, purpose: str, when: str = "") -> Endpoint:
    return Endpoint("sub", _rel(key), payload, purpose, when)


def serve(key: str, payload: type[Message] | str, purpose: str, when: str = "") -> Endpoint:
    return Endpoint("serve", _rel(key), payload, purpose, when)


def query(key: str, payload: type[Message] | str, purpose: str, when: str = "") -> Endpoint:
    return Endpoint("query", _rel(key), payload, purpose, when)


# Conditions (Endpoint.when) that several services share or tests name.
SIM_CLOCK = "--clock sim"  # the site clock follows the simulator's Clock messages (SimClock)
SENDING_FEEDBACK = "while a feedback awaits its ack"  # runtime.feedback_client.send_feedback
WITH_FEEDBACK = "without --no-feedback"
STUDY = "--study-trial"
ON_CONFLICT = "on a plan conflict"


# The restrictor's client side (runtime.feedback_client), as every feedback giver uses it.
_GIVE_FEEDBACK = (
    query(_keys.feedback(), FeedbackAck, "give feedback: the query carries the Feedback, the reply is its ack"),
    sub(_keys.feedback_ack(), FeedbackAck, "the ack of its feedback, if it comes as a publication", SENDING_FEEDBACK),
)
# What a drawn view of the world follows (services/ar_client/world.py: WorldView.follow).
_WORLD_VIEW = (
    sub(_keys.robot_pose(), RobotPose, "robots drawn where they are"),
    sub(_keys.robot_status(), RobotStatus, "robot states shown"),
    sub(_keys.intent(), Intent, "each robot's path drawn"),
    sub(_keys.door_state(), DoorState, "doors drawn open or closed"),
)
_SITE_CLOCK = sub(_keys.clock(), Clock, "the site clock (SimClock)", SIM_CLOCK)

PLANNER = ServiceNode(
    "planner",
    "arroch planner",
    "planner",
    "task and motion planner and dispatcher: plans the team, sends each robot its next action",
    (
        sub(_keys.robot_pose(), RobotPose, "where the robots are (plans start there)"),
        sub(_keys.robot_status(), RobotStatus, "action progress and completion; world version"),
        sub(_keys.door_state(), DoorState, "which doors are open"),
        sub(_keys.constraints(), ConstraintSet, "the human's active constraints: replan"),
        sub(_keys.event(), Event, "mission events (deliveries, failures)"),
        sub(_keys.clock(), Clock, "site clock; in lockstep, when to plan"),
        query(_keys.constraints(), ConstraintSet, "the live set at start (a late joiner's)"),
        pub(_keys.plan(), TeamPlan, "the team plan (makespan, door openings, each robot's steps)"),
        serve(_keys.plan(), TeamPlan, "the current plan, for late joiners"),
        pub(_keys.robot_command(), RobotCommand, "each robot's next action with its trajectory"),
        serve(_keys.robot_command(), RobotCommand, "each robot's current command, for a simulator that missed it"),
        pub(_keys.intent(), Intent, "each robot's intended motion, for the AR overlay and the bridge"),
        pub(_keys.event(), Event, "plan_conflict: a plan that could not be followed", ON_CONFLICT),
    ),
)

RESTRICTOR = ServiceNode(
    "restrictor",
    "arroch restrictor",
    "restrictor",
    "turns the human's feedback into a versioned, persisted set of constraints",
    (
        sub(_keys.feedback(), Feedback, "feedback published rather than asked"),
        serve(_keys.feedback(), FeedbackAck, "feedback as a query (carrying the Feedback): answered with its ack"),
        pub(_keys.feedback_ack(), FeedbackAck, "each feedback's ack, on its sender's key", "once feedback arrived"),
        pub(_keys.constraints(), ConstraintSet, "the active constraints, at start and on each change"),
        serve(_keys.constraints(), ConstraintSet, "the active constraints, for late joiners"),
        serve(_keys.constraint_library(), LIBRARY_PAYLOAD, "the library the feedback buttons are built from"),
        _SITE_CLOCK,
    ),
)

SIM_CAMERA = "--camera"
SIM_HOLD = "--camera, --mode lockstep"  # each held frame waits for its overlay
_SIM_EXTERNAL = "--robots none or --ros2-bases"  # robots driven outside the simulator
SIM_REFETCH = "--mode lockstep, paused 5 s for a plan or a command"  # its publication was lost
SIM = ServiceNode(
    "sim",
    "arroch sim",
    "sim",
    "simulated robots, doors, human and tablet camera; the site clock (lockstep, rate or real time)",
    (
        sub(_keys.robot_command(), RobotCommand, "the robots' actions to execute"),
        sub(_keys.plan(), TeamPlan, "lockstep: the plan answering the current world version"),
        query(_keys.plan(), TeamPlan, "lockstep: the plan again, when none came", SIM_REFETCH),
        query(_keys.robot_command(), RobotCommand, "lockstep: the robots' commands again", SIM_REFETCH),
        sub(_keys.study_control(), StudyControl, "the experimenter pauses, resumes or aborts"),
        sub(_keys.participant_action(), ParticipantAction, "the participant's moves", "--human participant"),
        sub(_keys.door_sensor(), DoorState, "real doors' sensors", "--doors sensor"),
        sub(_keys.overlay(), Overlay, "lockstep: the overlay of the held frame", SIM_HOLD),
        sub(_keys.robot_status(), RobotStatus, "external robots' statuses", _SIM_EXTERNAL),
        sub(_keys.robot_pose(), RobotPose, "external robots' poses", _SIM_EXTERNAL),
        pub(_keys.clock(), Clock, "the site clock; in lockstep, what it waits for"),
        pub(_keys.robot_pose(), RobotPose, "simulated robots' poses"),
        pub(_keys.robot_status(), RobotStatus, "simulated robots' statuses"),
        pub(_keys.door_state(), DoorState, "doors open or closed, and by whom"),
        pub(_keys.human_state(), HumanState, "where the (simulated or real) human is"),
        pub(_keys.event(), Event, "what happened: deliveries, doors, mission_done, ..."),
        pub(_keys.camera_frame(), CameraFrame, "the virtual tablet camera's frames", SIM_CAMERA),
        pub(_keys.camera_truth(), CameraTruth, "each frame's true camera pose", SIM_CAMERA),
        *_GIVE_FEEDBACK,  # the simulated human's feedback
    ),
)

AR_SIM_SOURCE = "--source sim"
FRAMES_ARRIVING = "once frames come"  # its publisher is declared with the first overlay
AR = ServiceNode(
    "ar",
    "arroch ar",
    "ar",
    "AR client: localises the camera from wall tags, draws robots and plans, feedback buttons",
    (
        *_WORLD_VIEW,
        sub(_keys.camera_frame(), CameraFrame, "the frames to localise and draw on", AR_SIM_SOURCE),
        sub(_keys.constraints(), ConstraintSet, "live constraints (the cancel button's choices)", WITH_FEEDBACK),
        pub(_keys.overlay(), Overlay, "the camera pose and the drawing of each frame", FRAMES_ARRIVING),
        query(_keys.constraint_library(), LIBRARY_PAYLOAD, "the feedback buttons", WITH_FEEDBACK),
        query(_keys.constraints(), ConstraintSet, "the live set at start", WITH_FEEDBACK),
        *(
            Endpoint(e.direction, e.key, e.payload, e.purpose, e.when or WITH_FEEDBACK)  # buttons' feedback
            for e in _GIVE_FEEDBACK
        ),
        _SITE_CLOCK,
    ),
)

_TABLET_SIM_CAMERA = "--camera-source sim"
TABLET = ServiceNode(
    "tablet",
    "arroch tablet",
    "ar",
    "the tablet page's server: the device's camera and overlays, feedback, the study participant's page",
    (
        *_WORLD_VIEW,
        sub(_keys.constraints(), ConstraintSet, "live constraints shown on the page"),
        sub(_keys.camera_frame(), CameraFrame, "the sim's camera shown on the page", _TABLET_SIM_CAMERA),
        sub(_keys.human_state(), HumanState, "the participant's place and door controls", STUDY),
        # A wall-clock tablet subscribes too in a study: the page shows the sim's rate and pause.
        sub(_keys.clock(), Clock, "the site clock; the sim's rate and pause, for the page", f"{SIM_CLOCK} or {STUDY}"),
        sub(_keys.event(), Event, "mission_done ends the participant's trial", STUDY),
        pub(_keys.overlay(), Overlay, "overlays of the device's camera (localised on the page's server)"),
        pub(_keys.participant_action(), ParticipantAction, "what the participant does on the page", STUDY),
        pub(_keys.questionnaire(), QuestionnaireAnswers, "the participant's answers after a trial", STUDY),
        query(_keys.constraints(), ConstraintSet, "the live set at start"),
        query(_keys.constraint_library(), LIBRARY_PAYLOAD, "the feedback buttons"),
        *_GIVE_FEEDBACK,
    ),
)

#: What a recorder keeps: every ARROCH stream of the namespace (services/recorder/topics.py), keys
#: below the namespace.
RECORDED: tuple[tuple[str, type[Message]], ...] = tuple(
    (_rel(key), message)
    for key, message in (
        (_keys.clock(), Clock),
        (_keys.robot_pose(), RobotPose),
        (_keys.robot_status(), RobotStatus),
        (_keys.robot_command(), RobotCommand),
        (_keys.robot_traffic(), RobotTraffic),
        (_keys.door_state(), DoorState),
        (_keys.door_sensor(), DoorState),
        (_keys.plan(), TeamPlan),
        (_keys.intent(), Intent),
        (_keys.feedback(), Feedback),
        (_keys.feedback_ack(), FeedbackAck),
        (_keys.constraints(), ConstraintSet),
        (_keys.camera_frame(), CameraFrame),
        (_keys.camera_truth(), CameraTruth),
        (_keys.overlay(), Overlay),
        (_keys.event(), Event),
        (_keys.human_state(), HumanState),
        (_keys.participant_action(), ParticipantAction),
        (_keys.questionnaire(), QuestionnaireAnswers),
        (_keys.study_control(), StudyControl),
    )
)

RECORDER = ServiceNode(
    "recorder",
    "arroch record / arroch view",
    "supervisor",
    "records the run to MCAP (Foxglove channels, a ROS 2 bag) and serves it live to Foxglove",
    # The clock is recorded too: with --clock sim, the SimClock's subscription is that same key.
    tuple(sub(key, msg_type, "recorded") for key, msg_type in RECORDED),
)

REPLAY = ServiceNode(
    "replay",
    "arroch replay",
    "",
    "publishes a recording again, message by message, as it was recorded (offline: it speaks for every "
    "service, which no access-control role may)",
    (
        pub(_keys.all(), RECORDED_PAYLOAD, "every recorded message, on its own key, as the bytes that travelled"),
        sub(_keys.overlay(), Overlay, "each replayed frame's overlay, before the next frame", "--hold-camera"),
        sub(_keys.clock(), Clock, "the site clock (a SimClock, fed by the replayed Clock messages)"),
        query(_keys.drain(), "empty", "behind the last message: its reply says all of them left the process"),
        serve(_keys.drain(), "empty", "on a second session: answers its own barrier query, through the router"),
    ),
)

_ROBOT_NS = "/<robot namespace>"
ROBOT = ServiceNode(
    "robot",
    "arroch robot --ros2",
    "sim",
    "a real (ROS 2) robot's driver: executes its commands on cmd_vel, reports its pose and status",
    (
        sub(_keys.robot_command(), RobotCommand, "its own commands (robot/<id>/command)"),
        sub(_keys.door_state(), DoorState, "doors ahead: wait at a closed one"),
        sub(_keys.robot_pose(), RobotPose, "the other robots: where each is (the traffic rules)"),
        sub(_keys.robot_status(), RobotStatus, "the other robots: what each does (the traffic rules)"),
        sub(_keys.robot_traffic(), RobotTraffic, "the other robots' rows of the traffic rules' tables"),
        pub(_keys.robot_pose(), RobotPose, "its pose in the site frame (robot/<id>/pose)"),
        pub(_keys.robot_status(), RobotStatus, "its status (robot/<id>/status)"),
        pub(_keys.robot_traffic(), RobotTraffic, "its rows of the traffic rules' tables (robot/<id>/traffic)"),
        Endpoint("pub", f"{_ROBOT_NS}/cmd_vel", "ROS 2 geometry_msgs/Twist(Stamped)", "velocity commands"),
        Endpoint("sub", f"{_ROBOT_NS}/<pose topic>", "ROS 2 pose type (configured)", "localisation"),
        Endpoint("sub", f"{_ROBOT_NS}/<odom topic>", "ROS 2 nav_msgs/Odometry", "odometry", "odom_topic set"),
        Endpoint("sub", f"{_ROBOT_NS}/<scan topic>", "ROS 2 sensor_msgs/LaserScan", "safety field", "scan_topic set"),
        Endpoint("sub", f"{_ROBOT_NS}/<tf topic>", "ROS 2 tf2_msgs/TFMessage", "frames", "tf_topic set"),
        _SITE_CLOCK,
    ),
)

_BRIDGE_NS = "/arroch"  # the bridge's default --ros-namespace
ROS2_BRIDGE = ServiceNode(
    "ros2bridge",
    "arroch ros2 bridge",
    "sim",
    "shows the site to ROS 2 (RViz): transforms, markers, paths; takes feedback and door sensors from ROS 2",
    (
        sub(_keys.robot_pose(), RobotPose, "robot transforms"),
        sub(_keys.intent(), Intent, "robot paths"),
        sub(_keys.door_state(), DoorState, "door markers"),
        sub(_keys.robot_status(), RobotStatus, "robot markers"),
        sub(_keys.event(), Event, "object markers (deliveries)"),
        pub(_keys.door_sensor(), DoorState, "a ROS 2 door sensor's state", "[ros2.doors.<door>] in the config"),
        *_GIVE_FEEDBACK,  # feedback from ROS 2
        Endpoint("pub", "/tf", "ROS 2 tf2_msgs/TFMessage", "map -> <robot>/base_link"),
        Endpoint("pub", f"{_BRIDGE_NS}/site", "ROS 2 visualization_msgs/MarkerArray", "walls, doors, robots"),
        Endpoint("pub", f"{_BRIDGE_NS}/*/path", "ROS 2 nav_msgs/Path", "each robot's intended path"),
        Endpoint("pub", f"{_BRIDGE_NS}/feedback_ack", "ROS 2 std_msgs/String (JSON)", "each feedback's answer"),
        Endpoint("sub", f"{_BRIDGE_NS}/feedback", "ROS 2 std_msgs/String (JSON)", "feedback from ROS 2"),
        Endpoint("sub", "/<door topic>", "ROS 2 std_msgs/Bool", "a door's sensor", "[ros2.doors.<door>] in the config"),
        _SITE_CLOCK,
    ),
)

SUPERVISOR = ServiceNode(
    "supervisor",
    "arroch up",
    "supervisor",
    "starts a run's services and watches the mission: progress, failures, mission_done",
    (
        sub(_keys.event(), Event, "mission events: progress, failures, mission_done"),
        sub(_keys.robot_status(), RobotStatus, "progress per robot"),
        _SITE_CLOCK,
    ),
)

STUDY_TRIAL = ServiceNode(
    "study",
    "arroch study run",
    "supervisor",
    "the experimenter's console of a study trial: logs the trial, pauses, aborts, marks, real doors",
    (
        sub(_keys.event(), Event, "logged"),
        sub(_keys.participant_action(), ParticipantAction, "logged"),
        sub(_keys.questionnaire(), QuestionnaireAnswers, "logged"),
        sub(_keys.human_state(), HumanState, "logged"),
        sub(_keys.door_state(), DoorState, "logged"),
        sub(_keys.door_sensor(), DoorState, "logged"),
        sub(_keys.constraints(), ConstraintSet, "logged"),
        sub(_keys.study_control(), StudyControl, "logged"),
        sub(_keys.robot_status(), RobotStatus, "the trial's progress"),
        pub(_keys.study_control(), StudyControl, "pause, resume, abort"),
        pub(_keys.participant_action(), ParticipantAction, "the experimenter's marks"),
        pub(_keys.door_sensor(), DoorState, "a real door's state as the experimenter reports it", "a door reported"),
        _SITE_CLOCK,
    ),
)

EXPERIMENT = ServiceNode(
    "experiment",
    "arroch experiment run",
    "supervisor",
    "runs a sweep's trials; its monitor notes each plan (a plain session, no Service)",
    (sub(_keys.plan(), TeamPlan, "plans per trial (solve time, makespan)"),),
)

PING = ServiceNode(
    "ping",
    "arroch ping serve",
    "",
    "diagnostic echo server: every pose heard is sent back",
    (
        sub(_keys.robot_pose(), RobotPose, "the poses to echo"),
        pub(_keys.ping_reply(), RobotPose, "the echo"),
        _SITE_CLOCK,
    ),
)

PING_SEND = ServiceNode(
    "pingsend",
    "arroch ping send",
    "",
    "diagnostic round-trip measurement: sends poses, times their echo",
    (
        pub(_keys.robot_pose(), RobotPose, "probe poses (a robot id of its own)"),
        sub(_keys.ping_reply(), RobotPose, "the echoes"),
        _SITE_CLOCK,
    ),
)

SERVICES: tuple[ServiceNode, ...] = (
    SIM,
    PLANNER,
    RESTRICTOR,
    AR,
    TABLET,
    ROBOT,
    ROS2_BRIDGE,
    RECORDER,
    REPLAY,
    SUPERVISOR,
    STUDY_TRIAL,
    EXPERIMENT,
    PING,
    PING_SEND,
)
BY_NAME: dict[str, ServiceNode] = {s.name: s for s in SERVICES}

#: What every Service declares besides its own keys (runtime/service.py), ``<service>`` its name.
FRAMEWORK: tuple[Endpoint, ...] = (
    Endpoint("serve", "stats/<service>/*", Event, "its counters (an Event of kind stats), also for stats/**"),
    Endpoint("pub", "@liveliness/<service>/*", "liveliness token", "it is up (gone when it stops or dies)"),
)


def framework_keys(service: str) -> list[Endpoint]:
    """:data:`FRAMEWORK`'s endpoints for the service named ``service`` (its instance left as ``*``)."""
    return [Endpoint(e.direction, e.key.replace("<service>", service), e.payload, e.purpose, e.when) for e in FRAMEWORK]
