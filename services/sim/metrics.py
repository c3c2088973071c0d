"""The figures the paper reports for a mission (§V-A), gathered while it runs.

- team completion time: the slowest agent's, the human included;
- each agent's completion time: a robot's is when its last object was delivered (0 for a robot
  with none), the human's when her own task was done;
- door openings by the human (her a1 actions), and door openings of every kind per door;
- feedback sent, accepted, refused and unanswered (a2 declarations, ARROCH only);
- safety: robots that entered the doorway of a closed door (:mod:`services.sim.crossings`; 0 in
  every correct run); robot-robot overlaps (two discs intersecting, :mod:`services.sim.overlaps`),
  in total, per pair and per place (room or opening); robot-wall contacts (a disc reaching into a
  wall, :mod:`services.sim.walls`), per place, and the deepest any disc reached;
plus what explains them (robots' waiting time at doors, the human's time away and focus intervals,
world versions) and every parameter of the run, so a metrics file is self-describing.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from typing import Any


@dataclass
class MetricsRecorder:
    params: dict[str, Any] = field(default_factory=dict)
    robot_done: dict[str, float] = field(default_factory=dict)  # robot -> completion time
    human_done: float | None = None
    door_openings: Counter = field(default_factory=Counter)  # (door, by) -> openings
    feedback_sent: int = 0
    feedback_accepted: int = 0
    feedback_refused: int = 0
    feedback_unanswered: int = 0
    actions_done: int = 0
    actions_failed: int = 0
    closed_door_crossings: int = 0
    overlaps: Counter = field(default_factory=Counter)  # ((robot, robot), place) -> overlaps
    wall_contacts: Counter = field(default_factory=Counter)  # place -> robot-wall contacts

    def overlap(self, pair: tuple[str, str], place: str) -> None:
        self.overlaps[(pair, place)] += 1

    def wall_contact(self, place: str) -> None:
        self.wall_contacts[place] += 1

    def opened(self, door: str, by: str) -> None:
        self.door_openings[(door, "human" if by == "human" else "robot")] += 1

    def feedback_answer(self, accepted: bool | None) -> None:
        if accepted is None:
            self.feedback_unanswered += 1
        elif accepted:
            self.feedback_accepted += 1
        else:
            self.feedback_refused += 1

    def summary(
        self,
        *,
        time: float,
        completed: bool,
        robots: dict[str, dict[str, Any]],
        human: dict[str, Any],
        world_versions: int,
        wall_depth_max: float = 0.0,
    ) -> dict[str, Any]:
        """The metrics as a JSON-ready map (the data of Event ``mission_done``)."""
        agents = {rid: self.robot_done.get(rid) for rid in sorted(robots)}
        agents["human"] = self.human_done
        finished = [t for t in agents.values() if t is not None]
        per_door: dict[str, dict[str, int]] = {}
        for (door, by), n in sorted(self.door_openings.items()):
            per_door.setdefault(door, {})[by] = n
        per_pair: Counter = Counter()
        per_place: Counter = Counter()
        for (pair, place), n in self.overlaps.items():
            per_pair["-".join(pair)] += n
            per_place[place] += n
        return {
            "completed": completed,
            "time": round(time, 6),
            "team_completion_time": max(finished) if completed and finished else None,
            "agent_completion_times": agents,
            "human_door_openings": human.get("door_openings", 0),
            "door_openings": per_door,
            "feedback": {
                "sent": self.feedback_sent,
                "accepted": self.feedback_accepted,
                "refused": self.feedback_refused,
                "unanswered": self.feedback_unanswered,
            },
            "actions": {"done": self.actions_done, "failed": self.actions_failed},
            "closed_door_crossings": self.closed_door_crossings,
            "robot_overlaps": sum(self.overlaps.values()),
            "robot_overlaps_by_pair": dict(sorted(per_pair.items())),
            "robot_overlaps_by_place": dict(sorted(per_place.items())),
            "wall_contacts": sum(self.wall_contacts.values()),
            "wall_contacts_by_place": dict(sorted(self.wall_contacts.items())),
            "wall_depth_max": round(wall_depth_max, 6),
            "world_versions": world_versions,
            "robots": robots,
            "human": human,
            "params": self.params,
        }
