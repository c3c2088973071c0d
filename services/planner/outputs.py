"""What the planner publishes: TeamPlans, each robot's command and intent, ``plan_conflict`` events.

It numbers the plans, keeps the last TeamPlan (served to late joiners and published again when a
lockstep simulator may have lost it), sends commands again that a robot never got, and reports each
conflict of a constraints version once.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from protocol.events import PlanConflict
from protocol.keys import Keys
from protocol.messages import Event, RobotStatus, TeamPlan

from .dispatcher import Dispatched, Dispatcher
from .lockstep import Repeat
from .plan import TeamResult
from .plan_message import to_message
from .world import World

RESEND_INTERVAL = 1.0  # wall s after sending a command before it is sent again (robot reports no such id)


@dataclass
class PlanOutputs:
    publish: Callable[[str, Any], None]
    keys: Keys
    dispatcher: Dispatcher
    method: str
    count: Callable[[str], None]  # adds one to a service counter
    log: logging.Logger
    plan_id: int = field(default_factory=lambda: int(time.time() * 1000))  # increasing across restarts
    message: TeamPlan | None = None  # the last TeamPlan published
    sent_at: dict[str, float] = field(default_factory=dict)  # robot -> monotonic time of its last command
    reported_conflicts: set[tuple] = field(default_factory=set)

    def plan(
        self,
        world: World,
        kept: TeamResult | None,
        new: bool,
        diagnostic: str,
        versions: tuple[int, int],
        finished: set[str],
        force: set[str],
    ) -> TeamResult | None:
        """Publish ``kept`` (the plan being executed, None before the first) as the next TeamPlan for
        ``versions`` (world, constraints); ``new``: it was just made or continued, so the front
        actions are dispatched (else the commands under way stay as they are). Returns the plan as
        published: a dispatched one carries the waits team motion added (its times then agree with
        the trajectories sent)."""
        self.plan_id += 1
        world_version, cs_version = versions
        if kept is None:
            self.message = TeamPlan(
                plan_id=self.plan_id,
                world_version=world_version,
                constraints_version=cs_version,
                method=self.method,
                diagnostic=diagnostic[:4096],
            )
            self.publish(self.keys.plan(), self.message)
            return None
        if new:
            commands, front = self.dispatcher.dispatch(kept, world, self.plan_id, finished=finished, force=force)
            kept = self.dispatcher.with_waits(kept)  # the plan's times include the waits
        else:
            commands, front = [], {rid: d.action_id for rid, d in self.dispatcher.current.items()}
        # Commands first: a simulator in lockstep waits for the commands a plan names before it runs on.
        for cmd in commands:
            self.publish(self.keys.robot_command(cmd.robot), cmd)
            self.sent_at[cmd.robot] = time.monotonic()
        for intent in self.dispatcher.intents(self.plan_id):
            # (an action taken over from before a restart has no trajectory to show)
            if intent.robot in kept.plans and not kept.plans[intent.robot].empty and intent.trajectory:
                self.publish(self.keys.intent(intent.robot), intent)
        self.message = to_message(
            kept, self.plan_id, world_version, cs_version, front, diagnostic, self.dispatcher.front_index
        )
        self.publish(self.keys.plan(), self.message)
        self.log.info(
            "plan %d for world v%d, constraints v%d: makespan %d s, %d door openings, %d rounds, %.2f s%s",
            self.plan_id,
            world_version,
            cs_version,
            kept.makespan,
            kept.door_openings,
            kept.iterations,
            kept.solve_time,
            f" ({diagnostic})" if diagnostic else "",
        )
        return kept

    def repeat(self, repeat: Repeat) -> None:
        """Publish the last TeamPlan again (a lockstep simulator paused at the version it answers)."""
        if self.message is None:
            return
        self.count("plans_repeated")
        self.log.log(
            logging.INFO if repeat.first else logging.DEBUG,  # the first repeat in a pause is worth a line
            "the simulator has been paused at world v%d for %.0f s: publishing plan %d again (in case it was lost)",
            repeat.world_version,
            repeat.paused_for,
            self.message.plan_id,
        )
        self.publish(self.keys.plan(), self.message)

    def resend(self, status: RobotStatus) -> None:
        """Send the robot's current command again (same id) when its status shows an older action.

        A command published before the robot (or the simulator) subscribed is lost, and a replan
        that keeps the same front action does not send it again, so a lockstep simulator would wait
        for it forever. Statuses come at least once a wall second, so a lost command is sent again
        within about a second; one that did arrive is ignored as a duplicate (same id). A command
        younger than RESEND_INTERVAL is left alone: the status may have been sent before it arrived."""
        robot, now = status.robot, time.monotonic()
        if now - self.sent_at.get(robot, -math.inf) < RESEND_INTERVAL:
            return
        cmd = self.dispatcher.resend(robot)
        if cmd is None:
            return
        self.sent_at[robot] = now
        self.count("commands_resent")
        self.log.debug(
            "sending %s's command %d (%s) again: its status shows action %d",
            robot,
            cmd.action_id,
            cmd.action,
            status.action_id,
        )
        self.publish(self.keys.robot_command(robot), cmd)

    def conflict(self, ids: list[str], reason: str, constraints_version: int) -> None:
        """Publish a ``plan_conflict`` event, once per constraints version and set of constraints."""
        key = (constraints_version, tuple(ids))
        if key in self.reported_conflicts:
            return
        self.reported_conflicts.add(key)
        self.count("plan_conflicts")
        self.log.warning("constraints %s: %s", ", ".join(ids) or "(none)", reason)
        data = PlanConflict(constraints=list(ids), constraints_version=constraints_version, reason=reason[:1000])
        self.publish(self.keys.event(), Event(data=data))


def adopted(status: RobotStatus, sent: dict[str, Dispatched], finished_states: tuple[str, ...]) -> Dispatched | None:
    """A robot's running action taken as the one sent, when this planner sent it nothing (a
    restart): a plan whose front is that action then leaves it running (same id, not sent again),
    and a load or unload under way counts as in progress. None when there is nothing to take over."""
    if status.robot in sent or status.action_id <= 0 or status.state in finished_states:
        return None
    if status.action in ("", "stop"):
        return None
    return Dispatched(status.action, tuple(status.args), status.action_id, status.plan_id, [])
