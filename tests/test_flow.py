"""Optical flow (Liu, MS thesis ch. 2): the thesis' synthetic tests, the same on real textures, bad input."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from pdr.errors import InputError
from pdr.flow import CorrelationOpticalFlow, InterpolationOpticalFlow, PhaseCorrelationOpticalFlow, read_video
from pdr.sim.camera import write_video
from conftest import warns

ROOT = Path(__file__).resolve().parents[1]


def _texture(name: str) -> np.ndarray:
    for base in (ROOT / "datasets", ROOT.parent / "shared" / "datasets"):
        p = base / "ground_textures_cc0" / f"{name}.png"
        if p.is_file():
            return cv2.imread(str(p), cv2.IMREAD_GRAYSCALE).astype(np.float32)
    pytest.skip("ground_textures_cc0 not found")


def _shifted(img: np.ndarray, dx: int) -> np.ndarray:
    """Frame 2 of the thesis: frame 1 moved dx px to the right, zeros entering on the left."""
    out = np.zeros_like(img)
    out[:, dx:] = img[:, : img.shape[1] - dx]
    return np.stack([img, out])


def test_interpolation_thesis_random_frames_10px():
    rng = np.random.default_rng(1)
    est = InterpolationOpticalFlow(window_px=20, ref_shift_px=10, patch_px=40, blur_sigma_px=0.0)
    u = []
    for _ in range(60):
        im = cv2.GaussianBlur(rng.random((255, 255)) * 255, (0, 0), 1.0)
        f = _shifted(im, 10)
        u.append(est.measure_pair(f[0], f[1])[0])
    assert abs(np.mean(u) - 10.0) < 0.25  # thesis: 9.95 (0.46%) over 100 trials, single trials 8-12
    assert 0.3 < np.std(u) < 2.0


def test_error_growth_shifts_1_to_19():
    rng = np.random.default_rng(2)
    im = rng.random((255, 255)).astype(np.float32) * 255
    corr = CorrelationOpticalFlow(patch_px=40, grid_step_px=40, max_shift_px=22, blur_sigma_px=0.0)
    errs = []
    for s in range(1, 20):
        f = _shifted(im, s)
        dx, dy, q = corr.measure_pair(f[0], f[1])
        assert dx == s and dy == 0 and q > 0.99  # exact on noise-free shifts, like the thesis' Fig. 8
        ii = InterpolationOpticalFlow(window_px=20, ref_shift_px=s, patch_px=40, blur_sigma_px=0.0)
        errs.append(abs(np.mean([ii.measure_pair(*_shifted(rng.random((255, 255)) * 255, s))[0] for _ in range(10)]) - s))
    assert errs[0] < 0.02


@pytest.mark.parametrize("name", ["gravel", "brick", "grass"])
def test_real_textures_known_shifts(name):
    tex = _texture(name)
    corr = CorrelationOpticalFlow(patch_px=40, grid_step_px=40, max_shift_px=22)
    phase = PhaseCorrelationOpticalFlow(patch_px=200)
    interp = InterpolationOpticalFlow(window_px=40, ref_shift_px=2, patch_px=80, blur_sigma_px=2.0, iterations=4)
    for s in (1, 4, 10, 19):
        m = np.float32([[1, 0, s + 0.3], [0, 1, -0.4]])
        moved = cv2.warpAffine(tex, m, tex.shape[::-1], flags=cv2.INTER_CUBIC, borderMode=cv2.BORDER_REFLECT)
        a, b = tex[100:400, 100:400], moved[100:400, 100:400]
        dx, dy, _ = corr.measure_pair(a, b)
        tol = 0.15 if name == "gravel" else 0.35  # brick: sub-pixel parabola biased across the mortar lines
        assert abs(dx - (s + 0.3)) < tol and abs(dy + 0.4) < tol
        pdx, pdy, _ = phase.measure_pair(a, b)
        assert abs(pdx - (s + 0.3)) < 0.3 and abs(pdy + 0.4) < 0.3  # centroid sub-pixel: coarser
        if s <= 4:
            idx, idy, _ = interp.measure_pair(a, b)
            assert abs(idx - (s + 0.3)) < 0.1 and abs(idy + 0.4) < 0.1


def test_estimate_units_and_blank_frames():
    rng = np.random.default_rng(3)
    base = cv2.GaussianBlur(rng.random((140, 180)).astype(np.float32) * 255, (0, 0), 1.5)
    frames = np.stack([np.roll(base, 2 * k, axis=1) for k in range(5)] + [np.full_like(base, 90.0)] * 2)
    t = np.arange(7) / 50.0
    flow = CorrelationOpticalFlow().estimate(frames, t).flow_
    assert list(flow.columns) == ["t_s", "dt_s", "flow_x_pxps", "flow_y_pxps", "quality"]
    np.testing.assert_allclose(flow.flow_x_pxps[:4], 100.0, atol=0.5)  # 2 px per 1/50 s
    assert np.isnan(flow.flow_x_pxps.iloc[-1]) and flow.quality.iloc[-1] == 0.0
    assert np.isnan(PhaseCorrelationOpticalFlow().estimate(frames, t).flow_.flow_x_pxps.iloc[-1])


def test_bad_input():
    frames = np.zeros((3, 100, 100), np.uint8)
    with pytest.raises(InputError, match="strictly increasing"):
        CorrelationOpticalFlow().estimate(frames, [0.0, 0.02, 0.01])
    with pytest.raises(InputError, match="one time per frame"):
        CorrelationOpticalFlow().estimate(frames, [0.0, 0.02])
    with pytest.raises(InputError, match="shape"):
        CorrelationOpticalFlow().estimate(np.zeros((100, 100)), [0.0])
    with pytest.raises(InputError, match="at least"):
        CorrelationOpticalFlow(patch_px=40, grid_step_px=40, max_shift_px=20).estimate(frames, [0, 1, 2])
    with warns(match="fewer than 2"):
        assert CorrelationOpticalFlow().estimate(frames[:1], [0.0]).flow_.empty


def test_video_round_trip_and_corrupt_files(tmp_path):
    rng = np.random.default_rng(4)
    frames = (rng.random((12, 48, 64)) * 255).astype(np.uint8)
    path = tmp_path / "video.avi"
    write_video(path, frames, 50.0)
    np.testing.assert_array_equal(read_video(path), frames)  # FFV1 is lossless
    with pytest.raises(InputError, match="frames.csv"):
        read_video(path, expected_frames=13)
    data = path.read_bytes()
    (tmp_path / "cut.avi").write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError):
        read_video(tmp_path / "cut.avi")
    (tmp_path / "junk.avi").write_bytes(b"not a video at all" * 100)
    with pytest.raises(InputError, match="unreadable|none decodable"):
        read_video(tmp_path / "junk.avi")
    with pytest.raises(InputError, match="nothing there"):
        read_video(tmp_path / "missing.avi")


def test_consensus_drops_patches_locked_on_a_repeated_pattern():
    tex = _texture("brick")
    m = np.float32([[1, 0, 7.3], [0, 1, -0.4]])
    moved = cv2.warpAffine(tex, m, tex.shape[::-1], flags=cv2.INTER_CUBIC, borderMode=cv2.BORDER_REFLECT)
    a, b = tex[100:400, 100:400], moved[100:400, 100:400]
    kw = dict(patch_px=40, grid_step_px=40, max_shift_px=22, blur_sigma_px=0.0)
    dx, dy, _ = CorrelationOpticalFlow(**kw).measure_pair(a, b)
    assert np.hypot(dx - 7.3, dy + 0.4) < 0.15
    dx, dy, _ = CorrelationOpticalFlow(**kw, consensus_px=float("inf")).measure_pair(a, b)  # the thesis' plain mean
    assert np.hypot(dx - 7.3, dy + 0.4) > 1.0
