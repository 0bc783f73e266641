"""Optical flow of a frame sequence, one global 2-D velocity per frame pair (px/s) with a quality value.

Three methods, as in Liu (MS thesis "Optical Flow Measurement of Human Walking", ch. 2):

- :class:`InterpolationOpticalFlow`: Srinivasan's image-interpolation method (eq. 2.1-2.8);
- :class:`CorrelationOpticalFlow`: normalised cross-correlation of a 3x3 grid of patches over a search zone,
  patches weighted by their peak correlation, weak peaks discarded (eq. 2.9-2.11, Appendix D);
- :class:`PhaseCorrelationOpticalFlow`: OpenCV's phase correlation (Kuglin & Hines), for comparison.

Conventions: a shift is the displacement of the image content from frame k to frame k+1, +x to the right
(columns), +y down (rows). ``flow_`` rows are stamped at the middle of their frame pair.
"""

from __future__ import annotations

from typing import Sequence

import cv2
import numpy as np
import pandas as pd

from pdr.base import Algorithm
from pdr.errors import InputError, warn

FLOW_COLUMNS = ["t_s", "dt_s", "flow_x_pxps", "flow_y_pxps", "quality"]


def _as_frames(frames: np.ndarray | Sequence[np.ndarray], t_s: np.ndarray | Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    """Validate a frame stack (N, H, W) and its time stamps (N,)."""
    try:
        arr = np.asarray(frames)
    except ValueError:
        raise InputError("frames: expected N grey images of one size, found images of different sizes") from None
    if arr.ndim == 4 and arr.shape[-1] == 3:
        arr = np.stack([cv2.cvtColor(np.ascontiguousarray(f), cv2.COLOR_BGR2GRAY) for f in arr.astype(np.uint8)])
    if arr.ndim != 3:
        raise InputError(f"frames: expected an array of shape (N, H, W), found shape {arr.shape}")
    if not np.issubdtype(arr.dtype, np.number):
        raise InputError(f"frames: expected numeric pixels, found dtype {arr.dtype}")
    arr = arr.astype(np.float32)
    if not np.isfinite(arr).all():
        raise InputError("frames: expected finite pixel values, found NaN or inf")
    t = np.asarray(t_s, dtype=float)
    if t.ndim != 1 or len(t) != len(arr):
        raise InputError(f"t_s: expected one time per frame ({len(arr)}), found {t.size}")
    if len(t) and (not np.isfinite(t).all() or (np.diff(t) <= 0).any()):
        raise InputError("t_s: expected finite, strictly increasing frame times, found repeated, unsorted or NaN times")
    return arr, t


def _empty_flow() -> pd.DataFrame:
    return pd.DataFrame({c: np.zeros(0) for c in FLOW_COLUMNS})


class _FrameFlow(Algorithm):
    """Shared driver: ``estimate`` loops over frame pairs and calls ``measure_pair``."""

    blur_sigma_px: float

    def _prepare(self, frame: np.ndarray) -> np.ndarray:
        frame = np.asarray(frame, dtype=np.float32)
        if self.blur_sigma_px > 0:
            frame = cv2.GaussianBlur(frame, (0, 0), self.blur_sigma_px, borderType=cv2.BORDER_REFLECT)
        return frame

    def measure_pair(self, frame1: np.ndarray, frame2: np.ndarray) -> tuple[float, float, float]:
        """Shift (dx_px, dy_px) of the content from ``frame1`` to ``frame2`` and its quality in [0, 1]."""
        return self._shift(self._prepare(frame1), self._prepare(frame2))

    def _shift(self, f1: np.ndarray, f2: np.ndarray) -> tuple[float, float, float]:  # pragma: no cover - abstract
        raise NotImplementedError

    def _check_size(self, shape: tuple[int, int]) -> None:
        """Raise if the frame is too small for the method's windows."""

    def estimate(self, frames: np.ndarray | Sequence[np.ndarray], t_s: np.ndarray | Sequence[float]) -> "_FrameFlow":
        """Measure the flow of every consecutive frame pair.

        Parameters
        ----------
        frames : (N, H, W) grey frames (or (N, H, W, 3) BGR), any numeric dtype.
        t_s : (N,) frame times, strictly increasing, seconds.
        """
        arr, t = _as_frames(frames, t_s)
        if len(arr) < 2:
            warn(f"{type(self).__name__}: fewer than 2 frames ({len(arr)}), no flow measured")
            self.flow_ = _empty_flow()
            self.shift_px_ = np.zeros((0, 2))
            return self
        self._check_size(arr.shape[1:])
        prepared = [self._prepare(f) for f in arr]
        shifts = np.empty((len(arr) - 1, 2))
        quality = np.empty(len(arr) - 1)
        self._reset()
        for k in range(len(arr) - 1):
            dx, dy, q = self._shift(prepared[k], prepared[k + 1])
            shifts[k] = dx, dy
            quality[k] = q
        dt = np.diff(t)
        self.shift_px_ = shifts
        self.flow_ = pd.DataFrame({
            "t_s": 0.5 * (t[1:] + t[:-1]),
            "dt_s": dt,
            "flow_x_pxps": shifts[:, 0] / dt,
            "flow_y_pxps": shifts[:, 1] / dt,
            "quality": quality,
        })
        return self

    def _reset(self) -> None:
        """Forget any state carried from pair to pair (prediction of the search zone)."""


class InterpolationOpticalFlow(_FrameFlow):
    """Srinivasan's image-interpolation optical flow on a centred sub-image.

    Parameters
    ----------
    window_px : width p of the Gaussian weighting window psi(x, y) = exp(-2.772 (x² + y²) / p²) (weights fall to
        6% at radius p), centred on the sub-image.
    ref_shift_px : the reference shifts dx_ref = dy_ref (integer pixels) of the interpolation images (eq. 2.5).
    patch_px : side of the centred square sub-image the flow is computed on; None: the largest that fits.
    blur_sigma_px : standard deviation of the Gaussian pre-blur (0: none).
    iterations : 1 is the thesis' one-shot method; more re-estimate the residual after shifting frame 2 back by
        the current estimate (sub-pixel, bilinear), which removes the bias of large shifts.

    Attributes
    ----------
    flow_ : DataFrame ``t_s, dt_s, flow_x_pxps, flow_y_pxps, quality`` (one row per frame pair); quality is the
        weighted fraction of the temporal change explained by the flow (R², 0..1).
    shift_px_ : (N-1, 2) shifts in pixels.

    Notes
    -----
    Liu, MS thesis, eq. 2.1-2.8 (after Srinivasan 1994): with f1, f2 frame 1 shifted by -/+ dx_ref in x and
    f3, f4 in y, the weighted normal equations [A B; B E][u v]' = [C F]' with A = sum psi (f2-f1)²,
    B = sum psi (f2-f1)(f4-f3), E = sum psi (f4-f3)², C = 2 sum psi (f_2nd - f0)(f2-f1), F likewise give the
    shift (u, v) dx_ref. Valid while the image is locally linear over the shift: pre-blur, small shifts.

    Example
    -------
    >>> flow = InterpolationOpticalFlow(window_px=20, ref_shift_px=10).estimate(frames, t_s).flow_
    """

    def __init__(self, *, window_px: float = 20.0, ref_shift_px: int = 10, patch_px: int | None = 40,
                 blur_sigma_px: float = 1.0, iterations: int = 1):
        self.window_px = window_px
        self.ref_shift_px = ref_shift_px
        self.patch_px = patch_px
        self.blur_sigma_px = blur_sigma_px
        self.iterations = iterations

    def _region(self, shape: tuple[int, int]) -> tuple[slice, slice, int]:
        h, w = shape
        d = int(self.ref_shift_px)
        if d < 1:
            raise InputError(f"InterpolationOpticalFlow: expected ref_shift_px >= 1, found {self.ref_shift_px}")
        side = self.patch_px if self.patch_px is not None else min(h, w) - 2 * d
        if side < 4 or side + 2 * d > min(h, w):
            raise InputError(
                f"InterpolationOpticalFlow: expected frames of at least {side + 2 * d} px per side for patch_px={side} "
                f"and ref_shift_px={d}, found {w}x{h}")
        r0, c0 = (h - side) // 2, (w - side) // 2
        return slice(r0, r0 + side), slice(c0, c0 + side), d

    def _check_size(self, shape: tuple[int, int]) -> None:
        self._region(shape)

    def _shift(self, f1: np.ndarray, f2: np.ndarray) -> tuple[float, float, float]:
        rows, cols, d = self._region(f1.shape)
        side = rows.stop - rows.start
        r = np.arange(side) - (side - 1) / 2.0
        psi = np.exp(-2.772 * (r[:, None] ** 2 + r[None, :] ** 2) / float(self.window_px) ** 2)
        f0 = f1[rows, cols]
        gx = f1[rows, cols.start - d:cols.stop - d] - f1[rows, cols.start + d:cols.stop + d]  # f2 - f1 of eq. 2.6
        gy = f1[rows.start - d:rows.stop - d, cols] - f1[rows.start + d:rows.stop + d, cols]  # f4 - f3
        a = float(np.sum(psi * gx * gx))
        b = float(np.sum(psi * gx * gy))
        e = float(np.sum(psi * gy * gy))
        det = a * e - b * b
        if not np.isfinite(det) or det <= 1e-9 * max(a * e, 1e-30):
            return float("nan"), float("nan"), 0.0
        u = v = 0.0
        f2w = f2
        for _ in range(max(1, int(self.iterations))):
            ft = f2w[rows, cols] - f0
            c = 2.0 * float(np.sum(psi * ft * gx))
            f = 2.0 * float(np.sum(psi * ft * gy))
            du = d * (e * c - b * f) / det
            dv = d * (a * f - b * c) / det
            u, v = u + du, v + dv
            if self.iterations > 1:
                m = np.float32([[1, 0, -u], [0, 1, -v]])
                f2w = cv2.warpAffine(f2, m, (f2.shape[1], f2.shape[0]), flags=cv2.INTER_LINEAR,
                                     borderMode=cv2.BORDER_REFLECT)
        # quality: weighted R² of the first-order model ft = -(u gx + v gy) / (2 d)
        ft = f2[rows, cols] - f0
        model = (u * gx + v * gy) / (2.0 * d)
        tot = float(np.sum(psi * ft * ft))
        res = float(np.sum(psi * (ft - model) ** 2))
        quality = float(np.clip(1.0 - res / tot, 0.0, 1.0)) if tot > 0 else 0.0
        return float(u), float(v), quality


class CorrelationOpticalFlow(_FrameFlow):
    """Correlation optical flow: a 3x3 grid of patches matched by normalised cross-correlation.

    Parameters
    ----------
    patch_px : side of each square patch taken from frame k.
    grid_step_px : distance between the centres of neighbouring patches of the 3x3 grid (0: one central patch).
    max_shift_px : search radius: each patch is searched in frame k+1 over a zone of +/- max_shift_px.
    min_peak_corr : patches whose correlation peak is below this are discarded (thesis: 0.5).
    blur_sigma_px : Gaussian pre-blur (thesis: sigma 1).
    subpixel : refine each peak by a parabola through its neighbours.
    predict : centre each search zone on the previous pair's shift (tracks fast motion with a small zone).
    consensus_px : patches farther than this from the median patch shift are dropped before the weighted mean
        (a repeated pattern such as brick joints can lock a patch one period off); inf keeps all, as the thesis.

    Attributes
    ----------
    flow_ : DataFrame ``t_s, dt_s, flow_x_pxps, flow_y_pxps, quality``; quality is the mean peak correlation of
        the kept patches times the fraction kept (0 when none is kept; then the flow is NaN).
    shift_px_ : (N-1, 2) shifts in pixels.

    Notes
    -----
    Liu, MS thesis, eq. 2.9-2.11 and Appendix D: the displacement is the arg max of the normalised
    cross-correlation of a patch of frame k over a zone of frame k+1; nine patches are averaged with their peak
    correlations as weights, peaks under 0.5 are discarded. Here on OpenCV's ``matchTemplate``
    (``TM_CCOEFF_NORMED``, which removes the means as the thesis does) with sub-pixel peaks.

    Example
    -------
    >>> flow = CorrelationOpticalFlow(patch_px=24, max_shift_px=12).estimate(frames, t_s).flow_
    """

    def __init__(self, *, patch_px: int = 24, grid_step_px: int = 24, max_shift_px: int = 12,
                 min_peak_corr: float = 0.5, blur_sigma_px: float = 1.0, subpixel: bool = True, predict: bool = False,
                 consensus_px: float = 1.5):
        self.patch_px = patch_px
        self.grid_step_px = grid_step_px
        self.max_shift_px = max_shift_px
        self.min_peak_corr = min_peak_corr
        self.blur_sigma_px = blur_sigma_px
        self.subpixel = subpixel
        self.predict = predict
        self.consensus_px = consensus_px

    def _reset(self) -> None:
        self._last = (0, 0)

    def _check_size(self, shape: tuple[int, int]) -> None:
        h, w = shape
        need = self.patch_px + 2 * self.grid_step_px + 2 * self.max_shift_px
        if need > min(h, w):
            raise InputError(
                f"CorrelationOpticalFlow: expected frames of at least {need}x{need} px for patch_px={self.patch_px}, "
                f"grid_step_px={self.grid_step_px}, max_shift_px={self.max_shift_px}, found {w}x{h}")

    @staticmethod
    def _parabola(m: float, c: float, p: float) -> float:
        den = m - 2.0 * c + p
        return 0.0 if den >= 0 else float(np.clip(0.5 * (m - p) / den, -0.5, 0.5))

    def _shift(self, f1: np.ndarray, f2: np.ndarray) -> tuple[float, float, float]:
        if not hasattr(self, "_last"):
            self._reset()
        h, w = f1.shape
        half, s, step = self.patch_px // 2, int(self.max_shift_px), int(self.grid_step_px)
        px, py = self._last if self.predict else (0, 0)
        cy, cx = h // 2, w // 2
        # keep the predicted zone inside the frame
        lim_x = w // 2 - step - half - s
        lim_y = h // 2 - step - half - s
        px, py = int(np.clip(px, -lim_x, lim_x)), int(np.clip(py, -lim_y, lim_y))
        shifts, weights = [], []
        for gy in (-1, 0, 1):
            for gx in (-1, 0, 1):
                if step == 0 and (gx or gy):
                    continue
                r0, c0 = cy + gy * step - half, cx + gx * step - half
                patch = f1[r0:r0 + self.patch_px, c0:c0 + self.patch_px]
                zr, zc = r0 + py - s, c0 + px - s
                zone = f2[zr:zr + self.patch_px + 2 * s, zc:zc + self.patch_px + 2 * s]
                if float(patch.std()) < 1e-3 or float(zone.std()) < 1e-3:
                    continue  # a blank patch matches everything: no information
                corr = cv2.matchTemplate(zone, patch, cv2.TM_CCOEFF_NORMED)
                _, peak, _, (bx, by) = cv2.minMaxLoc(corr)
                if not np.isfinite(peak) or peak < self.min_peak_corr:
                    continue
                sx, sy = float(bx), float(by)
                if self.subpixel and peak < 1.0 - 1e-5:  # a perfect match (to float32 rounding) is an integer shift
                    if 0 < bx < corr.shape[1] - 1:
                        sx += self._parabola(corr[by, bx - 1], corr[by, bx], corr[by, bx + 1])
                    if 0 < by < corr.shape[0] - 1:
                        sy += self._parabola(corr[by - 1, bx], corr[by, bx], corr[by + 1, bx])
                shifts.append((sx - s + px, sy - s + py))
                weights.append(peak)
        n_patches = 9 if step else 1
        if not weights:
            self._last = (0, 0)
            return float("nan"), float("nan"), 0.0
        wts = np.asarray(weights)
        sh = np.asarray(shifts)
        # consensus: a patch locked on a repeated pattern (brick joints) disagrees with the median; drop it
        med = np.median(sh, axis=0)
        keep = np.hypot(*(sh - med).T) <= self.consensus_px
        if keep.any():
            wts, sh = wts[keep], sh[keep]
        dx, dy = (wts[:, None] * sh).sum(axis=0) / wts.sum()
        self._last = (int(round(dx)), int(round(dy)))
        quality = float(wts.mean() * len(wts) / n_patches)
        return float(dx), float(dy), quality


class PhaseCorrelationOpticalFlow(_FrameFlow):
    """Global shift by OpenCV's phase correlation (``cv2.phaseCorrelate``) of the centred sub-image.

    Parameters
    ----------
    patch_px : side of the centred square used (None: the whole frame).
    blur_sigma_px : Gaussian pre-blur.
    hann_window : apodise with a Hann window (reduces the edge effect of the FFT).

    Attributes
    ----------
    flow_ : DataFrame ``t_s, dt_s, flow_x_pxps, flow_y_pxps, quality``; quality is OpenCV's peak response (0..1).
    shift_px_ : (N-1, 2) shifts in pixels.

    Notes
    -----
    Kuglin & Hines (1975) phase correlation, sub-pixel by OpenCV's 5x5 weighted centroid; added as a fast third
    option beside the thesis' two methods.

    Example
    -------
    >>> flow = PhaseCorrelationOpticalFlow().estimate(frames, t_s).flow_
    """

    def __init__(self, *, patch_px: int | None = None, blur_sigma_px: float = 0.0, hann_window: bool = True):
        self.patch_px = patch_px
        self.blur_sigma_px = blur_sigma_px
        self.hann_window = hann_window

    def _crop(self, f: np.ndarray) -> np.ndarray:
        if self.patch_px is None:
            return f
        h, w = f.shape
        side = int(self.patch_px)
        if side > min(h, w):
            raise InputError(f"PhaseCorrelationOpticalFlow: expected frames of at least {side} px per side, found {w}x{h}")
        r0, c0 = (h - side) // 2, (w - side) // 2
        return f[r0:r0 + side, c0:c0 + side]

    def _check_size(self, shape: tuple[int, int]) -> None:
        self._crop(np.zeros(shape, np.float32))

    def _shift(self, f1: np.ndarray, f2: np.ndarray) -> tuple[float, float, float]:
        a, b = np.ascontiguousarray(self._crop(f1)), np.ascontiguousarray(self._crop(f2))
        if float(a.std()) < 1e-3 or float(b.std()) < 1e-3:
            return float("nan"), float("nan"), 0.0
        win = cv2.createHanningWindow(a.shape[::-1], cv2.CV_32F) if self.hann_window else None
        (dx, dy), response = cv2.phaseCorrelate(a, b, win)
        return float(dx), float(dy), float(np.clip(response, 0.0, 1.0))
