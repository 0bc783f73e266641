"""``pdr steps``: the steps table (CONTRACT.md) from a recording (detection, features, heading)."""

from __future__ import annotations

import pandas as pd

from pdr.errors import InputError, warn
from pdr.heading import AttitudeStepHeading
from pdr.io.recording import TRUNK_PLACEMENTS, Recording
from pdr.pipelines.not_walking import min_step_rate_hz
from pdr.schema import DETECTED_STEPS_COLUMNS
from pdr.signals import ImuSignals
from pdr.steps import PeakStepDetection, WaveletStepDetection, acc_norm_signal, step_features

DETECTORS = {"wavelet": WaveletStepDetection, "peak": PeakStepDetection}
LOW_RATE_HZ = 25.0  # below this, contact times are coarse (1/rate) and impacts are smoothed away


def empty_steps_table() -> pd.DataFrame:
    return pd.DataFrame({c: pd.Series(dtype=int if c == "bout_id" else float) for c in DETECTED_STEPS_COLUMNS})


EVERY_STEP_PLACEMENTS = (*TRUNK_PLACEMENTS, "head")  # sensors that see every step: the gait period is never a stride
PHONE_PLACEMENTS = ("hand", "pocket", "bag", "arm", "neck", "unknown")  # where a phone is carried, taken out, put away


def make_detector(section: dict | None, placement: str = "unknown"):
    """The ``[steps]`` section: ``method = "wavelet" | "peak"`` (default wavelet) plus that detector's parameters.

    For a trunk placement the wavelet detector's ``stride_check`` defaults to False, and for a phone placement its
    ``leave_out_handling`` to True (a strapped sensor is not handled), unless the section sets them.
    """
    section = dict(section or {})
    method = section.pop("method", "wavelet")
    if method not in DETECTORS:
        raise InputError(f"configuration [steps]: expected method one of {', '.join(DETECTORS)}, found {method!r}")
    if method == "wavelet" and placement in EVERY_STEP_PLACEMENTS:
        section.setdefault("stride_check", False)
    if method == "wavelet" and placement in PHONE_PLACEMENTS:
        section.setdefault("leave_out_handling", True)
    return DETECTORS[method].from_config(section)


def detect_steps(rec: Recording, config: dict) -> pd.DataFrame:
    """Detect the steps of ``rec``'s main IMU and return the steps table (one row per step, sorted by ``t_s``).

    Config sections: ``[steps]`` (detector parameters, ``method``), ``[heading]`` (:class:`AttitudeStepHeading`).
    A recording with no walking gives an empty, correctly typed table and a warning.
    """
    if not isinstance(config, dict):
        raise InputError(f"configuration: expected a dict of sections, found {type(config).__name__}")
    detector = make_detector(config.get("steps"), rec.placement)
    return steps_table(rec, detector, AttitudeStepHeading.from_config(config.get("heading")))


def steps_table(rec: Recording, detector, heading: AttitudeStepHeading,
                signals: ImuSignals | None = None) -> pd.DataFrame:
    """The steps table of ``rec`` from a step detector and a heading estimator (see :func:`detect_steps`); ``signals``:
    the main IMU's shared signals (default: computed here)."""
    signals = signals or ImuSignals(rec.imu)
    u = signals.uniform
    if u.rate_hz < min_step_rate_hz():
        warn(f"{rec.id}: no steps: sampling rate {u.rate_hz:.1f} Hz is below twice the highest cadence "
             f"({min_step_rate_hz():g} Hz), so steps can not be found")
        return empty_steps_table()
    if u.rate_hz < LOW_RATE_HZ:
        warn(f"{rec.id}: sampling rate {u.rate_hz:.1f} Hz is low (< {LOW_RATE_HZ:g} Hz): contact times are "
             f"only good to about {1e3 / u.rate_hz:.0f} ms")
    detector.detect(u)
    left_out = getattr(detector, "left_out_", None)
    if left_out is not None and len(left_out):
        spans = ", ".join(f"{r.t_start_s:.1f}-{r.t_end_s:.1f} s" for r in left_out.itertuples())
        warn(f"{rec.id}: the phone was handled at {spans} (its attitude turned at a walking bout's edge): "
             f"{int(left_out['n_maxima'].sum())} acceleration peak(s) there not counted as steps")
    steps = detector.steps_.sort_values("t_s", kind="stable").reset_index(drop=True)
    if len(steps) == 0:
        warn(f"{rec.id}: no walking found, no steps")
        return empty_steps_table()
    if len(steps) == 1:
        warn(f"{rec.id}: only one step found")
    feats = step_features(steps, u, acc_norm_signal(u), gnss=rec.gnss)
    heading.estimate(u, signals.attitude, steps)
    table = pd.concat([steps[["t_s", "bout_id"]], feats], axis=1)
    table["heading_rad"] = heading.heading_rad_
    table["heading_change_rad"] = heading.heading_change_rad_
    table["heading_change_std_rad"] = heading.heading_change_std_rad_
    table["mag_heading_rad"] = heading.mag_heading_rad_
    table["mag_heading_std_rad"] = heading.mag_heading_std_rad_
    table["bout_id"] = table["bout_id"].astype(int)
    return table
