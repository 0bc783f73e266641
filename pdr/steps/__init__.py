"""Step detection (wavelet and a peak-picking baseline), walking bouts, the phone's handling, per-step features."""

from pdr.steps.features import step_features
from pdr.steps.handling import AttitudeHandlingDetection
from pdr.steps.peak import PeakStepDetection
from pdr.steps.wavelet import WaveletStepDetection, acc_norm_signal

__all__ = ["AttitudeHandlingDetection", "PeakStepDetection", "WaveletStepDetection", "acc_norm_signal", "step_features"]
