"""The leg camera's own motion over a flat floor, from the plane homography between consecutive frames.

Two views of a plane are related by the homography ``H = K (R + t n^T / d) K^-1`` (Hartley & Zisserman 2004,
§13.1): ``R, t`` the camera's motion from the first view to the second, ``n`` the plane's unit normal and ``d`` its
distance (the camera's height over the floor) in the first view. The homography is measured directly on the image
intensities (enhanced correlation coefficient, Evangelidis & Psarakis 2008: OpenCV's ``findTransformECC``), and read
without any model of the walk:

- the height ratio of the two views, ``d2 / d1 = 1 + (R n) . t / d = det(Hn)``, with ``Hn = K^-1 H K`` scaled to a
  middle singular value of 1 (Ma, Soatto, Kosecka & Sastry 2004, Lemma 5.18; no choice among the decomposition's
  solutions);
- the camera's displacement over the floor in units of ``d1``, projected on the floor plane (the
  decomposition's solution whose normal continues the previous one, ``cv2.decomposeHomographyMat``, Malis & Vargas
  2007), along two orthonormal floor directions, the image x axis' projection and the one perpendicular to it;
- the optical axis' tilt from the floor normal and its lean (the axis' floor part, sin(tilt) long, along the same
  two directions), where the camera moves enough for the normal to be determined.

Metric scale is not in the images (a monocular camera sees the floor's geometry up to scale): the height itself comes
from the leg (:class:`pdr.slip.FloorOdometryStride`).
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pandas as pd

from pdr.base import Algorithm
from pdr.errors import InputError
from pdr.flow.methods import _as_frames

HALF = np.diag([0.5, 0.5, 1.0])  # a homography's change of pixel coordinates to half the size
ECC_CRITERIA = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-6)
# the refinement on the unblurred frames starts within a fraction of a pixel: a few iterations
REFINE_CRITERIA = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 8, 1e-4)
MOTION_COLUMNS = ["t_s", "dt_s", "height_log_ratio", "floor_x_per_height", "floor_y_per_height", "tilt_rad",
                  "lean_x", "lean_y", "flow_x_pxps", "flow_y_pxps", "quality"]


class HomographyCameraMotion(Algorithm):
    """Per frame pair: the camera's height ratio, its displacement over the floor per height and its tilt.

    Parameters
    ----------
    focal_px, cx_px, cy_px : the camera's intrinsics at the frames' size (``camera.toml``).
    blur_sigma_px : Gaussian pre-blur of both frames (px at the measured size) while the homography is searched for
        (smooth intensity gradients reach further); the homography is then refined on the frames unblurred: aligned
        on the blurred frames alone, the height ratio's log read 1-3% high on the leg-camera benchmark's walks
        (the strides about 1% long), and a blur scaled to each pair's zoom did not remove it.
    max_width_px : frames wider than this are halved (``cv2.pyrDown``) until they are not, the intrinsics with them:
        the homography's 8 parameters are determined by a 160 px view of a textured floor (the leg-camera benchmark's
        frames), and at 320 px the alignment took 20 times longer on the benchmark's 640x480 video (8 frames/s).
    min_correlation : a pair whose aligned frames correlate less (ECC's coefficient) is not measured (no texture,
        blur, a lost view).
    max_height_log_ratio : a pair whose height changes by more than this (ln) is not measured: 0.1 per frame is
        1.5 m/s up or down at 60 frames/s for a camera 0.25 m over the floor, beyond a shank's motion.
    min_translation : the floor normal (the tilt) is read only where the camera moved this fraction of its height
        between the frames; below it the decomposition cannot tell the normal from the translation.

    Attributes
    ----------
    motion_ : DataFrame, one row per frame pair: ``t_s`` (mid time), ``dt_s``, ``height_log_ratio`` (ln of the
        second frame's height over the first's), ``floor_x_per_height`` and ``floor_y_per_height`` (the camera's
        displacement along the floor projection of the image x axis and the floor direction perpendicular to it,
        on the image y axis' side, in units of its height at the first frame), ``tilt_rad`` (optical axis from the
        floor normal; NaN where not determined), ``lean_x`` and ``lean_y`` (the optical axis' part along the floor,
        in the same two directions: its sine of tilt split by direction; NaN where the tilt is), ``flow_x_pxps`` and
        ``flow_y_pxps`` (the image centre's flow, full-size px/s: the table is also a flow series, as
        :class:`CorrelationOpticalFlow`'s) and ``quality`` (ECC's correlation coefficient). Pairs not measured have
        NaN values and quality 0.

    Example
    -------
    >>> m = HomographyCameraMotion(focal_px=120, cx_px=79.5, cy_px=59.5).estimate(frames, t_s).motion_
    """

    def __init__(self, *, focal_px: float, cx_px: float, cy_px: float, blur_sigma_px: float = 1.0,
                 max_width_px: int = 160, min_correlation: float = 0.8, max_height_log_ratio: float = 0.1,
                 min_translation: float = 0.004):
        self.focal_px = focal_px
        self.cx_px = cx_px
        self.cy_px = cy_px
        self.blur_sigma_px = blur_sigma_px
        self.max_width_px = max_width_px
        self.min_correlation = min_correlation
        self.max_height_log_ratio = max_height_log_ratio
        self.min_translation = min_translation

    def _intrinsics(self, scale: float) -> np.ndarray:
        return np.array([[self.focal_px * scale, 0.0, (self.cx_px + 0.5) * scale - 0.5],
                         [0.0, self.focal_px * scale, (self.cy_px + 0.5) * scale - 0.5], [0.0, 0.0, 1.0]])

    def estimate(self, frames, t_s) -> "HomographyCameraMotion":
        """Measure every consecutive pair of ``frames`` ((N, H, W) grey) taken at ``t_s`` (N, strictly increasing)."""
        if not (math.isfinite(self.focal_px) and self.focal_px > 0):
            raise InputError(f"HomographyCameraMotion: expected a positive focal_px, found {self.focal_px!r}")
        frames, t = _as_frames(frames, t_s)
        threads = cv2.getNumThreads()
        cv2.setNumThreads(1)  # OpenCV's thread pool left running would deadlock a process forked later (pdr batch)
        try:
            self.motion_ = self._measure(frames, t)
        finally:
            cv2.setNumThreads(threads)
        return self

    def _prepared(self, frame: np.ndarray, width_px: float) -> tuple[np.ndarray, np.ndarray]:
        """A frame halved down to ``width_px``: pre-blurred, and as it is."""
        g = frame.astype(np.float32)
        while g.shape[1] > width_px + 0.5:
            g = cv2.pyrDown(g)
        return (cv2.GaussianBlur(g, (0, 0), self.blur_sigma_px) if self.blur_sigma_px > 0 else g), g

    def _aligned(self, a: np.ndarray, b: np.ndarray, prev_warp: np.ndarray | None) -> tuple[float, np.ndarray | None]:
        """ECC's best homography from ``a`` to ``b``: from the last measured pair's (the motion is smooth), from the
        global shift, from the shift aligned at half size first (a fast swing can be beyond the full size's reach),
        then from matched features (a fast turning swing, where no shift is near); the first start correlating 0.9
        or more is taken."""
        (dx, dy), _ = cv2.phaseCorrelate(a, b)
        shift = np.array([[1, 0, dx], [0, 1, dy], [0, 0, 1]], np.float32)
        best_cc, warp = -1.0, None
        for start in ([prev_warp] if prev_warp is not None else []) + [shift, "coarse", "features"]:
            if isinstance(start, str):
                start = _coarse_start(a, b, shift) if start == "coarse" else _feature_start(a, b)
                if start is None:
                    continue
            cc, w1 = _align(a, b, start)
            if cc > best_cc:
                best_cc, warp = cc, w1
            if cc >= 0.9:
                break
        return best_cc, warp

    def _measure(self, frames: np.ndarray, t: np.ndarray) -> pd.DataFrame:
        n = len(frames)
        scale = 1.0
        while frames.shape[2] * scale > self.max_width_px:
            scale /= 2.0
        k = self._intrinsics(scale)
        k_inv = np.linalg.inv(k)
        out = np.full((max(n - 1, 0), 9), np.nan)
        centre = np.array([(self.cx_px + 0.5) * scale - 0.5, (self.cy_px + 0.5) * scale - 0.5, 1.0])
        prev_warp, prev_normal = None, None
        b = self._prepared(frames[0], frames.shape[2] * scale) if n else None
        for i in range(n - 1):
            a, b = b, self._prepared(frames[i + 1], frames.shape[2] * scale)
            best_cc, warp = self._aligned(a[0], b[0], prev_warp)
            if warp is None or best_cc < self.min_correlation:
                continue
            if self.blur_sigma_px > 0:
                _, refined = _align(a[1], b[1], warp, REFINE_CRITERIA)
                warp = warp if refined is None else refined
            hn = k_inv @ warp.astype(np.float64) @ k  # maps the first view's rays to the second's
            hn /= np.linalg.svd(hn, compute_uv=False)[1]
            ratio = float(np.linalg.det(hn))
            if not (ratio > 0 and abs(math.log(ratio)) <= self.max_height_log_ratio):
                continue
            prev_warp = warp
            moved = warp.astype(np.float64) @ centre
            out[i, 0], out[i, 4] = math.log(ratio), best_cc
            out[i, 5:7] = (moved[:2] / moved[2] - centre[:2]) / scale / (t[i + 1] - t[i])
            _, rots, trans, normals = cv2.decomposeHomographyMat(warp.astype(np.float64), k)
            best = None
            for r, tr, nr in zip(rots, trans, normals):
                nr, tr = nr.ravel(), tr.ravel()
                if nr[2] > 0:  # the floor lies in front of the camera: its normal towards the camera has z < 0
                    continue
                # the one nearest the previous normal; the first one nearest the optical axis (the camera looks at
                # the floor; the other solution's normal lies along the motion)
                score = float(nr[2]) if prev_normal is None else -float(nr @ prev_normal)
                if best is None or score < best[0]:
                    best = (score, r, tr, nr)
            if best is None:
                continue
            _, r, tr, nr = best
            # the normal taken points up, towards the camera: the floor is n.X = -d, so H's translation is minus the
            # motion's and the camera's displacement in the first view's frame, in units of its height, is R^T t
            disp = r.T @ tr
            axes = _floor_axes(nr)
            out[i, 1], out[i, 2] = axes @ disp
            if np.linalg.norm(tr) >= self.min_translation:
                prev_normal = nr
                out[i, 3] = math.acos(min(1.0, abs(float(nr[2]))))
                out[i, 7:9] = axes @ (np.array([0.0, 0.0, 1.0]) - nr[2] * nr)  # the optical axis' floor part
        return pd.DataFrame({"t_s": 0.5 * (t[1:] + t[:-1]), "dt_s": np.diff(t), "height_log_ratio": out[:, 0],
                             "floor_x_per_height": out[:, 1], "floor_y_per_height": out[:, 2], "tilt_rad": out[:, 3],
                             "lean_x": out[:, 7], "lean_y": out[:, 8], "flow_x_pxps": out[:, 5], "flow_y_pxps": out[:, 6],
                             "quality": np.nan_to_num(out[:, 4])})


def _coarse_start(a: np.ndarray, b: np.ndarray, shift: np.ndarray) -> np.ndarray | None:
    """The homography aligned at half size from ``shift``, at full size (None where it does not converge)."""
    _, coarse = _align(cv2.pyrDown(a), cv2.pyrDown(b), HALF @ shift @ np.linalg.inv(HALF))
    return None if coarse is None else np.linalg.inv(HALF) @ coarse @ HALF


def _feature_start(a: np.ndarray, b: np.ndarray) -> np.ndarray | None:
    """The homography of ORB features matched between the frames (Rublee et al. 2011; cross-checked matches,
    RANSAC with 2 px), or None where fewer than 8 agree. Patches of 15 px: a 160 px frame has room for them."""
    orb = cv2.ORB_create(nfeatures=300, nlevels=4, edgeThreshold=15, patchSize=15, fastThreshold=5)
    (ka, da), (kb, db) = (orb.detectAndCompute(np.clip(f, 0, 255).astype(np.uint8), None) for f in (a, b))
    if da is None or db is None:
        return None
    matches = cv2.BFMatcher(cv2.NORM_HAMMING, crossCheck=True).match(da, db)
    if len(matches) < 8:
        return None
    pa = np.float32([ka[m.queryIdx].pt for m in matches])
    pb = np.float32([kb[m.trainIdx].pt for m in matches])
    h, inliers = cv2.findHomography(pa, pb, cv2.RANSAC, 2.0)
    return None if h is None or int(inliers.sum()) < 8 else h


def _floor_axes(normal: np.ndarray) -> np.ndarray:
    """Two orthonormal floor directions in the camera frame (rows): the image x axis projected on the floor, and the
    image y axis' projection made perpendicular to it (both follow the camera whatever its roll on the shank)."""
    x = np.array([1.0, 0.0, 0.0]) - normal[0] * normal
    x /= np.linalg.norm(x)
    y = np.cross(normal, x)
    return np.stack([x, y if y[1] >= 0 else -y])


def _align(a: np.ndarray, b: np.ndarray, start: np.ndarray, criteria=ECC_CRITERIA) -> tuple[float, np.ndarray | None]:
    """ECC's homography from ``a`` to ``b`` from ``start`` (correlation, warp), or (-1, None) where it does not
    converge (no texture, or too far from the start)."""
    try:
        return cv2.findTransformECC(a, b, start.astype(np.float32), cv2.MOTION_HOMOGRAPHY, criteria, None, 1)
    except cv2.error:
        return -1.0, None
