"""Step detection (wavelet and a plain peak-picking baseline), walking bouts and per-step features."""

from pdr.steps.features import step_features
from pdr.steps.peak import PeakStepDetection
from pdr.steps.wavelet import WaveletStepDetection, acc_norm_signal

__all__ = ["PeakStepDetection", "WaveletStepDetection", "acc_norm_signal", "step_features"]
