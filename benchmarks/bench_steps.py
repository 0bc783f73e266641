"""Step detection: Oxford step counting (9 phone recordings), mobgap lower-back initial contacts, speed.

Tiny private loaders read the raw files of the registry's data folder (``pdr.io.datasets.dataset_dir``) so the benchmark does not
depend on the importers' files; the optimisation set's steps are those of the importer's ``foot_device_steps`` (the two
feet's contacts made to alternate). Every recording is reported; nothing is tuned per file.
"""

from __future__ import annotations

import time
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import scipy.io as sio

from pdr.constants import GRAVITY_MPS2
from pdr.io.datasets import dataset_dir
from pdr.io.importers.oxford import foot_device_steps
from pdr.io.recording import Recording
from pdr.pipelines.steps import detect_steps
from pdr.signals import uniform_imu
from pdr.steps import PeakStepDetection, WaveletStepDetection, acc_norm_signal, step_features

ROOT = Path(__file__).resolve().parents[1]
TOL_S = 0.25
BRAJDIC = "Brajdic & Harle 2013: windowed peak detection < 3% count error"


def _imu(t: np.ndarray, acc: np.ndarray, gyr: np.ndarray | None = None) -> pd.DataFrame:
    keep = np.concatenate([[True], np.diff(t) > 0])
    cols = {"t_s": t[keep], "acc_x_mps2": acc[keep, 0], "acc_y_mps2": acc[keep, 1], "acc_z_mps2": acc[keep, 2]}
    if gyr is not None:
        cols.update(gyr_x_radps=gyr[keep, 0], gyr_y_radps=gyr[keep, 1], gyr_z_radps=gyr[keep, 2])
    return pd.DataFrame(cols)


def oxford_recordings() -> list[tuple[str, pd.DataFrame, np.ndarray, float]]:
    """(name, imu, ground-truth step times, app count or NaN) for the 6 validation and 3 optimisation recordings."""
    root = dataset_dir("oxford_step_counter")
    out = []
    for f in sorted((root / "validation").glob("user1_*.csv")):
        a = pd.read_csv(f, header=None).to_numpy(float)
        a = a[np.any(a[:, 1:4] != 0, axis=1)]
        t = (a[:, 0] - a[0, 0]) / 1e9
        steps = t[np.flatnonzero(np.diff(a[:, 5]) > 0) + 1]
        out.append((f.stem.split("_")[1], _imu(t, a[:, 1:4]), steps, float(a[-1, 4] - a[0, 4])))
    for d in sorted((root / "optimisation" / "data").iterdir()):
        a = pd.read_csv(d / "accelerometer.csv", header=None).to_numpy(float)
        s = pd.read_csv(d / "stepcounter.csv", header=None).to_numpy(float)
        t0 = a[0, 0]
        steps, _, _ = foot_device_steps(tuple((s[1:, 0][np.diff(s[:, c]) > 0] - t0) / 1e9 for c in (1, 2)))
        out.append((d.name, _imu((a[:, 0] - t0) / 1e9, a[:, 2:5]), steps, float("nan")))
    return out


def _ics(standard, table: str) -> tuple[np.ndarray, list[tuple[float, float]]]:
    ics, bouts = [], []
    for wb in np.atleast_1d(getattr(standard, table, [])) if standard is not None else []:
        ics += list(np.atleast_1d(wb.InitialContact_Event).astype(float))
        bouts.append((float(wb.Start), float(wb.End)))
    ics = np.asarray(ics, float)
    return np.sort(ics[np.isfinite(ics)]), bouts


def mobgap_trials() -> list[tuple[str, pd.DataFrame, np.ndarray, list[tuple[float, float]], np.ndarray]]:
    """(name, imu, INDIP initial contacts (s), INDIP walking bouts, union ICs) of the trials with a reference.

    The union adds the Stereophoto micro-bout ICs farther than the tolerance from every INDIP IC: INDIP misses
    some walking that the motion capture saw (HA/001 Test11 131-134 s, HA/002 Test11 142-147 s, HA/002 Test5).
    """
    out = []
    for part in sorted((dataset_dir("mobgap_lowerback_tvs_lab") / "lab" / "HA").iterdir()):
        tm = sio.loadmat(part / "data.mat", squeeze_me=True, struct_as_record=False)["data"].TimeMeasure1
        for test in tm._fieldnames:
            for trial in getattr(tm, test)._fieldnames:
                r = getattr(getattr(tm, test), trial)
                lb = r.SU.LowerBack
                fs = float(lb.Fs.Acc) if hasattr(lb.Fs, "Acc") else float(lb.Fs)
                acc = np.asarray(lb.Acc, float) * GRAVITY_MPS2
                gyr = np.radians(np.asarray(lb.Gyr, float))
                indip = getattr(r.Standards, "INDIP", None)
                ics, bouts = _ics(indip, "ContinuousWalkingPeriod")
                union = list(_ics(indip, "MicroWB")[0])
                for x in _ics(getattr(r.Standards, "Stereophoto", None), "MicroWB")[0]:
                    if all(abs(x - y) > TOL_S for y in union):
                        union.append(x)
                if len(union):
                    out.append((f"{part.name}/{test}/{trial}", _imu(np.arange(len(acc)) / fs, acc, gyr), ics, bouts,
                                np.sort(union)))
    return out


def match(det: np.ndarray, ref: np.ndarray, tol_s: float = TOL_S) -> tuple[int, int, int]:
    """One-to-one matching within ``tol_s``: (true positives, false positives, false negatives)."""
    used = np.zeros(len(det), bool)
    tp = 0
    for r in ref:
        c = np.flatnonzero(~used & (np.abs(det - r) <= tol_s))
        if len(c):
            used[c[np.argmin(np.abs(det[c] - r))]] = True
            tp += 1
    return tp, int((~used).sum()), len(ref) - tp


def _f1(tp: int, fp: int, fn: int) -> float:
    return 2 * tp / max(2 * tp + fp + fn, 1)


def _row(case: str, metric: str, ours: float, unit: str, target: str, anchor: str) -> dict:
    return {"area": "steps", "case": case, "metric": metric, "ours": round(float(ours), 3), "unit": unit,
            "target": target, "anchor": anchor}


def run(quick: bool = False) -> list[dict]:
    rows = []
    warnings.simplefilter("ignore")
    ox = oxford_recordings()
    if quick:
        ox = ox[:2]
    errs = []
    for name, imu, truth, app in ox:
        n_true = len(truth)
        wav = WaveletStepDetection().detect(imu).steps_.t_s.to_numpy()
        peak = PeakStepDetection().detect(imu).steps_.t_s.to_numpy()
        e = 100 * (len(wav) - n_true) / n_true
        errs.append(abs(e))
        tp, fp, fn = match(wav, truth)
        rows.append(_row(f"oxford/{name} ({n_true} steps)", "count error wavelet", e, "%", "|e| <= 2", BRAJDIC))
        rows.append(_row(f"oxford/{name}", "step F1 wavelet (0.25 s)", _f1(tp, fp, fn), "", "-", "-"))
        rows.append(_row(f"oxford/{name}", "count error peak baseline", 100 * (len(peak) - n_true) / n_true, "%", "-", BRAJDIC))
        if np.isfinite(app):
            rows.append(_row(f"oxford/{name}", "count error app (steps_algo)", 100 * (app - n_true) / n_true, "%", "-",
                             "Salvi et al. 2018 app"))
    rows.append(_row("oxford/all", "max |count error| wavelet", max(errs), "%", "<= 2", BRAJDIC))

    tot, tot_in, tot_u = np.zeros(3, int), np.zeros(3, int), np.zeros(3, int)
    for name, imu, ics, bouts, union in mobgap_trials()[: 2 if quick else None]:
        det = WaveletStepDetection(stride_check=False).detect(imu).steps_.t_s.to_numpy()  # lower back: a trunk sensor
        inside = np.zeros(len(det), bool)
        for a, b in bouts:
            inside |= (det >= a - TOL_S) & (det <= b + TOL_S)
        m_u = np.array(match(det, union))
        tot_u += m_u
        if len(ics):  # HA/002 Test5: INDIP saw no walking bout, only the motion capture did
            m, m_in = np.array(match(det, ics)), np.array(match(det[inside], ics))
            tot, tot_in = tot + m, tot_in + m_in
            rows.append(_row(f"mobgap/{name} ({len(ics)} INDIP ICs)", "IC F1 whole recording vs INDIP", _f1(*m), "", ">= 0.95", "-"))
        rows.append(_row(f"mobgap/{name} ({len(union)} union ICs)", "IC F1 whole recording vs INDIP + Stereophoto", _f1(*m_u),
                         "", ">= 0.95", "-"))
    anchor = "INDIP reference ICs (target; no published figure checked here)"
    rows.append(_row("mobgap/all", "IC F1 whole recording vs INDIP (bout detection included)", _f1(*tot), "", ">= 0.95", anchor))
    rows.append(_row("mobgap/all", "IC F1 whole recording vs INDIP + Stereophoto ICs", _f1(*tot_u), "", ">= 0.95", anchor))
    rows.append(_row("mobgap/all", "IC F1 within INDIP walking bouts", _f1(*tot_in), "", ">= 0.95", anchor))

    name, imu, truth, _ = ox[0]
    u0 = uniform_imu(imu, 100.0)
    reps = int(np.ceil(3600.0 / (u0.t_s[-1] - u0.t_s[0])))
    n = reps * len(u0)
    acc = np.tile(u0.acc_mps2, (reps, 1))
    hour = pd.DataFrame({"t_s": np.arange(n) / 100.0, "acc_x_mps2": acc[:, 0], "acc_y_mps2": acc[:, 1], "acc_z_mps2": acc[:, 2]})
    best = np.inf
    for _ in range(1 if quick else 3):
        t0 = time.perf_counter()
        u = uniform_imu(hour)
        det = WaveletStepDetection().detect(u)
        step_features(det.steps_, u, acc_norm_signal(u))
        best = min(best, time.perf_counter() - t0)
    rows.append(_row(f"speed/{n / 100 / 3600:.2f} h at 100 Hz ({len(det.steps_)} steps)", "detection + features time", best, "s",
                     "< 1", "-"))

    # the whole steps table (VQF attitude and heading included) on a lower-back recording with gyro, tiled to an hour
    name, imu, _, _, _ = [m for m in mobgap_trials() if "Test11" in m[0]][0]
    reps = int(np.ceil(3600.0 / imu.t_s.iloc[-1]))
    big = pd.concat([imu] * reps, ignore_index=True)
    big["t_s"] = np.arange(len(big)) / 100.0
    rec = Recording(meta={"recording": {"id": "hour", "placement": "waist"}}, imu=big)
    t0 = time.perf_counter()
    table = detect_steps(rec, {})
    rows.append(_row(f"speed/{len(big) / 100 / 3600:.2f} h at 100 Hz with gyro ({len(table)} steps)",
                     "detect_steps time (incl. VQF attitude, heading)", time.perf_counter() - t0, "s", "-", "-"))
    return rows
