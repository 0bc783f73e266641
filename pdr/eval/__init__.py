"""``pdr evaluate``: metrics of a ``pdr run`` output against a recording's ``reference/``."""

from pdr.eval.evaluate import STEP_F1_TOLERANCE_S, evaluate_run
from pdr.eval.metrics import (
    event_f1,
    fit_rotation_about,
    interpolate_positions,
    match_events,
    path_length_m,
    position_errors_m,
    rmse_m,
    rotate_about,
)

__all__ = [
    "STEP_F1_TOLERANCE_S", "evaluate_run", "event_f1", "fit_rotation_about", "interpolate_positions", "match_events",
    "path_length_m", "position_errors_m", "rmse_m", "rotate_about",
]
