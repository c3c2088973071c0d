"""Tablet pose from detected landmark tags: solve, reject outliers, resolve ambiguity, track.

How a pose is found (every step on the same 2-D↔3-D correspondences, all corners of all tags at
once):

1. Candidates. SQPnP (a global solver, unaffected by the exact-180° configuration that breaks IPPE:
   a level camera squarely facing a wall tag). When every used corner lies in one plane (one tag,
   or tags on one wall) a planar pose has a mirror twin of nearly equal reprojection error, so both
   IPPE solutions join the candidates. When tracking, the previous pose joins too. Each candidate is
   refined with Levenberg–Marquardt (``solvePnPRefineLM``) and scored by its reprojection RMSE.
2. Choice. Candidates with an RMSE above ``max_rmse_px`` are out (this is also what removes IPPE's
   wrong poses). The rest must be *plausible*: the camera in front of every tag it uses, inside the
   building, at a height a hand-held tablet can have, and roughly upright (image "down" pointing
   down). Plausible candidates fitting about as well as the best one (within ``AMBIGUOUS_RATIO``)
   are equally good explanations of the pixels: among them, the one nearest the previous pose when
   tracking (the last good pose at most ``track_max_age`` old), else the lowest RMSE; the result is
   then flagged ``ambiguous``.
3. Outliers. A tag whose own corner RMSE exceeds ``outlier_px`` (a mis-decode, a tag moved on the
   wall, a site-file typo) is dropped and the pose solved again; when no plausible pose exists with
   all tags, every leave-one-out subset is tried.
4. No tag or no acceptable pose: the result is *lost*, carrying the age of the last good pose and the
   reason — never an extrapolated or invented pose.

With gravity (the tablet's accelerometer, :mod:`gravity`), the candidates also include the minima of
the gravity-constrained 4-DoF solve (yaw + position), every candidate is refined with gravity as a
soft prior, a candidate tilted more than ``gravity_gate_deg`` from it is implausible, and the choice
weighs the pixels and gravity together (chi-square: corner residuals at the best fit's RMSE, tilt at
the prior's sigma). One tag's mirror solution tilts the camera differently from the true one, so
gravity picks the right one where the pixels cannot. Without gravity nothing changes.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np

from runtime.frames import CameraPose, rotation_angle

from .detect import TagDetection
from .gravity import GravityPrior, gravity_error, yaw_scan
from .gravity import refine as refine_with_gravity
from .project import Intrinsics

#: Candidates within this factor (plus ``AMBIGUOUS_SLACK_PX``) of the best RMSE count as equally good fits.
AMBIGUOUS_RATIO = 1.5
AMBIGUOUS_SLACK_PX = 0.2
#: With gravity: candidates whose chi-square exceeds the best one's by less than this are ambiguous.
AMBIGUOUS_CHI2 = 9.0
#: With gravity: a 4-DoF seed this close to an unconstrained candidate is not refined again.
SAME_SEED_RAD = np.radians(4.0)
SAME_SEED_M = 0.1
#: With gravity: the corner noise (pixels per coordinate) is estimated from the best fit, within these bounds.
MIN_SIGMA_PX = 0.1
MAX_SIGMA_PX = 1.0


@dataclass
class Localization:
    """One frame's answer: a pose with its quality, or lost with a reason."""

    ok: bool
    stamp: float
    pose: CameraPose | None = None
    tags: list[int] = field(default_factory=list)  # tags the pose was solved from
    rmse_px: float = 0.0  # reprojection RMSE over all their corners
    per_tag_rmse: dict[int, float] = field(default_factory=dict)
    rejected: list[int] = field(default_factory=list)  # detected known tags dropped as outliers
    ambiguous: bool = False
    candidates: int = 0
    reason: str = ""
    lost_age: float | None = None  # when lost: seconds since the last good pose (None: never had one)
    gravity_error_deg: float | None = None  # when gravity was given: tilt between the pose and it

    def to_json(self) -> dict:
        """The ``arroch ar localize --json`` shape."""
        if not self.ok or self.pose is None:
            return {"ok": False, "reason": self.reason, "tags": self.tags, "lost_age": self.lost_age}
        out = {
            "ok": True,
            "position": [float(v) for v in self.pose.position],
            "quaternion": [float(v) for v in self.pose.quaternion()],
            "tags": self.tags,
            "reprojection_rmse_px": float(self.rmse_px),
            "per_tag_rmse_px": {str(k): float(v) for k, v in self.per_tag_rmse.items()},
            "rejected": self.rejected,
            "ambiguous": self.ambiguous,
        }
        if self.gravity_error_deg is not None:  # gravity was given: how far the pose's vertical is from it
            out["gravity_error_deg"] = float(self.gravity_error_deg)
        return out


@dataclass
class _Candidate:
    rvec: np.ndarray
    tvec: np.ndarray
    rmse: float
    pose: CameraPose
    tilt: float = 0.0  # radians between the pose's vertical and gravity (0 without gravity)


class Localizer:
    """Turns detections into camera poses against one site's landmarks, keeping tracking state."""

    def __init__(
        self,
        site,  # protocol.site.Site
        *,
        max_rmse_px: float = 3.0,
        outlier_px: float = 3.0,
        height_range: tuple[float, float] = (0.3, 2.2),
        track_max_age: float = 1.0,
        room_margin: float = 0.2,
        gravity_sigma_deg: float = 1.0,
        gravity_gate_deg: float = 10.0,
    ) -> None:
        self.site = site
        self.landmarks: dict[int, np.ndarray] = {
            lm.tag: np.asarray(lm.corners(), dtype=np.float64) for lm in site.landmarks
        }
        self.normals: dict[int, np.ndarray] = {lm.tag: np.asarray(lm.normal, dtype=np.float64) for lm in site.landmarks}
        self.centres: dict[int, np.ndarray] = {
            lm.tag: np.asarray(lm.position, dtype=np.float64) for lm in site.landmarks
        }
        self.max_rmse_px = max_rmse_px
        self.outlier_px = outlier_px
        self.height_range = height_range
        self.track_max_age = track_max_age
        self.room_margin = room_margin
        self.gravity_sigma_deg = gravity_sigma_deg
        self.gravity_gate = np.radians(gravity_gate_deg)
        self.last: Localization | None = None  # last good result
        self._failure = ""  # why the last failed solve found nothing, for the "lost" reason
        self._gravity: GravityPrior | None = None  # this frame's, while it is solved

    def reset(self) -> None:
        self.last = None

    # ------------------------------------------------------------------ public

    def localize(
        self, detections: Sequence[TagDetection], intrinsics: Intrinsics, stamp: float, gravity=None
    ) -> Localization:  # noqa: ANN001
        """Solve this frame's pose and update the tracking state (only good poses are remembered).

        ``gravity``: the measured gravity in the camera frame (pointing down, any magnitude), or None.
        """
        self._gravity = GravityPrior.from_vector(gravity, self.gravity_sigma_deg)
        known = [d for d in detections if d.tag_id in self.landmarks]
        if not known:
            why = (
                "no landmark tag in view"
                if not detections
                else f"tags {sorted(d.tag_id for d in detections)} are not in the site"
            )
            return self._lost(stamp, why, [])
        prior = self.prior(stamp)
        self._failure = ""
        used = list(known)
        rejected: list[int] = []
        result: Localization | None = None
        while used:
            result = self._solve(used, intrinsics, stamp, prior)
            if result is None and len(used) >= 2:
                result = self._best_leave_one_out(used, intrinsics, stamp, prior)
                if result is not None:
                    rejected += [d.tag_id for d in used if d.tag_id not in result.tags]
                    used = [d for d in used if d.tag_id in result.tags]
            if result is None:
                break
            worst = max(result.per_tag_rmse, key=result.per_tag_rmse.get)
            if result.per_tag_rmse[worst] > self.outlier_px and len(used) >= 2:
                rejected.append(worst)
                used = [d for d in used if d.tag_id != worst]
                continue
            break
        if result is None:
            detail = f": {self._failure}" if self._failure else ""
            return self._lost(
                stamp, f"no plausible pose fits the detected tags{detail}", sorted(d.tag_id for d in known)
            )
        if result.rmse_px > self.max_rmse_px:
            return self._lost(
                stamp, f"reprojection RMSE {result.rmse_px:.2f} px exceeds {self.max_rmse_px} px", result.tags
            )
        result.rejected = sorted(rejected)
        self.last = result
        return result

    # ------------------------------------------------------------------ internals

    def _lost(self, stamp: float, reason: str, tags: list[int]) -> Localization:
        age = None if self.last is None else max(stamp - self.last.stamp, 0.0)
        return Localization(ok=False, stamp=stamp, tags=tags, reason=reason, lost_age=age)

    def prior(self, stamp: float) -> CameraPose | None:
        """The last good pose if it is recent enough to track from (at most ``track_max_age`` old)."""
        if self.last is None or self.last.pose is None:
            return None
        age = stamp - self.last.stamp
        return self.last.pose if 0.0 <= age <= self.track_max_age else None

    def _best_leave_one_out(
        self, used: list[TagDetection], K: Intrinsics, stamp: float, prior: CameraPose | None
    ) -> Localization | None:
        best: Localization | None = None
        for i in range(len(used)):
            r = self._solve(used[:i] + used[i + 1 :], K, stamp, prior)
            if r is not None and (best is None or r.rmse_px < best.rmse_px):
                best = r
        return best

    def _solve(
        self, used: list[TagDetection], K: Intrinsics, stamp: float, prior: CameraPose | None
    ) -> Localization | None:
        """Best plausible refined candidate for these tags, or None."""
        obj = np.concatenate([self.landmarks[d.tag_id] for d in used]).astype(np.float64)
        img = np.concatenate([d.corners for d in used]).astype(np.float64)
        Km, dist = K.K, K.dist
        seeds: list[tuple[np.ndarray, np.ndarray]] = []
        ok, rvec, tvec = cv2.solvePnP(obj, img, Km, dist, flags=cv2.SOLVEPNP_SQPNP)
        if ok:
            seeds.append((rvec, tvec))
        if _coplanar(obj):
            n, rvecs, tvecs, _ = cv2.solvePnPGeneric(obj, img, Km, dist, flags=cv2.SOLVEPNP_IPPE)
            seeds += [(rvecs[i], tvecs[i]) for i in range(n)]
        if prior is not None:
            r, t = prior.rvec_tvec()
            seeds.append((r.reshape(3, 1).copy(), t.reshape(3, 1).copy()))
        cands = self._refined(obj, img, Km, dist, seeds)
        gravity = self._gravity
        sigma_px = MIN_SIGMA_PX
        if gravity is not None and cands:
            # Corner noise from the best unconstrained fit (per coordinate, 6 parameters fitted),
            # then every fitting minimum and every gravity-consistent one (the 4-DoF scan) refined
            # with gravity as a prior at that noise.
            n = 2 * len(obj)
            best_rmse = min(c.rmse for c in cands)
            sigma_px = float(np.clip(best_rmse * np.sqrt(len(obj) / max(n - 6, 1)), MIN_SIGMA_PX, MAX_SIGMA_PX))
            seeds = [(c.rvec, c.tvec) for c in cands if c.rmse <= self.max_rmse_px]
            # A gravity-consistent minimum next to an unconstrained one would refine to the same pose.
            for rvec, tvec in yaw_scan(obj, img, Km, dist, gravity):
                pose = CameraPose.from_rvec_tvec(rvec, tvec)
                if not any(
                    rotation_angle(pose.R_wc, c.pose.R_wc) < SAME_SEED_RAD
                    and np.linalg.norm(pose.position - c.pose.position) < SAME_SEED_M
                    for c in cands
                ):
                    seeds.append((rvec, tvec))
            cands = self._refined(obj, img, Km, dist, seeds, gravity, sigma_px)
        n_cands = len(cands)
        good = [
            c
            for c in cands
            if c.rmse <= self.max_rmse_px and c.tilt <= self.gravity_gate and self._plausible(c.pose, used)
        ]
        if not good:
            # Say why the best-fitting candidate failed: that is what a user can act on.
            if cands:
                top = min(cands, key=lambda c: c.rmse)
                ids = [d.tag_id for d in used]
                if top.rmse > self.max_rmse_px:
                    self._failure = f"best fit {top.rmse:.2f} px"
                elif top.tilt > self.gravity_gate:
                    self._failure = f"camera tilt disagrees with gravity by {np.degrees(top.tilt):.1f}°"
                else:
                    self._failure = self.plausibility(top.pose, ids)
            return None
        # Solutions fitting nearly as well as the best are genuinely ambiguous on these pixels;
        # only there may the previous pose decide (never against a clearly better fit).
        floor = min(c.rmse for c in good)
        if gravity is None:
            contenders = [c for c in good if c.rmse <= AMBIGUOUS_RATIO * floor + AMBIGUOUS_SLACK_PX]
        else:
            sigma_tilt = np.radians(gravity.sigma_deg)
            chi2 = {id(c): len(obj) * (c.rmse / sigma_px) ** 2 + (c.tilt / sigma_tilt) ** 2 for c in good}
            least = min(chi2.values())
            contenders = sorted((c for c in good if chi2[id(c)] <= least + AMBIGUOUS_CHI2), key=lambda c: chi2[id(c)])
        if prior is not None:
            best = min(
                contenders,
                key=lambda c: (
                    rotation_angle(c.pose.R_wc, prior.R_wc) + np.linalg.norm(c.pose.position - prior.position)
                ),
            )
        elif gravity is not None:
            best = contenders[0]
        else:
            best = min(contenders, key=lambda c: c.rmse)
        ambiguous = len(contenders) > 1
        per_tag = {}
        proj, _ = cv2.projectPoints(obj, best.rvec, best.tvec, Km, dist)
        err = np.linalg.norm(proj.reshape(-1, 2) - img, axis=1)
        for i, d in enumerate(used):
            per_tag[d.tag_id] = float(np.sqrt(np.mean(err[4 * i : 4 * i + 4] ** 2)))
        return Localization(
            ok=True,
            stamp=stamp,
            pose=best.pose,
            tags=sorted(d.tag_id for d in used),
            rmse_px=best.rmse,
            per_tag_rmse=per_tag,
            ambiguous=ambiguous,
            candidates=n_cands,
            gravity_error_deg=float(np.degrees(best.tilt)) if gravity is not None else None,
        )

    def _refined(
        self,
        obj: np.ndarray,
        img: np.ndarray,
        Km: np.ndarray,
        dist: np.ndarray,
        seeds,
        gravity: GravityPrior | None = None,  # noqa: ANN001
        sigma_px: float = MIN_SIGMA_PX,
    ) -> list[_Candidate]:
        """Each seed refined (Levenberg–Marquardt; with gravity as a prior when given), duplicates dropped."""
        cands: list[_Candidate] = []
        for rvec, tvec in seeds:
            rvec, tvec = (
                np.asarray(rvec, np.float64).reshape(3, 1).copy(),
                np.asarray(tvec, np.float64).reshape(3, 1).copy(),
            )
            if gravity is None:
                rvec, tvec = cv2.solvePnPRefineLM(obj, img, Km, dist, rvec, tvec)
            else:
                rvec, tvec = refine_with_gravity(obj, img, Km, dist, rvec, tvec, gravity, sigma_px=sigma_px)
            rmse = _rmse(obj, img, rvec, tvec, Km, dist)
            if not np.isfinite(rmse):
                continue
            pose = CameraPose.from_rvec_tvec(rvec, tvec)
            if any(
                rotation_angle(pose.R_wc, c.pose.R_wc) < np.radians(0.5)
                and np.linalg.norm(pose.position - c.pose.position) < 0.01
                for c in cands
            ):
                continue  # the same solution reached from another seed
            tilt = gravity_error(pose.R_wc, gravity) if gravity is not None else 0.0
            cands.append(_Candidate(rvec, tvec, rmse, pose, tilt))
        return cands

    def plausibility(self, pose: CameraPose, tag_ids: Sequence[int]) -> str:
        """Empty when a pose is plausible for a hand-held tablet seeing ``tag_ids``; else why not."""
        cam = pose.position
        for tag in tag_ids:
            if np.dot(cam - self.centres[tag], self.normals[tag]) <= 0.0:
                return f"camera behind tag {tag}"
        lo, hi = self.height_range
        if not lo <= cam[2] <= hi:
            return f"camera height {cam[2]:.2f} m outside {lo}–{hi} m"
        if not any(room.contains(cam[0], cam[1], margin=-self.room_margin) for room in self.site.rooms.values()):
            return "camera outside the building"
        if pose.R_wc[2, 1] > -0.25:  # the image's "down" axis must point down in the world
            return "camera not upright"
        return ""

    def _plausible(self, pose: CameraPose, used: list[TagDetection]) -> bool:
        return not self.plausibility(pose, [d.tag_id for d in used])


def _rmse(
    obj: np.ndarray, img: np.ndarray, rvec: np.ndarray, tvec: np.ndarray, K: np.ndarray, dist: np.ndarray
) -> float:
    proj, _ = cv2.projectPoints(obj, rvec, tvec, K, dist)
    return float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - img) ** 2, axis=1))))


def _coplanar(points: np.ndarray, tol: float = 1e-3) -> bool:
    """True when the points lie within ``tol`` metres (RMS) of one plane."""
    centred = points - points.mean(axis=0)
    s = np.linalg.svd(centred, compute_uv=False)
    return bool(s[-1] / np.sqrt(len(points)) < tol)
