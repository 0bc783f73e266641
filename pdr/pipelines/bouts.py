"""``bouts.csv`` of ``pdr run``: the walking bouts of a recording and their mechanics (:mod:`pdr.gait.mechanics`)."""

from __future__ import annotations

import numpy as np
import pandas as pd

from pdr.gait.mechanics import sensor_above_hip_m, walking_bouts
from pdr.io.recording import Recording
from pdr.signals import ImuSignals


def recording_bouts(rec: Recording, steps: pd.DataFrame, gnss: pd.DataFrame | None,
                    signals: ImuSignals | None = None) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Bouts and per-step mechanics of ``rec`` from its steps table (``t_s, bout_id, step_length_m``, the fused
    lengths) and the run's local GNSS fixes (``t_s, e_m, n_m, h_acc_m, masked``, rows as in ``gnss.csv``; None without
    GNSS or with ``--no-gnss``), to which the altitude (``u_m`` or ``alt_m``) of ``gnss.csv`` is added. The trunk
    sensor's height above the hips comes from ``[subject]`` (:func:`pdr.gait.mechanics.sensor_above_hip_m`); ``signals``:
    the main IMU's shared signals (default: computed here)."""
    fixes = None
    if gnss is not None:
        alt = next((c for c in ("u_m", "alt_m") if c in rec.gnss.columns), None)
        fixes = gnss.assign(u_m=rec.gnss[alt].to_numpy(float) if alt else np.nan)
        fixes = fixes[~fixes["masked"].to_numpy(bool)]
    mass = rec.subject.get("mass_kg")
    imu = (signals or ImuSignals(rec.imu)).uniform if len(steps) else None
    return walking_bouts(steps, placement=rec.placement, imu=imu, gnss=fixes,
                         mass_kg=None if mass is None else float(mass),
                         sensor_above_hip_m=sensor_above_hip_m(rec.subject), what=rec.id)
