"""A steady overlay: the pose drawn is a filtered, gated version of the poses measured.

Frame-by-frame poses jitter (corner noise, a tag's ambiguity at a distance), and now and then one is
simply wrong (the other planar solution, a mis-read tag). Drawn as they come, robots and paths
shake, and a wrong pose throws the whole overlay across the room for a frame. So the pose drawn goes
through a constant-velocity filter (an alpha-beta filter on position and on rotation, the tablet
moving at a steady linear and angular velocity between frames):

* **predict** each frame from the previous state and the time since it;
* **gate** the measured pose against the prediction: a measurement farther than
  ``gate_m + speed_m_s · dt`` in position or ``gate_deg + turn_deg_s · dt`` in rotation — or, with
  gravity, tilted more than ``gravity_gate_deg`` from it — is *rejected*: counted, not drawn; the
  prediction is drawn instead (the first pose of a stream has nothing to be gated against);
* **correct** with an accepted one: ``alpha`` of the innovation to the pose while it is within the
  pose's jitter (``noise_m``, ``noise_deg``), more as it grows (all of it at 4x: a real move is
  followed at once), and ``beta`` (per second) to the velocities.

A run of ``reinit_after`` rejections that agree with one another is the tablet really somewhere
else (a fast turn, the filter started on a wrong pose): the filter restarts there. After
``max_gap_s`` without an accepted pose the state is stale, and the next measurement starts afresh.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import pairwise

import cv2
import numpy as np

from runtime.frames import CameraPose, rotation_angle

from .gravity import GravityPrior, gravity_error


@dataclass
class FilterOptions:
    alpha: float = 0.6  # share of the innovation taken by the pose, for innovations within the noise
    noise_m: float = 0.02  # innovations up to this (and noise_deg) are treated as jitter; beyond, the
    noise_deg: float = 0.6  # share rises to 1 at 4x, so a real move is followed without lag
    beta: float = 0.15  # share of the innovation rate taken by the velocities
    gate_m: float = 0.12  # position gate at dt = 0 (metres)
    speed_m_s: float = 1.5  # position gate growth (a hand-held tablet's fastest plausible motion)
    gate_deg: float = 6.0
    turn_deg_s: float = 120.0
    gravity_gate_deg: float = 5.0
    reinit_after: int = 3  # consecutive rejected poses, consistent with one another, that restart the filter
    max_gap_s: float = 1.0


@dataclass
class FilteredPose:
    """What to draw for one frame: the pose, and whether the measurement was accepted."""

    pose: CameraPose
    accepted: bool
    reason: str = ""  # why the measurement was rejected


class PoseFilter:
    """Constant-velocity alpha-beta filter with gating over one camera's pose stream."""

    def __init__(self, options: FilterOptions | None = None) -> None:
        self.options = options or FilterOptions()
        self.rejected = 0  # measurements refused by the gates since the start
        self.accepted = 0
        self.reset()

    def reset(self) -> None:
        """Forget the state (independent frames follow)."""
        self._pose: CameraPose | None = None
        self._velocity = np.zeros(3)
        self._spin = np.zeros(3)  # world-frame angular velocity, rotation vector per second
        self._stamp = 0.0
        self._pending: list[tuple[CameraPose, float]] = []  # the current run of rejected measurements

    def predict(self, stamp: float) -> CameraPose | None:
        """The state carried to ``stamp`` (None without a fresh state)."""
        if self._pose is None or not 0.0 <= stamp - self._stamp <= self.options.max_gap_s:
            return None
        dt = stamp - self._stamp
        turn, _ = cv2.Rodrigues((self._spin * dt).reshape(3, 1))
        return CameraPose(R_wc=turn @ self._pose.R_wc, position=self._pose.position + self._velocity * dt)

    def update(self, measured: CameraPose, stamp: float, gravity: GravityPrior | None = None) -> FilteredPose:
        """One measured pose at ``stamp``: the pose to draw."""
        o = self.options
        predicted = self.predict(stamp)
        if (
            predicted is not None
            and gravity is not None
            and gravity_error(measured.R_wc, gravity) > np.radians(o.gravity_gate_deg)
        ):
            self.rejected += 1
            return FilteredPose(
                predicted, False, f"tilted {np.degrees(gravity_error(measured.R_wc, gravity)):.1f}° from gravity"
            )
        if predicted is None:
            self._restart(measured, stamp)
            return FilteredPose(measured, True)
        dt = stamp - self._stamp
        jump = float(np.linalg.norm(measured.position - predicted.position))
        turn = float(np.degrees(rotation_angle(measured.R_wc, predicted.R_wc)))
        if jump > o.gate_m + o.speed_m_s * dt or turn > o.gate_deg + o.turn_deg_s * dt:
            self.rejected += 1
            self._pending.append((measured, stamp))
            if len(self._pending) >= o.reinit_after and _consistent(self._pending[-o.reinit_after :], o):
                self._restart(measured, stamp)
                return FilteredPose(measured, True, "restarted")
            return FilteredPose(predicted, False, f"jumped {jump:.2f} m / {turn:.1f}° against the motion")
        self._pending = []
        self.accepted += 1
        # Correct: alpha of the innovation to the pose, beta/dt to the velocities.
        dp = measured.position - predicted.position
        dR = measured.R_wc @ predicted.R_wc.T  # world-frame rotation from prediction to measurement
        dr, _ = cv2.Rodrigues(dR)
        dr = dr.reshape(3)
        a_pos, a_rot = _share(o.alpha, jump / o.noise_m), _share(o.alpha, turn / o.noise_deg)
        step, _ = cv2.Rodrigues((a_rot * dr).reshape(3, 1))
        self._pose = CameraPose(R_wc=step @ predicted.R_wc, position=predicted.position + a_pos * dp)
        if dt > 1e-6:
            self._velocity = self._velocity + o.beta * dp / dt
            self._spin = self._spin + o.beta * dr / dt
        self._stamp = stamp
        return FilteredPose(self._pose, True)

    def _restart(self, pose: CameraPose, stamp: float) -> None:
        self._pose, self._stamp = pose, stamp
        self._velocity, self._spin = np.zeros(3), np.zeros(3)
        self._pending = []
        self.accepted += 1


def _share(alpha: float, ratio: float) -> float:
    """The innovation's share taken: ``alpha`` within the noise (ratio <= 1), rising to 1 at 4x."""
    return alpha if ratio <= 1.0 else min(1.0, alpha + (1.0 - alpha) * (ratio - 1.0) / 3.0)


def _consistent(run: list[tuple[CameraPose, float]], o: FilterOptions) -> bool:
    """Consecutive rejected poses agree with one another (each within the gates of the one before)."""
    for (a, ta), (b, tb) in pairwise(run):
        dt = max(tb - ta, 0.0)
        if np.linalg.norm(b.position - a.position) > o.gate_m + o.speed_m_s * dt:
            return False
        if np.degrees(rotation_angle(b.R_wc, a.R_wc)) > o.gate_deg + o.turn_deg_s * dt:
            return False
    return True
