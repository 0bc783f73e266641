"""Metamorphic tests of the phone pipeline: a recording and a copy that differs the way another user's recording would
(an epoch-time clock, the phone turned in the hand, dropouts of the sensor service) give the same answer, within what
the physics of the change allows."""

from __future__ import annotations

import copy

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation

from conftest import DATASETS, make_imu
from pdr.errors import collect_warnings
from pdr.eval.evaluate import evaluate_run
from pdr.io.importers import import_recordings
from pdr.io.recording import ACC_COLUMNS, GYR_COLUMNS, TIME_COLUMNS, Recording, load_recording, save_recording
from pdr.pipelines.run import run_recording
from pdr.sim import simulate
from pdr.steps import WaveletStepDetection

EPOCH_S = 1.7e9  # a Unix-time clock (2023)
HUMOLIRE = DATASETS / "humolire_phone_landmarks" / "data" / "imus" / "1" / "square_2x"


def _shifted(df: pd.DataFrame, dt: float) -> pd.DataFrame:
    return df.assign(**{c: df[c] + dt for c in TIME_COLUMNS if c in df.columns})


def test_reference_times_on_an_epoch_clock_survive_save_and_load(tmp_path):
    """Reference tables were written with 9 significant digits: at 1.7e9 s landmarks 10 s apart came back on one
    time (steps.csv: "repeated time", evaluate refused)."""
    imu = _shifted(make_imu(duration_s=20.0), EPOCH_S)
    steps = pd.DataFrame({"t_s": EPOCH_S + np.arange(1.0, 19.0, 0.55)})
    landmarks = pd.DataFrame({"t_s": EPOCH_S + np.array([3.217, 9.871, 15.006]), "e_m": [0.0, 5.0, 9.0],
                              "n_m": [0.0, 1.0, 2.0]})
    rec = Recording(meta={"recording": {"id": "epoch", "placement": "hand"}}, imu=imu,
                    reference={"steps": steps, "landmarks": landmarks})
    back = load_recording(save_recording(rec, tmp_path / "epoch"))
    for name, table in (("steps", steps), ("landmarks", landmarks)):
        np.testing.assert_allclose(back.reference[name]["t_s"], table["t_s"], rtol=0, atol=1e-5)
    np.testing.assert_allclose(back.imu["t_s"], imu["t_s"], rtol=0, atol=1e-5)  # 10 µs, not the fewest digits (1 ms)
    small = Recording(meta=rec.meta, imu=make_imu(duration_s=5.0), reference={"steps": steps.assign(t_s=steps.t_s - EPOCH_S)})
    path = save_recording(small, tmp_path / "small")
    assert (path / "reference" / "steps.csv").read_text().splitlines()[1] == "1"  # a clock near zero: files as before


@pytest.mark.real_data("humolire_phone_landmarks")
def test_humolire_epoch_clock_and_turned_phone_give_the_same_walk(tmp_path):
    """HuMoLiRe square_2x (real phone in the hand, 8 surveyed landmarks) against itself on a Unix-time clock and
    with the phone frame turned (acc and gyro together): the same steps, distance and landmark errors."""
    with collect_warnings():
        path = import_recordings("humolire", HUMOLIRE, tmp_path / "recs")[0]
    rec = load_recording(path)
    turned = copy.copy(rec)
    R = Rotation.from_euler("xyz", [40.0, -25.0, 110.0], degrees=True).as_matrix()
    turned.imu = rec.imu.copy()
    for cols in (ACC_COLUMNS, GYR_COLUMNS):
        turned.imu[list(cols)] = rec.imu[list(cols)].to_numpy() @ R.T
    epoch = copy.copy(rec)
    epoch.imu = _shifted(rec.imu, EPOCH_S)
    epoch.reference = {k: _shifted(v, EPOCH_S) if isinstance(v, pd.DataFrame) else v for k, v in rec.reference.items()}
    results = {}
    with collect_warnings():
        for name, r in (("base", rec), ("turned", turned), ("epoch", epoch)):
            p = save_recording(r, tmp_path / name)
            summary = run_recording(p, tmp_path / f"out_{name}")
            results[name] = (summary["n_steps"], summary["distance_m"], evaluate_run(tmp_path / f"out_{name}", p))
    n, dist, m = results["base"]
    for name in ("turned", "epoch"):
        n2, dist2, m2 = results[name]
        assert n2 == n, name
        assert dist2 == pytest.approx(dist, rel=1e-3), name
        assert m2["landmark_error_mean_m"] == pytest.approx(m["landmark_error_mean_m"], abs=0.05), name
        assert m2["landmark_error_max_m"] == pytest.approx(m["landmark_error_max_m"], abs=0.1), name


def test_short_dropouts_lose_only_the_steps_inside_them():
    """A phone's sensor service pausing for 0.5 s mid-walk (4 times) hides the contacts inside the pauses, no others:
    the bout used to end at each gap and take the visible step beside it along (6 steps lost for 3 hidden)."""
    sc = {"simulation": {"id": "gaps"}, "subject": {"height_m": 1.74},
          "route": {"waypoints_m": [[0.0, 0.0], [60.0, 0.0], [60.0, 40.0], [0.0, 40.0]], "loop": True},
          "segment": [{"duration_s": 6.0, "speed_mps": 0.0}, {"duration_s": 50.0, "speed_mps": 1.3},
                      {"duration_s": 8.0, "speed_mps": 0.0}, {"duration_s": 50.0, "speed_mps": 1.1},
                      {"duration_s": 5.0, "speed_mps": 0.0}],
          "imu": [{"placement": "hand", "rate_hz": 100.0}], "gnss": {"enabled": False}}
    rec = simulate(sc, seed=11)
    truth = rec.reference["steps"]["t_s"].to_numpy()
    t = rec.imu["t_s"].to_numpy()
    gaps = [(c, c + 0.5) for c in (24.17, 47.97, 71.77, 95.57)]
    keep = np.ones(len(t), bool)
    for a, b in gaps:
        keep &= ~((t > a) & (t < b))
    full = WaveletStepDetection(leave_out_handling=True).detect(rec.imu).steps_["t_s"].to_numpy()
    with collect_warnings():
        gappy = WaveletStepDetection(leave_out_handling=True).detect(rec.imu[keep]).steps_["t_s"].to_numpy()
    hidden = sum(int(((truth > a) & (truth < b)).sum()) for a, b in gaps)
    assert hidden >= 2
    assert not any(((gappy > a) & (gappy < b)).any() for a, b in gaps)
    visible = np.array([x for x in full if not any(a < x < b for a, b in gaps)])
    near = np.abs(gappy[:, None] - visible[None, :]).min(axis=1) < 0.02
    # a contact at a gap's edge (its impact half seen) may come out on the other side of the gap: one at most
    assert len(gappy) == len(visible) and near.sum() >= len(visible) - 1
