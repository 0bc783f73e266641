"""Shoe-mounted IMUs: gaitmap motion-capture stride lengths (57 strides, both methods), x-io closed loop, stairs,
simulated walks at slow / normal / fast speeds (``pdr.sim``, both feet, truth = heel displacement between heel
strikes), and the speed on one hour of 200 Hz data from both feet (the real walk tiled).

Recordings are made with the project's importers (``pdr.io.importers``, formats ``gaitmap`` and ``xio``) from
the registry's data folder (``pdr.io.datasets.dataset_dir``) into a temporary folder. The mocap reference is matched to our strides by
the largest time overlap of (mid-stance to mid-stance) intervals of the same foot. Nothing is tuned per file.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from pdr.io.datasets import dataset_dir
from pdr.foot import FootStepTrackerStride, ZuptInsStride
from pdr.io.importers import import_recordings
from pdr.io.recording import Recording, load_recording
from pdr.eval.evaluate import _match_intervals
from pdr.pipelines.foot import foot_strides
from pdr.pipelines.run import run_recording
from pdr.sim import simulate
from pdr.errors import collect_warnings

ROOT = Path(__file__).resolve().parents[1]
RAMPP = "Rampp et al. 2015 (shoe IMU, geriatric patients): 6.26 cm stride-length MAE"
XIO = "x-io Gait-Tracking pipeline on this file: 82 mm"
LOOP_M = 25.0  # the walked loop, from the x-io README ("about 25 m")
SIM_SPEEDS_MPS = (0.7, 1.25, 1.75)  # one minute each, standing 3 s before and after each
SIM_BINS = (("slow (< 1 m/s)", 0.0, 1.0), ("normal (1-1.5 m/s)", 1.0, 1.5), ("fast (> 1.5 m/s)", 1.5, 9.0))
SIM_ANCHOR = "pdr simulate truth: heel displacement between heel strikes"


def _import(fmt: str, src: Path, dest: Path, **kw) -> dict[str, Recording]:
    with collect_warnings():
        return {p.name: load_recording(p) for p in import_recordings(fmt, src, dest, **kw)}


def mocap_errors(strides: pd.DataFrame, reference: pd.DataFrame) -> np.ndarray:
    """Our length minus the mocap length, one per reference stride (same foot, largest time overlap)."""
    errs = []
    for _, r in reference.iterrows():
        mine = strides[strides["foot"] == r["foot"]]
        ov = np.minimum(mine["t_end_s"], r["t_end_s"]) - np.maximum(mine["t_start_s"], r["t_start_s"])
        errs.append(float(mine["length_m"].iloc[int(np.argmax(ov.to_numpy()))] - r["length_m"]))
    return np.asarray(errs)


def simulated_errors(seed: int, methods: dict[str, dict]) -> pd.DataFrame:
    """``method, speed_mps, error_m`` of every reference stride of a simulated walk (both feet at 200 Hz, one minute at
    each of SIM_SPEEDS_MPS) matched to our strides by shared time (as ``pdr evaluate``); speed = reference stride
    length / duration."""
    feet = [{"placement": f"foot_{s}", "rate_hz": 200.0, "magnetometer": False, "barometer": False}
            for s in ("left", "right")]
    segments = [{"duration_s": 3.0, "speed_mps": 0.0}]
    for v in SIM_SPEEDS_MPS:
        segments += [{"duration_s": 60.0, "speed_mps": v}, {"duration_s": 3.0, "speed_mps": 0.0}]
    rec = simulate({"route": {"waypoints_m": [[0.0, 0.0], [60.0, 0.0], [60.0, 40.0], [0.0, 40.0]]},
                    "segment": segments, "imu": feet, "gnss": {"enabled": False}}, seed=seed)
    ref = rec.reference["strides"]
    rows = []
    for name, section in methods.items():
        est = foot_strides(rec, {"foot": section})
        for foot in ("left", "right"):
            r, e = ref[ref["foot"] == foot], est[est["foot"] == foot]
            i_ref, i_est = _match_intervals(r, e, 0.5)
            r = r.iloc[i_ref]
            rows.append(pd.DataFrame({"method": name, "speed_mps": r["length_m"] / (r["t_end_s"] - r["t_start_s"]),
                                      "error_m": e["length_m"].to_numpy()[i_est] - r["length_m"].to_numpy()}))
    return pd.concat(rows, ignore_index=True)


GRID = {  # candidate defaults of the leave-one-recording-out choice: (zero_velocity, zupt_ins) parameters
    f"window {w:g} s, gyro noise {g:g}": ({"window_s": w}, {"gyr_noise_radps_rthz": g})
    for w in (0.05, 0.1) for g in (0.03, 0.05, 0.07, 0.1)
}
DEFAULT = "window 0.1 s, gyro noise 0.03"


def slow_walk() -> Recording:
    """30 s of simulated walking at 0.7 m/s with both feet at 200 Hz (``pdr.sim``, seed 1), standing 2 s before and
    after: the slow gait where the heel rise is slow (truth: the simulator's heel strides)."""
    feet = [{"placement": f"foot_{s}", "rate_hz": 200.0, "magnetometer": False, "barometer": False}
            for s in ("left", "right")]
    return simulate({"route": {"waypoints_m": [[0.0, 0.0], [100.0, 0.0]], "loop": False},
                     "segment": [{"duration_s": 2.0, "speed_mps": 0.0}, {"duration_s": 30.0, "speed_mps": 0.7},
                                 {"duration_s": 2.0, "speed_mps": 0.0}],
                     "imu": feet, "gnss": {"enabled": False}}, seed=1)


def recording_scores(recs: dict[str, Recording], reference: pd.DataFrame) -> pd.DataFrame:
    """Score of every GRID candidate on every recording: loop closure (% of the path) of the closed walks, stride
    length MAE (cm) on the gaitmap mocap strides and on the simulated slow walk (matched by shared time, as
    ``pdr evaluate``); one row per candidate, one column per recording."""
    rows = {}
    for name, (zv, ins) in GRID.items():
        row = {}
        for rec_name, rec in recs.items():
            out = foot_strides(rec, {"foot": {"zero_velocity": zv, "zupt_ins": ins}})
            if rec_name == "gaitmap":
                row[rec_name] = 100.0 * float(np.mean(np.abs(mocap_errors(out, reference))))
            elif rec_name == "simulated slow walk":
                ref = rec.reference["strides"]
                err = []
                for foot in ("left", "right"):
                    r, e = ref[ref["foot"] == foot], out[out["foot"] == foot]
                    i_ref, i_est = _match_intervals(r, e, 0.5)
                    err.extend(e["length_m"].to_numpy()[i_est] - r["length_m"].to_numpy()[i_ref])
                row[rec_name] = 100.0 * float(np.mean(np.abs(err)))
            else:
                imu = next(iter(rec.imus_by_placement().values()))
                r = ZuptInsStride(zero_velocity=zv, **ins).estimate(imu)
                row[rec_name] = 100.0 * float(np.hypot(*r.final_position_m_[:2]) / r.strides_["length_m"].sum())
        rows[name] = row
    return pd.DataFrame(rows).T


SCORE_TARGETS = {"gaitmap": 3.0, "x-io": 0.5, "OpenShoe": 0.5, "simulated slow walk": 3.0}  # issue targets: cm, %


def leave_one_out(scores: pd.DataFrame) -> dict[str, tuple[str, float]]:
    """Per recording, the candidate chosen without it (least mean of the other recordings' scores, each divided by
    its target in SCORE_TARGETS so that % and cm weigh alike) and its score on the left-out recording."""
    rel = scores / pd.Series(SCORE_TARGETS)[scores.columns]
    out = {}
    for rec in scores.columns:
        choice = rel.drop(columns=rec).mean(axis=1).idxmin()
        out[rec] = (choice, float(scores.loc[choice, rec]))
    return out


def run_closure(rec_dir: Path, out: Path, candidate: str | None = None) -> tuple[float, float]:
    """Final displacement from the start (m) and the path length (m) of ``pdr run`` on a recording, with the
    defaults or with the GRID ``candidate``."""
    config = None
    if candidate is not None:
        zv, ins = GRID[candidate]
        config = out.with_suffix(".toml")
        config.write_text("[foot.zero_velocity]\n" + "".join(f"{k} = {v!r}\n" for k, v in zv.items())
                          + "[foot.zupt_ins]\n" + "".join(f"{k} = {v!r}\n" for k, v in ins.items()))
    with collect_warnings():
        run_recording(rec_dir, out, config_path=config, force=True)
    traj = pd.read_csv(out / "trajectory.csv")
    xy = traj[["e_m", "n_m"]].to_numpy()
    return float(np.hypot(*(xy[-1] - xy[0]))), float(np.sum(np.hypot(*np.diff(xy, axis=0).T)))


def _tile(imu: pd.DataFrame, n: int, rate_hz: float) -> pd.DataFrame:
    out = pd.concat([imu] * int(np.ceil(n / len(imu))), ignore_index=True).iloc[:n].copy()
    out["t_s"] = np.arange(n) / rate_hz
    return out


def run(quick: bool = False) -> list[dict]:
    rows = []

    def row(case, metric, ours, unit, target, anchor):
        rows.append({"area": "foot", "case": case, "metric": metric, "ours": ours, "unit": unit, "target": target,
                     "anchor": anchor})

    with tempfile.TemporaryDirectory() as tmp:
        gm = _import("gaitmap", dataset_dir("gaitmap_foot_imu_mocap"), Path(tmp) / "gm", rate_hz=204.8)
        xio = _import("xio", dataset_dir("xio_foot_imu_loop_walk") / "short_walk.csv", Path(tmp) / "xio",
                      closed_loop=True)["short_walk"]
        shoe = _import("openshoe", dataset_dir("openshoe_foot_imu_figure8") / "data_inert_left.txt", Path(tmp) / "os",
                       closed_loop=True)["data_inert_left"]
        walk = gm["walk_2x20m"]
        ref = walk.reference["strides"]
        for name, rec in (("x-io loop walk", xio), ("OpenShoe two rectangular loops", shoe),
                          ("gaitmap 2x20 m walk (out and back)", walk)):
            closure, path = run_closure(rec.path, Path(tmp) / f"out_{rec.id}")
            target = "<= 1.5" if rec is walk else f"<= {0.005 * path:.3f} (0.5%)"
            row(f"{name}, pdr run (foot INS chain in the graph)", "final displacement from the start", round(closure, 3),
                "m", target, XIO if rec is xio else ("INS alone: 1.37 m" if rec is walk else "INS alone"))
            row(f"{name}, pdr run (foot INS chain in the graph)", "final displacement / path", round(100 * closure / path, 3),
                "%", "" if rec is walk else "<= 0.5 (goal 0.3)", "x-io: 0.33% of 25 m" if rec is xio else "")

        scores = recording_scores({"gaitmap": walk, "x-io": xio, "OpenShoe": shoe, "simulated slow walk": slow_walk()},
                                  ref)
        unit = {"gaitmap": "cm stride MAE", "x-io": "% loop closure", "OpenShoe": "% loop closure",
                "simulated slow walk": "cm stride MAE"}
        loo = leave_one_out(scores)
        for rec_name, (choice, score) in loo.items():
            row(f"leave-one-recording-out over {len(GRID)} candidate defaults, left out: {rec_name}",
                f"{unit[rec_name]}: left out ({choice}) / in-sample default",
                f"{score:.3g} / {scores.loc[DEFAULT, rec_name]:.3g}", unit[rec_name].split()[0], "", "")
        for rec_name, rec in (("x-io", xio), ("OpenShoe", shoe)):
            choice = loo[rec_name][0]
            closure, path = run_closure(rec.path, Path(tmp) / f"loo_{rec.id}", choice)
            row(f"{rec_name} loop, pdr run with the parameters chosen without it ({choice})",
                "final displacement / path", round(100 * closure / path, 3), "%", "<= 0.5 (goal 0.3)", "")

    case = f"gaitmap 2x20 m walk, {len(ref)} mocap strides"
    variants = [
        ("ZUPT INS, each foot alone (default)", {"method": "zupt_ins"}, "<= 0.03"),
        ("ZUPT INS + double feet", {"method": "zupt_ins", "double_feet": True}, "<= 0.03"),
        ("FootStep-Tracker as the seed (pitch, liftoff to rest)",
         {"method": "footstep_tracker", "double_feet": False, "footstep_tracker": {"integrate_from": "liftoff"}}, ""),
        ("FootStep-Tracker (pitch, uplift to rest)", {"method": "footstep_tracker", "double_feet": False}, ""),
        ("FootStep-Tracker (pitch, uplift to rest) + double feet (default)", {"method": "footstep_tracker"}, ""),
        ("FootStep-Tracker, 3-D attitude + double feet",
         {"method": "footstep_tracker", "footstep_tracker": {"attitude": "full"}}, ""),
    ]
    for name, section, target in variants:
        out = foot_strides(walk, {"foot": section})
        err = mocap_errors(out, ref)
        row(case, f"stride length MAE, {name}", round(float(np.mean(np.abs(err))), 4), "m", target, RAMPP)
        if name.startswith("ZUPT INS, each"):
            row(case, f"stride length bias, {name}", round(float(np.mean(err)), 4), "m", "", "")
            z = err / mocap_errors(out.assign(length_m=out["length_std_m"]), ref.assign(length_m=0.0))
            row(case, f"rms(error / length_std_m), {name}", round(float(np.sqrt(np.mean(z**2))), 2), "", "about 1", "")

    # Algorithm 1 against the mocap gait events: consistent offsets (small spread) are what a detector needs
    offsets = {"uplift - toe-off": ("t_uplift_s", "tc_s"), "liftoff - toe-off": ("t_liftoff_s", "tc_s"),
               "landing - heel strike": ("t_landing_s", "ic_s"), "rest - heel strike": ("t_rest_s", "ic_s")}
    crit = {foot: FootStepTrackerStride(foot=foot).estimate(imu).critical_times_
            for foot, imu in (("left", walk.imu), ("right", walk.extra_imus["foot_right"]))}
    for name, (col, ref_col) in offsets.items():
        d = np.array([crit[f][col].to_numpy()[np.argmin(np.abs(crit[f][col].to_numpy() - v))] - v
                      for f, v in zip(ref["foot"], ref[ref_col])])
        q25, q50, q75 = np.percentile(d, [25, 50, 75])
        row(case, f"critical time {name}: median (IQR)", f"{q50:+.3f} ({q75 - q25:.3f})", "s", "",
            "FootStep-Tracker Algorithm 1; mocap IC/TC events")

    ins = ZuptInsStride().estimate(xio.imu)  # the INS alone
    dist = float(ins.strides_["length_m"].sum())
    err = float(np.hypot(*ins.final_position_m_[:2]))
    loop = f"x-io loop walk (about {LOOP_M:g} m), ZUPT INS"
    row(loop, "final horizontal position error", round(err, 4), "m", f"<= {0.003 * LOOP_M:.3f}", XIO)
    row(loop, "final error / distance walked (INS)", round(100 * err / dist, 3), "%", "<= 0.3", "x-io: 0.33% of 25 m")
    row(loop, "final height error", round(float(abs(ins.final_position_m_[2])), 3), "m", "", "")
    row(loop, "distance walked (sum of strides)", round(dist, 2), "m", "about 25", "x-io README: about 25 m")

    for name in ("stairs_up", "stairs_down"):
        s = ZuptInsStride().estimate(gm[name].imu).strides_
        climb = s[np.abs(s["dz_m"]) > 0.15]
        row(f"gaitmap {name.replace('_', ' ')}, left foot, ZUPT INS", "strides / strides climbing > 0.15 m",
            f"{len(s)} / {len(climb)}", "", "", "no per-stride truth")
        row(f"gaitmap {name.replace('_', ' ')}, left foot, ZUPT INS", "median height change per climbing stride",
            round(float(np.median(climb["dz_m"])), 3) if len(climb) else float("nan"), "m", "",
            "two stair risers, about 0.3-0.35 m")

    seeds = (1,) if quick else (1, 2, 3)
    methods = {"ZUPT INS (default)": {"method": "zupt_ins"},
               "FootStep-Tracker + double feet": {"method": "footstep_tracker"}}
    errs = pd.concat([simulated_errors(seed, methods) for seed in seeds], ignore_index=True)
    for label, lo, hi in SIM_BINS:
        sel = errs[(errs["speed_mps"] >= lo) & (errs["speed_mps"] < hi)]
        case = f"pdr.sim walk {'/'.join(f'{v:g}' for v in SIM_SPEEDS_MPS)} m/s, seed{'s' if len(seeds) > 1 else ''} " \
               f"{','.join(map(str, seeds))}, {label}, {len(sel) // len(methods)} strides"
        for name in methods:
            e = sel.loc[sel["method"] == name, "error_m"].to_numpy()
            row(case, f"stride length MAE, {name}", round(float(np.mean(np.abs(e))), 4), "m", "", SIM_ANCHOR)
            row(case, f"stride length bias, {name}", round(float(np.mean(e)), 4), "m", "", "")

    minutes = 10 if quick else 60
    n = int(200 * 60 * minutes)
    big = Recording(meta=walk.meta, imu=_tile(walk.imu, n, 200.0),
                    extra_imus={"foot_right": _tile(walk.extra_imus["foot_right"], n, 200.0)})
    for method in ("zupt_ins", "footstep_tracker"):
        t0 = time.perf_counter()
        out = foot_strides(big, {"foot": {"method": method}})
        dt = time.perf_counter() - t0
        row(f"{minutes} min of 200 Hz, both feet (gaitmap walk tiled), {len(out)} strides",
            f"processing time, {method}", round(dt, 2), "s", "< 10" if minutes == 60 else "", "")
    return rows
