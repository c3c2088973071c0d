"""The executor of RobotCommands every robot runs: the simulator's and a real robot's.

``executor`` holds the state machine (phases, checks, holds, arrival, door waits); the rules that
keep robots apart are one module each (``right_of_way``, ``avoidance``, ``make_way``,
``doorways``, ``waiting``), with the wall guard's depth in ``walls``; ``interfaces`` says what the
executor needs from the doors and objects of the world it runs in. A real robot's driver, which sees
the other robots only over Zenoh, adds ``sensed`` (doors and objects as a robot process knows them),
``peers`` (the other robots from their poses and statuses) and ``traffic`` (the rules' shared
tables, exchanged between robot processes). docs/services/robot.md describes the whole.
"""

from .executor import CommandError, Outcome, Robot, RobotConfig, RobotExecutor, outcome_of, status_message

__all__ = ["CommandError", "Outcome", "Robot", "RobotConfig", "RobotExecutor", "outcome_of", "status_message"]
