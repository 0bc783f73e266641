"""Scores of the wearable thigh-camera gait estimator (Watanabe et al. 2011) against motion-capture truth.

The paper reports joint position errors (Fig. 7) and shows the estimated forms changing with the true ones (Fig. 6);
here: the mean and 95th-percentile joint position error over the 7 joints, the waist path and heading errors, the
form per true gait cycle (the form held for most of its frames), per steady cycle (more than one cycle from a change
of form), per frame, and the form switches found within one cycle (an estimated cycle of the new form starting
within one cycle of the true change, one cycle being the true cycle in progress at the change).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from pdr.errors import InputError
from pdr.gait.camera_estimator import JOINTS, joint_columns


def score_gait_camera(truth: pd.DataFrame, true_cycles: pd.DataFrame, segments: pd.DataFrame, states: pd.DataFrame,
                      joints: pd.DataFrame, cycles: pd.DataFrame) -> dict[str, float]:
    """Metrics of an estimate (``states``, ``joints``, ``cycles`` as the estimator's ``states_``, ``joints_``,
    ``cycles_``) against the truth per frame (``truth``: the motion-capture columns, same frames), the true cycles
    (``t_start_s, t_end_s, form``) and the true form segments (``form, t_start_s``)."""
    if len(truth) != len(states) or len(joints) != len(states):
        raise InputError(f"gait camera evaluation: expected the truth and the estimate on the same frames, found "
                         f"{len(truth)} and {len(states)} rows")
    err = np.mean([np.linalg.norm(joints[joint_columns(j)].to_numpy(float) - truth[joint_columns(j)].to_numpy(float), axis=1)
                   for j in JOINTS], axis=0)
    t, form = states["t_s"].to_numpy(float), states["form"].fillna("").to_numpy().astype(str)
    cyc_len = float(np.median(true_cycles.t_end_s - true_cycles.t_start_s)) if len(true_cycles) else np.nan
    changes = segments["t_start_s"].to_numpy(float)[1:]
    hits, steady = [], []
    for c in true_cycles.itertuples():
        m = (t >= c.t_start_s) & (t < c.t_end_s)
        vals, counts = np.unique(form[m], return_counts=True)
        hits.append(bool(len(vals)) and vals[np.argmax(counts)] == c.form)
        # steady: more than one cycle away from any change of form (the gait blends over about a step)
        steady.append(not np.any((changes > c.t_start_s - cyc_len) & (changes < c.t_end_s + cyc_len)))
    found = []
    for k in range(1, len(segments)):
        tb, new = float(segments["t_start_s"].iloc[k]), segments["form"].iloc[k]
        if not (len(t) and t[0] + cyc_len < tb < t[-1] - cyc_len):
            continue
        at = true_cycles[(true_cycles.t_start_s <= tb) & (true_cycles.t_end_s > tb)]
        one = float((at.t_end_s - at.t_start_s).iloc[0]) if len(at) else cyc_len
        later = cycles[(cycles.t_start_s >= tb - one) & (cycles.form == new)]
        found.append(bool(len(later)) and float(later.t_start_s.iloc[0]) <= tb + one)
    dpsi = np.angle(np.exp(1j * (states["heading_rad"] - truth["heading_rad"]).to_numpy(float)))
    hits_a, steady_a = np.array(hits, bool), np.array(steady, bool)

    def mean(x):
        return float(np.mean(x)) if len(x) else float("nan")

    return {"joint_mean_m": float(np.nanmean(err)), "joint_p95_m": float(np.nanpercentile(err, 95)),
            "position_m": float(np.nanmean(np.hypot(states.e_m - truth.e_m, states.n_m - truth.n_m))),
            "heading_deg": float(np.degrees(np.nanmean(np.abs(dpsi)))),
            "form_cycle": mean(hits_a), "n_cycles": len(hits), "form_steady_cycle": mean(hits_a[steady_a]),
            "n_steady": int(steady_a.sum()), "form_frame": mean(form == truth["form"].to_numpy().astype(str)),
            "switches_found": mean(found), "n_switches": len(found), "n_frames": len(states),
            "duration_s": float(t[-1] - t[0]) if len(t) else 0.0}
