"""The tables that pass between the stages and that ``pdr run`` writes (CONTRACT.md): their columns, each name
carrying its unit (``_s``, ``_m``, ``_rad``, ``_hz``, ...), the one check of a table's columns, and the one wrap of
angles. Frames: the east-north-up local frame of the recording's ``[geo]`` origin, headings counter-clockwise from east.
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np
import pandas as pd

from pdr.errors import InputError

# trajectory.csv: the start pose, then one row per step
TRAJECTORY_COLUMNS = ("t_s", "e_m", "n_m", "heading_rad", "e_std_m", "n_std_m")
# the step detection's table (pdr.pipelines.steps.detect_steps): contacts and their signals, before step lengths
DETECTED_STEPS_COLUMNS = (
    "t_s", "bout_id", "step_duration_s", "step_freq_hz", "step_freq_fft_hz", "acc_var_m2ps4", "slope_rad",
    "heading_rad", "heading_change_rad", "heading_change_std_rad", "mag_heading_rad", "mag_heading_std_rad",
)
# steps.csv
STEPS_COLUMNS = ("step_id", "t_s", "step_length_m", "step_length_std_m", "step_freq_hz", "heading_rad", "source")
# strides.csv, and the first columns of every stride source's table (foot IMU, leg camera)
STRIDE_COLUMNS = ("t_start_s", "t_end_s", "foot", "length_m", "length_std_m", "source")
# bouts.csv: one row per walking bout (Ladetto et al. 2000, section 6, for the mechanics)
BOUT_COLUMNS = ("bout_id", "t_start_s", "t_end_s", "n_steps", "distance_m", "speed_mps", "cadence_spm", "step_length_m",
                "step_length_cv", "vertical_lift_m", "speed_variation_mps", "power_gravity_w", "power_inertia_w",
                "power_external_w", "mechanics_source")
# GNSS fixes in the local frame, as the fusion reads them
GNSS_LOCAL_COLUMNS = ("t_s", "e_m", "n_m")


def require_table(df: Any, columns: Sequence[str], what: str) -> None:
    """An InputError naming ``what`` unless ``df`` is a DataFrame holding every one of ``columns``."""
    if not isinstance(df, pd.DataFrame):
        raise InputError(f"{what}: expected a pandas DataFrame, found {type(df).__name__}")
    missing = [c for c in columns if c not in df.columns]
    if missing:
        raise InputError(f"{what}: expected columns {', '.join(columns)}; missing {', '.join(missing)} "
                         f"(found {', '.join(map(str, df.columns)) or 'none'})")


def wrap_rad(angle: np.ndarray | float) -> np.ndarray | float:
    """Angles (rad) into [-pi, pi)."""
    return (np.asarray(angle, float) + np.pi) % (2.0 * np.pi) - np.pi
