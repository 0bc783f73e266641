"""Leg camera: optical-flow accuracy (thesis ch. 2 tests, real textures), speed, and stride length from rendered walks.

The walks are the simulator's ``pdr.sim.gait.WalkKinematics`` (Fourier hip/knee/ankle curves, rocker-sole stance feet
without slip, double support, per-step variability; written by another work stream) rendered by
``pdr.sim.camera`` - a richer model than the SLIP the SLIP-OF fits, and a walk the floor odometry knows nothing of.

Stride length is measured on simulated people with both stride methods, the floor odometry (the default:
``pdr.flow.HomographyCameraMotion`` + ``pdr.slip.FloorOdometryStride``) and the SLIP-OF (``[leg_camera] method =
"slip_of"``): a tuning group (on which the odometry's sigma spreads and the SLIP-OF's swing-clearance ratio, flow
pre-blur, failure threshold and sigma floor were chosen) and a test group of other people, each person with a drawn
leg proportion (Bogin & Varela-Silva 2010), knee height within the leg (``KNEE_SCALE_SD``) and step-length law
(``GaitUser``; healthy and older cohorts), at three speeds, on three real floors (gravel, brick, grass), with two
camera set-ups. The estimators are given what a user knows: the height and the leg length tape-measured (+-1 cm),
the camera's mount distance below the knee measured (+-0.5 cm), the camera intrinsics; the segment lengths come from
Winter's ratios (``SlipBody.from_user``); each group is read again with the walks' true body and mount (what no user
knows: the bound of better body measurements), the odometry also with the shank (knee to ankle) tape-measured.
The SLIP-OF's rows also give its strides read from the measured flow with the walks' true camera geometry (the
flow's own error, apart from the model's). Both methods are scored after a per-user calibration (the scale ``pdr
calibrate`` stores, ``pdr.slip.calibrated_length_scale`` with the method's spreads) on one walk of each person, a
known distance over that walk's strides: the scale is fitted there once and the person's other walks are scored,
never the calibration walk.
"""

from __future__ import annotations

import dataclasses
import time

import cv2
import numpy as np

from pdr.flow import CorrelationOpticalFlow, HomographyCameraMotion, InterpolationOpticalFlow, PhaseCorrelationOpticalFlow
from pdr.errors import collect_warnings
from pdr.pipelines.calibrate import SCALE_SPREADS
from pdr.pipelines.leg_camera import cut_strides, flow_defaults, forward_flow
from pdr.sim.camera import TEXTURES, CameraModel, load_texture, render_leg_camera
from pdr.sim.gait import WalkKinematics
from pdr.sim.people import FOOT_RATIO, KNEE_SCALE_SD, LEG_SCALE_SD, Body, GaitUser, plan_walk
from pdr.sim.simulator import MEASURE_STD_M, MOUNT_STD_M
from pdr.sim.route import Route
from pdr.pipelines.calibrate import KNOWN_DISTANCE_REL_STD
from pdr.slip import FloorOdometryStride, SlipOpticalFlowStride, calibrated_length_scale
from pdr.slip.model import ANKLE_HEIGHT_RATIO, SlipBody

AREA = "leg_camera"
THESIS = "Liu MS thesis"
# Two camera set-ups: 100 fps with a 67 deg wide view 0.25 m below the knee; 60 fps, 77 deg, 0.17 m below the knee.
CAMERAS = {
    "100 fps": CameraModel(fps=100.0, focal_px=120.0, cx_px=79.5, cy_px=59.5, width_px=160, height_px=120,
                           segment="shank_left", distance_from_knee_m=0.25),
    "60 fps": CameraModel(fps=60.0, focal_px=100.0, cx_px=79.5, cy_px=59.5, width_px=160, height_px=120,
                          segment="shank_left", distance_from_knee_m=0.17),
}
CAM = CAMERAS["100 fps"]
SPEEDS_MPS = (0.8, 1.2, 1.6)
# simulated people (height m, seed, cohort); the two groups share no one
TUNING_PEOPLE = ((1.55, 11, "healthy"), (1.68, 12, "older"), (1.80, 13, "healthy"), (1.92, 14, "healthy"))
TEST_PEOPLE = ((1.50, 21, "healthy"), (1.62, 22, "healthy"), (1.74, 23, "older"), (1.86, 24, "healthy"),
               (1.95, 25, "healthy"))
# the per-user calibration walk: each person's walk nearest this speed (the slower on a tie), whatever its camera and
# floor - a comfortable pace, where a user walks a known distance; declared before any calibrated walk was scored
CALIBRATION_SPEED_MPS = 1.2


def _row(case, metric, ours, unit, target, anchor):
    return {"area": AREA, "case": case, "metric": metric, "ours": float(ours), "unit": unit, "target": target, "anchor": anchor}


def _shift(img, dx):
    out = np.zeros_like(img)
    out[:, dx:] = img[:, : img.shape[1] - dx]
    return out


def _flow_rows(quick: bool) -> list[dict]:
    rows = []
    rng = np.random.default_rng(0)
    n = 30 if quick else 100
    interp = InterpolationOpticalFlow(window_px=20, ref_shift_px=10, patch_px=40, blur_sigma_px=0.0)
    corr = CorrelationOpticalFlow(patch_px=40, grid_step_px=40, max_shift_px=22, blur_sigma_px=0.0)
    u_i, u_c = [], []
    for _ in range(n):
        im = cv2.GaussianBlur(rng.random((255, 255)) * 255, (0, 0), 1.0).astype(np.float32)
        im2 = _shift(im, 10)
        u_i.append(interp.measure_pair(im, im2)[0])
        u_c.append(corr.measure_pair(im, im2)[0])
    rows.append(_row("random 255x255, 10 px", "interpolation rel. error of the mean", 100 * abs(np.mean(u_i) - 10) / 10, "%",
                     "<= 0.5", f"0.46% ({THESIS}, Fig. 3, 100 trials)"))
    rows.append(_row("random 255x255, 10 px", "correlation max abs error", np.max(np.abs(np.array(u_c) - 10)), "px",
                     "0 (exact)", f"exact ({THESIS}, Fig. 7)"))
    for s in (1, 19):
        est = InterpolationOpticalFlow(window_px=20, ref_shift_px=s, patch_px=40, blur_sigma_px=0.0)
        u = [est.measure_pair(im := rng.random((255, 255)).astype(np.float32) * 255, _shift(im, s))[0] for _ in range(n)]
        anchor = "0.03%" if s == 1 else "9.20%"
        rows.append(_row(f"random 255x255, {s} px", "interpolation rel. error of the mean", 100 * abs(np.mean(u) - s) / s, "%",
                         "-", f"{anchor} ({THESIS}, Fig. 4)"))
    for name in TEXTURES:
        tex = load_texture(name).astype(np.float32)
        errs = {"correlation": [], "phase": [], "interpolation (<= 4 px)": []}
        phase = PhaseCorrelationOpticalFlow(patch_px=200)
        it = InterpolationOpticalFlow(window_px=40, ref_shift_px=2, patch_px=80, blur_sigma_px=2.0, iterations=4)
        for s in range(1, 20):
            m = np.float32([[1, 0, s + 0.3], [0, 1, -0.4]])
            moved = cv2.warpAffine(tex, m, tex.shape[::-1], flags=cv2.INTER_CUBIC, borderMode=cv2.BORDER_REFLECT)
            a, b = tex[100:400, 100:400], moved[100:400, 100:400]
            for key, est in (("correlation", corr), ("phase", phase)):
                dx, dy, _ = est.measure_pair(a, b)
                errs[key].append(np.hypot(dx - s - 0.3, dy + 0.4))
            if s <= 4:
                dx, dy, _ = it.measure_pair(a, b)
                errs["interpolation (<= 4 px)"].append(np.hypot(dx - s - 0.3, dy + 0.4))
        for key, e in errs.items():
            rows.append(_row(f"{name} texture, shifts 1.3-19.3 px", f"{key} mean abs error", np.mean(e), "px", "-",
                             "no real-texture test in the thesis"))
    return rows


def _speed_rows() -> list[dict]:
    tex = cv2.resize(load_texture("gravel"), (1400, 1000))
    frames = np.stack([tex[100 + 3 * i:580 + 3 * i, 100 + 5 * i:740 + 5 * i] for i in range(61)])
    t = np.arange(61) / 30.0
    est = CorrelationOpticalFlow(patch_px=48, grid_step_px=120, max_shift_px=16)
    est.estimate(frames[:3], t[:3])
    t0 = time.perf_counter()
    est.estimate(frames, t)
    fps = 60 / (time.perf_counter() - t0)
    motion = HomographyCameraMotion(focal_px=500.0, cx_px=319.5, cy_px=239.5)
    t0 = time.perf_counter()
    motion.estimate(frames, t)
    motion_fps = 60 / (time.perf_counter() - t0)
    return [_row("640x480 video", "correlation flow speed (3x3 patches of 48 px, +/-16 px)", fps, "frames/s", ">= 60",
                 "thesis: offline, no speed given"),
            _row("640x480 video", "homography camera motion speed (quartered to 160x120)", motion_fps, "frames/s", "-", "-")]


@dataclasses.dataclass
class Person:
    """A simulated person and what the user tells the estimator."""

    body: Body
    user: GaitUser
    known: dict
    seed: int


@dataclasses.dataclass(frozen=True)
class Table1Body(Body):
    """The thesis' Table 1 body (Liu §4.4, measured with a ruler): thigh 0.5 m (Winter's thigh of a 2.04 m height),
    shank 0.6 m knee to ground and a 0.2 m foot - not Winter's proportions, whose foot for that height is 0.31 m."""

    foot_m = property(lambda self: 0.2)
    shank_m = property(lambda self: 0.6 - self.ankle_height_m)


def person(height_m: float, seed: int, cohort: str) -> Person:
    rng = np.random.default_rng([seed, 1])
    leg_scale = float(np.clip(1.0 + LEG_SCALE_SD * rng.standard_normal(), 0.9, 1.1))
    user = GaitUser.draw(rng, cohort=cohort)
    knee_scale = float(np.clip(1.0 + KNEE_SCALE_SD * np.random.default_rng([seed, 4]).standard_normal(), 0.92, 1.08))
    body = Body(height_m, leg_scale, knee_scale)
    tape = np.random.default_rng([seed, 2]).standard_normal(4)
    known = dict(height_m=height_m + MEASURE_STD_M * tape[0], leg_length_m=body.leg_length_m + MEASURE_STD_M * tape[1],
                 mount_error_m=MOUNT_STD_M * tape[2], shank_length_m=body.shank_m + MEASURE_STD_M * tape[3])
    return Person(body, user, known, seed)


def _walk_of(p: Person, speed_mps: float, duration_s: float) -> WalkKinematics:
    rng = np.random.default_rng([p.seed, 3, int(round(10 * speed_mps))])
    bouts = plan_walk([(1.0, 0.0), (duration_s, speed_mps), (1.0, 0.0)], p.user, p.body, rng)
    return WalkKinematics(p.body, p.user, bouts, Route.straight(speed_mps * duration_s * 1.5 + 50.0))


def _render(kin, cam, texture, duration_s, seed):
    """The walk's flow and camera motion, the render time per frame and the two measurements' frames per second."""
    t0 = time.perf_counter()
    frames, table = render_leg_camera(kin, cam, 0.5, duration_s + 1.5, load_texture(texture), seed=seed)
    render_s = (time.perf_counter() - t0) / len(frames)
    t0 = time.perf_counter()
    flow = CorrelationOpticalFlow(**flow_defaults(*frames.shape[1:])).estimate(frames, table.t_s).flow_
    flow_fps = len(frames) / (time.perf_counter() - t0)
    t0 = time.perf_counter()
    motion = HomographyCameraMotion(focal_px=cam.focal_px, cx_px=cam.cx_px, cy_px=cam.cy_px).estimate(frames, table.t_s).motion_
    return flow, motion, render_s, flow_fps, len(frames) / (time.perf_counter() - t0)


def estimator_for(p: Person, cam: CameraModel, **params) -> SlipOpticalFlowStride:
    """The SLIP-OF as a user sets it up: body from the height and the measured leg length, the mount measured;
    ``params`` override any of it."""
    body = SlipBody.from_user(p.known["height_m"], leg_length_m=p.known["leg_length_m"])
    return SlipOpticalFlowStride(**{"thigh_length_m": body.thigh_length_m, "shank_length_m": body.shank_length_m,
                                    "foot_length_m": body.foot_length_m, "focal_px": cam.focal_px, "foot": cam.side,
                                    "camera_from_knee_m": cam.distance_from_knee_m + p.known["mount_error_m"],
                                    **params})


def true_body_params(p: Person, cam: CameraModel) -> dict:
    """What no user knows, handed over to bound the model's own error: the rendered body's thigh and knee height
    (knee to floor, the SLIP's shank) and the camera's exact mount."""
    return dict(thigh_length_m=p.body.thigh_m, shank_length_m=p.body.shank_m + p.body.ankle_height_m,
                camera_from_knee_m=cam.distance_from_knee_m)


def odometry_for(p: Person, cam: CameraModel, *, shank_measured: bool = False, true_body: bool = False,
                 **params) -> FloorOdometryStride:
    """The floor odometry as a user sets it up (the knee's height from the height and the measured leg length, or
    the measured shank; the mount measured), or with the walk's ``true_body`` and mount; ``params`` override."""
    if true_body:
        body = dict(shank_length_m=p.body.shank_m + p.body.ankle_height_m, ankle_height_m=p.body.ankle_height_m,
                    camera_from_knee_m=cam.distance_from_knee_m)
    else:
        shank = {"shank_length_m": p.known["shank_length_m"]} if shank_measured else {}
        slip = SlipBody.from_user(p.known["height_m"], leg_length_m=p.known["leg_length_m"], **shank)
        body = dict(shank_length_m=slip.shank_length_m, ankle_height_m=ANKLE_HEIGHT_RATIO * p.known["height_m"],
                    camera_from_knee_m=cam.distance_from_knee_m + p.known["mount_error_m"])
    return FloorOdometryStride(**{**body, "foot": cam.side, **params})


def _fit_odometry(est, motion):
    with collect_warnings():
        est.estimate(motion, cut_strides(motion))
    return est


def _fit(est, flow):
    with collect_warnings():
        est.estimate(flow.t_s.to_numpy(), forward_flow(flow), flow.quality.to_numpy())
    return est


def _matched(est, kin, side="left", t_range=None) -> tuple[np.ndarray, int]:
    """(estimated, true, sigma) of the estimated strides matched to true ones by start time; number of true strides
    inside the rendered flow."""
    true = kin.true_strides()
    true = true[true.foot == side]
    if t_range is not None:
        true = true[(true.t_start_s >= t_range[0]) & (true.t_end_s <= t_range[1])]
    ts, tl = true.t_start_s.to_numpy(), true.length_m.to_numpy()
    out = []
    for r in est.strides_.itertuples():
        k = int(np.argmin(np.abs(ts - r.t_start_s))) if len(ts) else -1
        if k >= 0 and abs(ts[k] - r.t_start_s) < 0.1:
            out.append((r.length_m, tl[k], r.length_std_m))
    return np.array(out).reshape(-1, 3), len(tl)


def _score(est, kin, cam, t_range) -> dict:
    """The fitted walk's matched (estimated, true, sigma) strides, its true strides in the flow and, of them, those
    in failed fits."""
    pairs, n_true = _matched(est, kin, cam.side, t_range)
    failed = 0
    fits = getattr(est, "fits_", None)
    if fits is not None and len(fits) and "flag" in fits:
        failed = int(round(n_true * fits.flag.astype(bool).to_numpy().mean()))
    return dict(pairs=pairs, n_true=n_true, n_failed=failed)


def _calibrated(results: list[dict], method: str = "odometry") -> list[dict]:
    """Each person's walks other than the calibration walk (``CALIBRATION_SPEED_MPS``), read by the stride ``method``
    ("odometry" or "slip_of") with the scale ``pdr calibrate`` would store (:func:`pdr.slip.calibrated_length_scale`
    with the method's spreads) from that walk: its known length the true length of the strides the estimator found
    there (a distance measured to 1%), against their length at scale 1. The body and the scale carry over to the
    other walks; the camera's intrinsics and mount are those of each walk's own set-up. A person whose calibration
    walk gives no stride has no calibrated walk."""
    out = []
    person_std, walk_std = SCALE_SPREADS[method]
    for spec in dict.fromkeys(r["spec"] for r in results):
        walks = [r for r in results if r["spec"] == spec]
        cal = min(walks, key=lambda r: (abs(r["speed"] - CALIBRATION_SPEED_MPS), r["speed"]))
        if not len(cal["pairs"]):
            continue
        known = float(cal["pairs"][:, 1].sum())
        scale, scale_std = calibrated_length_scale([known], [float(cal["pairs"][:, 0].sum())],
                                                   [KNOWN_DISTANCE_REL_STD * known], [0], person_std=person_std,
                                                   walk_std=walk_std)
        p = person(*spec)
        for r in walks:
            if r is not cal:
                cam = CAMERAS[r["camera"]]
                if method == "odometry":
                    est = _fit_odometry(odometry_for(p, cam, length_scale=scale, length_scale_std=scale_std),
                                        r["motion"])
                else:
                    est = _fit(estimator_for(p, cam, length_scale=scale), r["flow"])
                same = "same camera set-up as" if r["camera"] == cal["camera"] else "other camera set-up than"
                # the flow-alone readings do not depend on the calibration: they stay with the uncalibrated rows
                kept = {k: v for k, v in r.items() if not k.startswith("true_")}
                out.append({**kept, **_score(est, r["kin"], cam, r["t_range"]), "uncalibrated": r["pairs"],
                            "calibration": f"{same} the calibration walk"})
    return out


def _walk_error_spread(results: list[dict]) -> tuple[float, float, float]:
    """SD (%) of the walks' mean stride errors within a person (pooled), SD of the people's means between them and
    their RMS about none: what the spreads of the per-user scale (:data:`pdr.slip.odometry.ODOMETRY_PERSON_STD` /
    ``ODOMETRY_WALK_STD``, :data:`pdr.slip.fit.SCALE_PERSON_STD` / ``SCALE_WALK_STD``) were read from (tuning group)."""
    by_person: dict = {}
    for r in results:
        if len(r["pairs"]):
            by_person.setdefault(r["spec"], []).append(100 * np.mean(r["pairs"][:, 0] / r["pairs"][:, 1] - 1))
    groups = [np.array(v) for v in by_person.values() if len(v) >= 2]
    if not groups:
        return np.nan, np.nan, np.nan
    within = float(np.sqrt(sum(((g - g.mean()) ** 2).sum() for g in groups) / sum(len(g) - 1 for g in groups)))
    means = np.array([g.mean() for g in groups])
    between = float(np.std(means, ddof=1)) if len(means) >= 2 else np.nan
    return within, between, float(np.sqrt(np.mean(means ** 2)))


def _true_camera_pose(kin, cam, t) -> tuple[np.ndarray, np.ndarray]:
    """The rendered walk's camera position (m) and its segment's rotation (camera axes in the columns) at ``t``."""
    knee = np.asarray(kin.joint_positions_m(t)[f"knee_{cam.side}"], float)
    rot = np.asarray(kin.segment_rotation(t, cam.segment), float)
    return knee + cam.distance_from_knee_m * rot[:, :, 2], rot


def _true_metres_per_flow(kin, cam, t) -> np.ndarray:
    """h / cos^2(theta) of the rendered walk's camera at ``t`` (its height over the floor and its optical axis
    from the vertical): the flow at the image centre times this is the floor's speed times the focal length."""
    position, rot = _true_camera_pose(kin, cam, t)
    return position[:, 2] / rot[:, 2, 2] ** 2


def _stride_errors(kin, cam, t, metres_px, t_range) -> np.ndarray:
    """Relative errors of the camera foot's true strides inside ``t_range`` read as (1/f) x the integral over each
    stride of ``metres_px`` (flow times h / cos^2(theta), m px/s)."""
    true = kin.true_strides()
    true = true[(true.foot == cam.side) & (true.t_start_s >= t_range[0]) & (true.t_end_s <= t_range[1])]
    out = []
    for r in true.itertuples():
        m = (t >= r.t_start_s) & (t <= r.t_end_s)
        out.append(np.trapezoid(metres_px[m], t[m]) / cam.focal_px / r.length_m - 1)
    return np.array(out)


def _true_geometry_errors(kin, cam, flow, t_range) -> np.ndarray:
    """Relative errors of strides read from the measured flow with the walk's true camera geometry: s = (1/f) x
    the integral of F h / cos^2(theta) over the stride (h the camera height, theta the optical axis from the
    vertical; exact for the flow at the image centre in the sagittal plane over a flat floor). What is left is
    the flow's own error, the bound of any model of the camera geometry."""
    t = flow.t_s.to_numpy()
    f = forward_flow(flow)
    ok = np.isfinite(f)
    f = np.interp(t, t[ok], f[ok])  # gaps bridged as the estimator bridges them
    return _stride_errors(kin, cam, t, f * _true_metres_per_flow(kin, cam, t), t_range)


def _true_displacement_errors(kin, cam, flow, t_range) -> np.ndarray:
    """Relative errors of strides read as :func:`_true_geometry_errors` does, from the true image displacement over
    each frame interval of the floor point at the image centre (the walk's camera poses, no blur) instead of the
    measured flow: what a perfect tracker of the central patch reads with the instantaneous geometry. The model
    predicts this displacement (``SlipOpticalFlowStride.frame_interval_s``)."""
    t = flow.t_s.to_numpy()
    dt = flow.dt_s.to_numpy()
    c0, r0 = _true_camera_pose(kin, cam, t - 0.5 * dt)
    c1, r1 = _true_camera_pose(kin, cam, t + 0.5 * dt)
    axis = r0[:, :, 2]
    ground = c0 - (c0[:, 2] / axis[:, 2])[:, None] * axis  # floor point on the optical axis
    xc = np.einsum("nji,nj->ni", r1, ground - c1)  # in the camera frame at the interval's end
    f = -cam.focal_px * xc[:, 0] / xc[:, 2] / dt  # forward flow, px/s
    return _stride_errors(kin, cam, t, f * _true_metres_per_flow(kin, cam, t), t_range)


def walk_cases(people, speeds, quick: bool):
    """(person spec, speed, camera, texture) of every walk: each person walks every speed; cameras and floors
    alternate so that every person sees both cameras and every floor."""
    out = []
    for i, spec in enumerate(people):
        for j, v in enumerate(speeds):
            out.append((spec, v, list(CAMERAS)[(i + j) % 2], TEXTURES[(i + j) % len(TEXTURES)] if not quick else "gravel"))
    return out


def _group_rows(name: str, data: str, results: list[dict], splits: tuple[str, ...] = ("camera", "texture")
                ) -> list[dict]:
    """The group's rows; ``splits``: the walk keys whose values get a stride MAE row each (a camera's name, a floor's,
    or a calibrated walk's camera against its calibration walk's)."""
    rows = []
    pairs = np.concatenate([r["pairs"] for r in results]) if results else np.zeros((0, 3))
    n_true = sum(r["n_true"] for r in results)
    n_failed = sum(r["n_failed"] for r in results)
    rel = pairs[:, 0] / pairs[:, 1] - 1 if len(pairs) else np.zeros(0)
    walk_mae = [100 * np.mean(np.abs(r["pairs"][:, 0] / r["pairs"][:, 1] - 1)) for r in results if len(r["pairs"])]
    worst = max(range(len(walk_mae)), key=walk_mae.__getitem__) if walk_mae else None
    case = f"{name} ({len({r['spec'] for r in results})} people, {len(results)} walks, {len(pairs)} strides; {data})"
    anchor = f"10% ({THESIS}, 1.08 m vs 1.20 m, one trial)"
    rows.append(_row(case, "stride length MAE", 100 * np.mean(np.abs(rel)) if len(rel) else np.nan, "%", "<= 3", anchor))
    if results and all("uncalibrated" in r for r in results):
        before = np.concatenate([r["uncalibrated"] for r in results])
        rows.append(_row(case, "stride length MAE of the same walks uncalibrated",
                         100 * np.mean(np.abs(before[:, 0] / before[:, 1] - 1)), "%", "-", "-"))
    elif results:
        within, between, rms = _walk_error_spread(results)
        rows.append(_row(case, "walks' mean stride error, SD within a person (pooled)", within, "%", "-", "-"))
        rows.append(_row(case, "people's mean stride error, SD between them", between, "%", "-", "-"))
        rows.append(_row(case, "people's mean stride error, RMS", rms, "%", "-", "-"))
    if worst is not None:
        w = results[worst]
        rows.append(_row(case, f"worst walk MAE ({w['spec'][0]:.2f} m, {w['speed']} m/s, {w['camera']}, {w['texture']})",
                         walk_mae[worst], "%", "<= 6", "-"))
    rows.append(_row(case, "strides found (of the true strides in the video)", 100 * len(pairs) / max(n_true, 1), "%",
                     ">= 90", "-"))
    rows.append(_row(case, "strides in failed fits (no scale of their own)", 100 * n_failed / max(n_true, 1), "%", "< 5", "-"))
    for v in sorted({r["speed"] for r in results}):
        sel = [r["pairs"] for r in results if r["speed"] == v and len(r["pairs"])]
        if sel:
            p = np.concatenate(sel)
            rows.append(_row(case, f"stride length bias at {v} m/s", 100 * np.mean(p[:, 0] / p[:, 1] - 1), "%",
                             "within +-2", "-"))
    labels = dict(camera="{} camera", texture="{} floor", calibration="{}")
    for key, value in [(k, v) for k in splits for v in dict.fromkeys(r[k] for r in results)]:
        sel = [r["pairs"] for r in results if r[key] == value and len(r["pairs"])]
        if sel:
            p = np.concatenate(sel)
            rows.append(_row(case, f"stride length MAE, {labels[key].format(value)}",
                             100 * np.mean(np.abs(p[:, 0] / p[:, 1] - 1)), "%", "-", "-"))
    geo = np.concatenate([r["true_geometry"] for r in results if "true_geometry" in r] or [np.zeros(0)])
    if len(geo):
        rows.append(_row(case, "flow error alone: stride from the measured flow with the true camera geometry, bias",
                         100 * np.mean(geo), "%", "-", "-"))
        geo_walks = [r for r in results if len(r.get("true_geometry", ()))]
        geo_mae = [100 * np.mean(np.abs(r["true_geometry"])) for r in geo_walks]
        w = geo_walks[int(np.argmax(geo_mae))]
        rows.append(_row(case, "flow error alone, stride MAE", 100 * np.mean(np.abs(geo)), "%", "-", "-"))
        rows.append(_row(case, f"flow error alone, worst walk MAE ({w['spec'][0]:.2f} m, {w['speed']} m/s, {w['camera']}, "
                         f"{w['texture']}): a tracker failure where far above the bias", max(geo_mae), "%", "-", "-"))
        disp = np.concatenate([r["true_displacement"] for r in results])
        rows.append(_row(case, "of it, the frame interval: the true displacement at the image centre read so, bias",
                         100 * np.mean(disp), "%", "-", "-"))
    if len(pairs):
        z = np.abs(pairs[:, 0] - pairs[:, 1]) / pairs[:, 2]
        rows.append(_row(case, "errors within 2 sigma", 100 * np.mean(z < 2), "%", "~95", "a Gaussian sigma covers 95% at 2 sigma"))
        rms_ratio = np.sqrt(np.mean((pairs[:, 0] - pairs[:, 1]) ** 2) / np.mean(pairs[:, 2] ** 2))
        rows.append(_row(case, "RMS error over RMS sigma", rms_ratio, "-", "~1", "an honest sigma: 1"))
    return rows


@dataclasses.dataclass(frozen=True)
class FootScaledBody(Body):
    """A body whose foot is ``foot_factor`` times Winter's for its height, all else as :class:`Body`."""

    foot_factor: float = 1.0
    foot_m = property(lambda self: self.foot_factor * FOOT_RATIO * self.height_m)


FOOT_FACTORS = (0.8, 1.25)


def _foot_rows(duration_s: float) -> list[dict]:
    """The tuning people with feet :data:`FOOT_FACTORS` times Winter's (1.2 m/s, 100 fps, gravel), read by the floor
    odometry and by the SLIP-OF as a user sets it up (the toe lever Winter's foot for the height), then with the
    SLIP's toe lever set to the true foot: why :meth:`pdr.slip.model.SlipBody.from_user` takes no measured foot."""
    errors: dict[str, list] = {"floor odometry": [], "SLIP-OF, toe lever Winter's foot": [],
                               "SLIP-OF, toe lever the true foot": []}
    for spec in TUNING_PEOPLE:
        p0 = person(*spec)
        for factor in FOOT_FACTORS:
            p = Person(FootScaledBody(p0.body.height_m, p0.body.leg_scale, p0.body.knee_scale, foot_factor=factor),
                       p0.user, p0.known, p0.seed)
            kin = _walk_of(p, 1.2, duration_s)
            flow, motion, _, _, _ = _render(kin, CAM, "gravel", duration_s, seed=3)
            ests = [_fit_odometry(odometry_for(p, CAM), motion)]
            ests += [_fit(estimator_for(p, CAM, **extra), flow) for extra in ({}, {"foot_length_m": p.body.foot_m})]
            for key, est in zip(errors, ests):
                pairs, _ = _matched(est, kin, CAM.side)
                errors[key].append(pairs[:, 0] / pairs[:, 1] - 1)
    case = (f"tuning people with feet {' and '.join(map(str, FOOT_FACTORS))} x Winter's "
            f"({len(TUNING_PEOPLE) * len(FOOT_FACTORS)} walks, 1.2 m/s, 100 fps, gravel)")
    rows = []
    for key, per_walk in errors.items():
        rel = np.concatenate(per_walk)
        rows.append(_row(case, f"stride length MAE, {key}", 100 * np.mean(np.abs(rel)), "%", "<= 3", "-"))
        rows.append(_row(case, f"largest walk bias, {key}", 100 * max(abs(np.mean(e)) for e in per_walk if len(e)),
                         "%", "<= 6", "-"))
    return rows


# the rows of the groups read with the shank measured too
SHANK_ROWS = ("stride length MAE", "strides found (of the true strides in the video)", "errors within 2 sigma")


def _headline(rows: list[dict]) -> list[dict]:
    """A variant group's rows that matter beside the group's own: MAE, found, within 2 sigma, worst walk, bias."""
    return [r for r in rows if r["metric"] in SHANK_ROWS or r["metric"].startswith(("worst walk", "stride length bias"))]
THESIS_MODEL = dict(swing_profile="parabola", integral_weight=0.0, duration_weight=50.0, length_from="model")


def run(quick: bool = False) -> list[dict]:
    rows = _flow_rows(quick) + _speed_rows()
    duration = 8.0 if quick else 12.0
    tuning = TUNING_PEOPLE[1:3] if quick else TUNING_PEOPLE
    test = TEST_PEOPLE[:2] if quick else TEST_PEOPLE
    speeds = SPEEDS_MPS[::2] if quick else SPEEDS_MPS
    fit_times, render_ms, flow_fps, motion_fps = [], [], [], []
    slip = "SLIP-OF ([leg_camera] method = \"slip_of\": the SLIP fitted to the flow)"
    true_body = "the walk's true body and mount given (knee and ankle height, camera below the knee: the model's own error)"
    for name, data, people in (("tuning group", "in-sample", tuning), ("test group", "left out", test)):
        res: dict[str, list] = {k: [] for k in ("odometry", "shank", "true", "slip", "slip_true")}
        for spec, v, cam_name, tex in walk_cases(people, speeds, quick):
            p = person(*spec)
            cam = CAMERAS[cam_name]
            kin = _walk_of(p, v, duration)
            flow, motion, r_s, f_fps, m_fps = _render(kin, cam, tex, duration, seed=len(render_ms))
            render_ms.append(1e3 * r_s)
            flow_fps.append(f_fps)
            motion_fps.append(m_fps)
            t_range = (float(flow.t_s.iloc[0]), float(flow.t_s.iloc[-1]))
            walk = dict(spec=spec, speed=v, camera=cam_name, texture=tex, flow=flow, motion=motion, kin=kin,
                        t_range=t_range)
            for key, est in (("odometry", odometry_for(p, cam)), ("shank", odometry_for(p, cam, shank_measured=True)),
                             ("true", odometry_for(p, cam, true_body=True))):
                res[key].append({**walk, **_score(_fit_odometry(est, motion), kin, cam, t_range)})
            est = _fit(estimator_for(p, cam), flow)
            fit_times += est.fits_.time_s.tolist()
            res["slip"].append({**walk, **_score(est, kin, cam, t_range),
                                "true_geometry": _true_geometry_errors(kin, cam, flow, t_range),
                                "true_displacement": _true_displacement_errors(kin, cam, flow, t_range)})
            est = _fit(estimator_for(p, cam, **true_body_params(p, cam)), flow)
            res["slip_true"].append({**walk, **_score(est, kin, cam, t_range)})
        rows += _group_rows(name, data, res["odometry"])
        rows += _headline(_group_rows(f"{name}, shank measured too (knee to ankle, +-1 cm)", data, res["shank"]))
        rows += _headline(_group_rows(f"{name}, {true_body}", data, res["true"]))
        rows += _group_rows(f"{name}, calibrated on one walk (each person's walk nearest {CALIBRATION_SPEED_MPS} m/s, "
                            "whatever its camera and floor; not scored)", data, _calibrated(res["odometry"]),
                            splits=("calibration", "texture"))
        rows += _group_rows(f"{name}, {slip}", data, res["slip"])
        rows += _headline(_group_rows(f"{name}, {slip}, {true_body}", data, res["slip_true"]))
        rows += _headline(_group_rows(f"{name}, {slip}, calibrated on one walk", data,
                                      _calibrated(res["slip"], "slip_of"), splits=()))
    if not quick:
        rows += _foot_rows(duration)
    # the thesis set-up (Liu §4.3-4.4): its Table 1 body walking its trial, 1.20 m strides (the markers), six strides
    # in 9 s (0.8 m/s); Table 1's thigh and shank handed over as a user's measurements (its foot is not used: the
    # SLIP's toe lever is Winter's foot for the height), then the toe lever set to Table 1's foot
    thesis, speed = Table1Body(0.5 / Body(1.0).thigh_m), 0.8
    user = GaitUser.draw(np.random.default_rng(7))
    user = dataclasses.replace(user, length_coef=user.length_coef * 0.60 / float(user.step_length_m(speed, thesis.leg_length_m)))
    thesis_person = Person(thesis, user, dict(height_m=thesis.height_m, leg_length_m=thesis.leg_length_m, mount_error_m=0.0), 7)
    kin = _walk_of(thesis_person, speed, duration)
    flow, motion, _, _, _ = _render(kin, CAM, "gravel", duration, seed=7)
    table1 = dict(thigh_length_m=0.5, shank_length_m=0.6, mass_kg=50.0)
    fits = [("floor odometry", _fit_odometry(odometry_for(thesis_person, CAM, shank_length_m=0.6), motion))]
    fits += [(f"{key}", _fit(estimator_for(thesis_person, CAM, **extra), flow))
             for key, extra in (("SLIP-OF", table1), ("thesis model", {**table1, **THESIS_MODEL}),
                                ("SLIP-OF, toe lever set to Table 1's 0.2 m foot", {**table1, "foot_length_m": 0.2}))]
    for key, est in fits:
        pairs, _ = _matched(est, kin, CAM.side)
        true = float(pairs[:, 1].mean()) if len(pairs) else float("nan")
        rows.append(_row(f"thesis set-up (Table 1 body, 0.8 m/s), true mean {true:.2f} m", f"stride length MAE, {key}",
                         100 * np.mean(np.abs(pairs[:, 0] / pairs[:, 1] - 1)) if len(pairs) else np.nan, "%", "<= 3",
                         f"10% ({THESIS}: 1.08 m vs 1.20 m)"))
    rows.append(_row("two-stride window", "SLIP fit time incl. all starts (median)", np.median(fit_times), "s", "<= 0.5",
                     "thesis: fmincon, 5 starts, no time given"))
    rows.append(_row("160x120 at 60-100 fps", "render time per frame", np.mean(render_ms), "ms", "-", "-"))
    rows.append(_row("160x120 at 60-100 fps", "correlation flow speed", np.mean(flow_fps), "frames/s", "-", "-"))
    rows.append(_row("160x120 at 60-100 fps", "homography camera motion speed", np.mean(motion_fps), "frames/s", "-", "-"))
    return rows
