"""Walking forms (Watanabe et al.): per-cycle form accuracy on simulated mixed walks and on real shoe-IMU
data (gaitmap: level walking, stairs up, stairs down), distance with per-form step models against one model, and the
speed of classifying an hour of cycles.

Simulation: ``configs/sim/gait_forms_mix.toml`` (slow / normal / fast walking and running in a mixed order, corners
every 15-30 m), forms learnt on seeds 0-3 (four simulated people), tested on seeds 10-13 (four others; quick: 0-1 /
10). The truth of a cycle: the planned speed of its segment (``reference/steps.csv`` ``speed_mps``) named by Froude
number with the person's leg length (:func:`pdr.gait.forms.speed_kind`), or ``turning`` when the true heading
(``reference/trajectory.csv``) turns more than 30 degrees over the cycle.

gaitmap: six units (three recordings x two feet), leave one unit out (the other foot of the same recording stays in
the training set, so every class is seen), predicted kinds mapped to level / stairs_up / stairs_down. The stair
recordings include level strides (approach, landing, exit; no per-stride truth is given): two truths are reported,
the file's label for every cycle, and the file's label except for strides that the foot INS
(:class:`pdr.foot.ZuptInsStride`) measures below 10 degrees of slope, which count as level.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from pdr.io.datasets import dataset_dir
from pdr.foot import ZeroVelocityDetection, ZuptInsStride
from pdr.gait.forms import TURN_MIN_RAD_PER_CYCLE, FourierGaitForms, load_forms, speed_kind
from pdr.io.importers import import_recordings
from pdr.io.recording import load_recording, save_recording
from pdr.io.tomlio import read_toml
from pdr.pipelines.foot import foot_imus
from pdr.pipelines.gait_forms import fit_forms, per_form_step_lengths, recording_cycles
from pdr.pipelines.steps import detect_steps
from pdr.sim.simulator import simulate
from pdr.step_length.io import model_from_config, model_from_dict
from pdr.errors import collect_warnings

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "configs" / "sim" / "gait_forms_mix.toml"
PAPER = "Watanabe et al.: forms by PCA + k-means of 5th-order Fourier features (no accuracy given)"
LEVEL_SLOPE_DEG = 10.0


def sim_truth(rec, cycles: pd.DataFrame) -> np.ndarray:
    """True kind of each cycle (see the module docstring)."""
    ref = rec.reference["steps"]
    mid = 0.5 * (cycles["t_start_s"] + cycles["t_end_s"]).to_numpy()
    j = np.clip(np.searchsorted(ref["t_s"].to_numpy(), mid), 0, len(ref) - 1)
    kind = speed_kind(ref["speed_mps"].to_numpy()[j], 0.53 * float(rec.subject["height_m"]))
    tr = rec.reference["trajectory"]
    h = np.unwrap(tr["heading_rad"].to_numpy())
    turn = np.interp(cycles["t_end_s"], tr["t_s"], h) - np.interp(cycles["t_start_s"], tr["t_s"], h)
    return np.where(np.abs(turn) > TURN_MIN_RAD_PER_CYCLE, "turning", kind)


def _simulated(seeds, tmp: Path) -> list[Path]:
    raw = read_toml(SCENARIO, what="scenario")
    out = []
    for s in seeds:
        with collect_warnings():
            out.append(save_recording(simulate(raw, s, default_id=SCENARIO.stem), tmp / f"mix_{s}"))
    return out


def _distance_errors(paths: list[Path], forms_path: Path) -> dict[str, list[float]]:
    """Relative distance error (%) of each test walk with the per-form models, the single model fitted on the same
    training steps, and the uncalibrated population model."""
    _, doc = load_forms(forms_path)
    single = model_from_dict(doc["step_models"]["all"])
    out = {"per-form": [], "single": [], "population": []}
    for p in paths:
        rec = load_recording(p)
        truth = float(rec.reference["summary"]["distance_m"])
        with collect_warnings():
            steps = detect_steps(rec, {})
            base = model_from_config({})
            steps = base.prepare(steps, rec)
            base.estimate(steps, subject=rec.subject)
            out["population"].append(100 * (base.step_length_m_.sum() - truth) / truth)
            single.estimate(steps, subject=rec.subject)
            out["single"].append(100 * (single.step_length_m_.sum() - truth) / truth)
            steps = steps.assign(step_length_m=base.step_length_m_, step_length_std_m=base.step_length_std_m_)
            per, _ = per_form_step_lengths(rec, steps, {"forms": str(forms_path)}, {})
        out["per-form"].append(100 * (per["step_length_m"].sum() - truth) / truth)
    return out


def _gaitmap_cycles(tmp: Path) -> pd.DataFrame:
    with collect_warnings():
        recs = {p.name: load_recording(p) for p in import_recordings("gaitmap", dataset_dir("gaitmap_foot_imu_mocap"),
                                                                    tmp / "gm", rate_hz=204.8)}
    label = {"walk_2x20m": "level", "stairs_up": "stairs_up", "stairs_down": "stairs_down"}
    tables = []
    for name, rec in recs.items():
        with collect_warnings():
            cyc = recording_cycles(rec, {})
            slope = pd.Series(np.nan, index=cyc.index)
            for foot, imu in foot_imus(rec).items():
                ins = ZuptInsStride(foot=foot).estimate(imu, stance=ZeroVelocityDetection().detect(imu)).strides_
                sel = cyc["source"] == f"foot_{foot}"
                # the INS strides run between the same mid-stances: match by start time
                j = np.searchsorted(ins["t_start_s"].to_numpy(), cyc.loc[sel, "t_start_s"].to_numpy() - 1e-6)
                j = np.clip(j, 0, len(ins) - 1)
                ok = np.abs(ins["t_start_s"].to_numpy()[j] - cyc.loc[sel, "t_start_s"].to_numpy()) < 0.05
                s = np.degrees(np.arctan2(ins["dz_m"].to_numpy()[j], np.hypot(ins["dx_m"], ins["dy_m"]).to_numpy()[j]))
                slope[sel] = np.where(ok, s, np.nan)
        cyc["truth_file"] = label[name]
        cyc["truth"] = np.where(np.abs(slope) < LEVEL_SLOPE_DEG, "level", label[name])
        tables.append(cyc)
    return pd.concat(tables, ignore_index=True)


# GNSS for the first part of the walk only (the rest indoors): what the GNSS-calibrated step lengths carry into the
# outage. Fix noise as the walk_30min_gps scenario.
GNSS_OUTAGE = {"enabled": True, "noise_m": 1.5, "markov_sigma_m": 2.5, "markov_tau_s": 120.0, "outlier_fraction": 0.0,
               "outages_s": [[175.0, 400.0]]}


def _gnss_outage_errors(seeds, forms_path: Path, tmp: Path) -> dict[str, list[tuple[float, float]]]:
    """Final position error (m) and distance error (%) of ``pdr run`` on the mixed walks with GNSS for the first
    175 s: with the per-form step models (GNSS calibrates one scale of them) and with the configured regression
    (GNSS calibrates its A, B, C)."""
    from pdr.eval import evaluate_run
    from pdr.pipelines.run import run_recording

    raw = read_toml(SCENARIO, what="scenario") | {"gnss": GNSS_OUTAGE}
    config = tmp / "forms_run.toml"
    config.write_text(f'[gait_forms]\nforms = "{forms_path}"\n')
    out = {"per-form": [], "one regression": []}
    for s in seeds:
        with collect_warnings():
            rec = save_recording(simulate(raw, s, default_id=SCENARIO.stem), tmp / f"gnss_{s}")
            for name, cfg in (("per-form", config), ("one regression", None)):
                run_recording(rec, tmp / f"run_{name}_{s}", config_path=cfg)
                m = evaluate_run(tmp / f"run_{name}_{s}", rec)
                out[name].append((m["final_error_m"], m["distance_error_pct"]))
    return out


def _three_way(kind: np.ndarray) -> np.ndarray:
    return np.where(np.isin(kind, ["stairs_up", "stairs_down"]), kind, "level")


def run(quick: bool = False) -> list[dict]:
    rows = []

    def row(case, metric, ours, unit, target, anchor=PAPER):
        rows.append({"area": "gait_forms", "case": case, "metric": metric, "ours": ours, "unit": unit,
                     "target": target, "anchor": anchor})

    train_seeds, test_seeds = ((0, 1), (10,)) if quick else ((0, 1, 2, 3), (10, 11, 12, 13))
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        train = _simulated(train_seeds, tmp)
        test = _simulated(test_seeds, tmp)
        forms_path = tmp / "forms.json"
        with collect_warnings():
            fit_forms(train, forms_path)
        forms, _ = load_forms(forms_path)
        cycles, truth = [], []
        for p in test:
            rec = load_recording(p)
            with collect_warnings():
                c = recording_cycles(rec, {})
            cycles.append(c)
            truth.append(sim_truth(rec, c))
        cyc = pd.concat(cycles, ignore_index=True)
        truth = np.concatenate(truth)
        case = (f"simulated mixed walks ({SCENARIO.name}), forms from seeds {list(train_seeds)}, "
                f"test seeds {list(test_seeds)}: {len(cyc)} cycles")
        for smoothing in (False, True):
            forms.smoothing = smoothing
            kind = forms.classify(cyc).cycles_forms_["kind"].to_numpy()
            what = "transition-diagram smoothing" if smoothing else "nearest form (default)"
            row(case, f"form accuracy per cycle, {forms.n_forms} forms, {what}", round(float((kind == truth).mean()), 3),
                "fraction", ">= 0.95" if not smoothing else "")
            if not smoothing:
                straight = truth != "turning"
                row(case, "form accuracy per cycle, straight cycles only (speed kinds)",
                    round(float((kind[straight] == truth[straight]).mean()), 3), "fraction", "")
                turns = truth == "turning"
                row(case, f"turning cycles found ({int(turns.sum())} true turns)",
                    round(float((kind[turns] == "turning").mean()), 3), "fraction", "")
        forms.smoothing = False
        errs = _distance_errors(test, forms_path)
        for name, e in errs.items():
            label = {"per-form": "per-form step models (fitted on the training seeds' true step lengths)",
                     "single": "one step model fitted on the same training steps",
                     "population": "population step model (uncalibrated)"}[name]
            row(case, f"distance error, {label}: mean |error|", round(float(np.mean(np.abs(e))), 2), "%",
                "< single model" if name == "per-form" else "")

        if not quick:
            gnss = _gnss_outage_errors(test_seeds, forms_path, tmp)
            case_gnss = f"simulated mixed walks, GNSS for the first 175 s then indoors, test seeds {list(test_seeds)}"
            for name, errs in gnss.items():
                e = np.array(errs)
                how = ("per-form step models, GNSS calibrates one scale of them" if name == "per-form"
                       else "one regression, GNSS calibrates its A, B, C")
                row(case_gnss, f"final position error, {how}: mean", round(float(e[:, 0].mean()), 2), "m",
                    "< one regression" if name == "per-form" else "")
                row(case_gnss, f"distance error, {how}: mean |error|", round(float(np.abs(e[:, 1]).mean()), 2), "%",
                    "< one regression" if name == "per-form" else "")

        # speed: an hour of cycles (the test cycles tiled)
        n_hour = int(np.ceil(3600.0 / float(cyc["duration_s"].mean())))
        hour = pd.concat([cyc] * int(np.ceil(n_hour / len(cyc))), ignore_index=True).iloc[:n_hour].copy()
        hour["t_start_s"] = np.concatenate([[0.0], np.cumsum(hour["duration_s"].to_numpy())[:-1]])
        hour["t_end_s"] = hour["t_start_s"] + hour["duration_s"]
        hour["recording"] = "hour"
        hour["bout_id"] = 0
        for smoothing in (False, True):
            forms.smoothing = smoothing
            t0 = time.perf_counter()
            forms.classify(hour)
            dt = time.perf_counter() - t0
            what = "with transition smoothing" if smoothing else "nearest form"
            row(f"one hour of cycles ({n_hour} strides, body IMU layout)", f"classification time, {what}",
                round(dt, 4), "s", "< 1")

        # real shoe IMUs
        gm = _gaitmap_cycles(tmp)
    units = (gm["recording"] + "/" + gm["source"]).to_numpy()
    pred = np.empty(len(gm), dtype=object)
    for u in dict.fromkeys(units):
        te = units == u
        with collect_warnings():
            f = FourierGaitForms(n_forms=6).fit(gm[~te])
        pred[te] = _three_way(f.classify(gm[te]).cycles_forms_["kind"].to_numpy())
    case = (f"gaitmap shoe IMUs (walk 2x20 m, stairs up, stairs down; {len(gm)} strides), leave one recording-foot "
            "out, 6 forms")
    row(case, "3-way accuracy per cycle, truth = the file's label", round(float((pred == gm["truth_file"]).mean()), 3),
        "fraction", ">= 0.95")
    row(case, f"3-way accuracy per cycle, stair-file strides under {LEVEL_SLOPE_DEG:g} deg (foot INS) = level",
        round(float((pred == gm["truth"]).mean()), 3), "fraction", ">= 0.95")
    n_level = int(((gm["truth"] == "level") & (gm["truth_file"] != "level")).sum())
    row(case, "stair-file strides that are level (approach, landing, exit) by the foot INS", n_level, "strides", "")
    return rows


if __name__ == "__main__":
    with pd.option_context("display.max_colwidth", 90, "display.width", 250):
        print(pd.DataFrame(run(quick=False)).to_string(index=False))
