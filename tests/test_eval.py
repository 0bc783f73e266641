"""``pdr evaluate``: metric functions and evaluate_run on a hand-made run output with known metric values."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from pdr.cli.main import main
from pdr.eval import evaluate_run, event_f1, fit_rotation_about, match_events, path_length_m
from pdr.io.recording import Recording, save_recording
from pdr.report import write_json, write_trajectory_csv

from conftest import make_imu

SCALE = 1.05  # the estimate is 5% too long
POS_TOL = 1e-3  # trajectory.csv keeps 0.1 mm: position metrics agree to about that
ANGLE = np.radians(30.0)  # and rotated by 30 degrees about the start


def _ref_path() -> tuple[np.ndarray, np.ndarray]:
    """An L-shaped walk at 1 m/s: (0,0) -> (10,0) -> (10,10) -> (0,10), 30 m in 30 s, sampled every 0.5 s."""
    t = np.arange(0.0, 30.0 + 1e-9, 0.5)
    corners_t, corners = np.array([0.0, 10.0, 20.0, 30.0]), np.array([[0, 0], [10, 0], [10, 10], [0, 10]], float)
    xy = np.c_[np.interp(t, corners_t, corners[:, 0]), np.interp(t, corners_t, corners[:, 1])]
    return t, xy


def _make_case(tmp_path, *, gnss_used: int = 0, reference: dict | None = None):
    t, xy = _ref_path()
    ref_steps = pd.DataFrame({"t_s": t[1:], "step_length_m": 0.5})  # 60 steps
    if reference is None:
        reference = {
            "steps": ref_steps,
            "trajectory": pd.DataFrame({"t_s": t, "e_m": xy[:, 0], "n_m": xy[:, 1]}),
            "landmarks": pd.DataFrame({"t_s": [10.0, 20.0, 30.0], "e_m": [10.0, 10.0, 0.0], "n_m": [0.0, 10.0, 10.0]}),
            "summary": {"distance_m": 30.0, "n_steps": 60},
        }
    rec = save_recording(Recording(meta={"recording": {"id": "ell", "placement": "waist"}},
                                   imu=make_imu(duration_s=31.0, rate_hz=50.0), reference=reference), tmp_path / "rec")
    c, s = np.cos(ANGLE), np.sin(ANGLE)
    est = SCALE * xy @ np.array([[c, -s], [s, c]]).T
    out = tmp_path / "out"
    out.mkdir()
    write_trajectory_csv(out / "trajectory.csv", pd.DataFrame({
        "t_s": t, "e_m": est[:, 0], "n_m": est[:, 1], "heading_rad": 0.0, "e_std_m": 0.0, "n_std_m": 0.0}))
    # 50 of the 60 reference steps found 0.1 s late, the last 10 missed, 3 spurious ones after the walk
    t_est = np.r_[ref_steps["t_s"].to_numpy()[:50] + 0.1, [40.0, 41.0, 42.0]]
    pd.DataFrame({"step_id": np.arange(53), "t_s": t_est, "step_length_m": 0.55}).to_csv(out / "steps.csv", index=False)
    write_json(out / "summary.json", {"gnss": {"used": gnss_used}})
    return out, rec


def test_known_metric_values_origin_heading(tmp_path):
    out, rec = _make_case(tmp_path)
    m = evaluate_run(out, rec)
    assert m["n_steps"] == 53 and m["n_steps_ref"] == 60
    assert m["step_count_error"] == -7
    assert m["step_count_error_pct"] == pytest.approx(-100 * 7 / 60)  # signed, like step_count_error
    assert m["step_f1_tolerance_s"] == 0.25
    assert m["step_precision"] == pytest.approx(50 / 53) and m["step_recall"] == pytest.approx(50 / 60)
    assert m["step_f1"] == pytest.approx(2 * 50 / (53 + 60))
    assert m["step_length_mae_m"] == pytest.approx(0.05)
    assert m["distance_m"] == pytest.approx(31.5, abs=POS_TOL) and m["distance_error_pct"] == pytest.approx(5.0, abs=POS_TOL)
    assert m["alignment"] == "origin+heading"
    assert m["alignment_rotation_rad"] == pytest.approx(-ANGLE, abs=POS_TOL)
    # after the rotation, the estimate is the reference scaled by 1.05 about the start: error = 0.05 |p|
    _, xy = _ref_path()
    assert m["ate_rmse_m"] == pytest.approx(0.05 * np.sqrt(np.mean(np.sum(xy ** 2, axis=1))), abs=POS_TOL)
    assert m["final_error_m"] == pytest.approx(0.5, abs=POS_TOL) and m["final_error_pct"] == pytest.approx(100 * 0.5 / 30, abs=POS_TOL)
    lm = 0.05 * np.array([10.0, np.hypot(10, 10), 10.0])
    assert m["landmark_error_mean_m"] == pytest.approx(lm.mean(), abs=POS_TOL)
    assert m["landmark_error_max_m"] == pytest.approx(lm.max(), abs=POS_TOL)
    assert m["landmark_error_mean_pct"] == pytest.approx(100 * lm.mean() / 30, abs=POS_TOL)
    assert "stride_length_mae_m" not in m  # no strides anywhere


def test_no_alignment_when_gnss_was_used(tmp_path):
    out, rec = _make_case(tmp_path, gnss_used=5)
    m = evaluate_run(out, rec)
    assert m["alignment"] == "none" and "alignment_rotation_rad" not in m
    _, xy = _ref_path()
    c, s = np.cos(ANGLE), np.sin(ANGLE)
    err = np.linalg.norm(SCALE * xy @ np.array([[c, -s], [s, c]]).T - xy, axis=1)
    assert m["ate_rmse_m"] == pytest.approx(np.sqrt(np.mean(err ** 2)), abs=POS_TOL)


def test_absent_reference_metrics_are_omitted(tmp_path):
    out, rec = _make_case(tmp_path, reference={"summary": {"n_steps": 50}})
    m = evaluate_run(out, rec)
    assert m["step_count_error"] == 3
    for key in ("step_f1", "step_length_mae_m", "distance_error_pct", "ate_rmse_m", "final_error_m", "landmark_error_mean_m"):
        assert key not in m


def test_reference_step_count_prefers_summary(tmp_path):
    t, _ = _ref_path()
    out, rec = _make_case(tmp_path, reference={"steps": pd.DataFrame({"t_s": t[1:]}), "summary": {"n_steps": 62}})
    m = evaluate_run(out, rec)
    assert m["n_steps_ref"] == 62 and m["step_count_error"] == -9 and m["step_recall"] == pytest.approx(50 / 60)


def test_summary_toml_without_a_summary_table(tmp_path, capsys):
    """``reference/summary.toml`` with its keys at the top level is read the same; other tables are refused."""
    t, _ = _ref_path()
    out, rec = _make_case(tmp_path, reference={"steps": pd.DataFrame({"t_s": t[1:]}), "summary": {"n_steps": 62}})
    (rec / "reference" / "summary.toml").write_text("n_steps = 62\n")
    assert evaluate_run(out, rec)["n_steps_ref"] == 62
    (rec / "reference" / "summary.toml").write_text("[truth]\nn_steps = 62\n")
    assert main(["evaluate", str(out), str(rec)]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("error:") and "[summary] table" in err and len(err.splitlines()) == 1


def test_landmarks_only_reference_leaves_the_anchor_out(tmp_path):
    t, xy = _ref_path()
    lms = pd.DataFrame({"t_s": [0.0, 10.0, 20.0, 30.0], "e_m": [0.0, 10.0, 10.0, 0.0], "n_m": [0.0, 0.0, 10.0, 10.0]})
    out, rec = _make_case(tmp_path, reference={"landmarks": lms, "summary": {"distance_m": 30.0}})
    m = evaluate_run(out, rec)
    assert m["alignment"] == "origin+heading" and m["alignment_fit_on"] == "landmarks"
    assert m["n_landmarks"] == 3
    assert m["landmark_error_mean_m"] == pytest.approx(np.mean(0.05 * np.array([10.0, np.hypot(10, 10), 10.0])), abs=POS_TOL)
    assert "ate_rmse_m" not in m


def test_stride_mae(tmp_path):
    out, rec = _make_case(tmp_path, reference={
        "strides": pd.DataFrame({"t_start_s": [1.0, 2.0, 3.0], "t_end_s": [2.0, 3.0, 4.0], "foot": ["left", "left", "left"],
                                 "length_m": [1.2, 1.3, 1.4]})})
    pd.DataFrame({"t_start_s": [1.1, 2.1, 8.0], "t_end_s": [2.1, 3.1, 9.0], "foot": ["left", "left", "right"],
                  "length_m": [1.25, 1.2, 1.0], "length_std_m": 0.1, "source": "foot_imu"}).to_csv(out / "strides.csv", index=False)
    m = evaluate_run(out, rec)
    assert m["n_strides_matched"] == 2 and m["stride_length_mae_m"] == pytest.approx(0.075)


def test_match_events_is_one_to_one_and_maximal():
    # greedy nearest would pair 1.0 with 1.2 and leave 1.4 unmatched; the maximum matching pairs both
    i_ref, i_est = match_events(np.array([1.2, 1.4]), np.array([1.0, 1.3]), 0.25)
    assert list(i_ref) == [0, 1] and list(i_est) == [0, 1]
    i_ref, i_est = match_events(np.array([1.0]), np.array([0.9, 1.0, 1.1]), 0.25)
    assert len(i_ref) == 1
    assert event_f1(np.array([1.0, 2.0]), np.array([]), 0.25)["f1"] == 0.0
    with pytest.raises(ValueError):
        match_events(np.array([2.0, 1.0]), np.array([1.0]), 0.25)


def test_rotation_fit_and_path_length():
    ref = np.array([[0, 0], [1, 0], [1, 1]], float)
    est = ref @ np.array([[0, 1], [-1, 0]], float).T  # rotated by -90 deg
    assert fit_rotation_about(est, ref, est[0], ref[0]) == pytest.approx(np.pi / 2)
    assert path_length_m(ref) == pytest.approx(2.0) and path_length_m(ref[:1]) == 0.0


def test_cli_evaluate_prints_json(tmp_path, capsys):
    out, rec = _make_case(tmp_path)
    assert main(["evaluate", str(out), str(rec)]) == 0
    assert json.loads(capsys.readouterr().out)["step_count_error"] == -7


@pytest.mark.parametrize("breakage", ["no_out", "no_reference", "bad_traj", "unsorted_traj"])
def test_cli_evaluate_bad_input_one_error_line(tmp_path, capsys, breakage):
    out, rec = _make_case(tmp_path, reference={} if breakage == "no_reference" else None)
    if breakage == "no_out":
        out = tmp_path / "missing"
    elif breakage == "bad_traj":
        (out / "trajectory.csv").write_text("t_s,x\n0,1\n")
    elif breakage == "unsorted_traj":
        (out / "trajectory.csv").write_text("t_s,e_m,n_m\n1,0,0\n0,1,1\n")
    assert main(["evaluate", str(out), str(rec)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and "expected" in err[0]


from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402


@settings(max_examples=40, deadline=None)
@given(angle=st.floats(-3.1, 3.1), de=st.floats(-1e3, 1e3), dn=st.floats(-1e3, 1e3))
def test_origin_heading_alignment_undoes_any_rigid_motion(angle, de, dn):
    from pdr.eval import rotate_about

    _, ref = _ref_path()
    c, s = np.cos(angle), np.sin(angle)
    est = ref @ np.array([[c, -s], [s, c]]).T + [de, dn]
    fitted = fit_rotation_about(est, ref, est[0], ref[0])
    np.testing.assert_allclose(rotate_about(est, fitted, est[0], ref[0]), ref, atol=1e-6)
