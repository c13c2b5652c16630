"""Ground truth from bursts (Abdelhamed 2020, section 5.3): defective pixels, intensity alignment,
dense local alignment, censored robust mean.

Public API::

    from simcam.groundtruth import Burst, GroundTruthConfig, estimate_ground_truth
    gt = estimate_ground_truth(Burst.from_directory("burst/"), dark=Burst.from_directory("dark/"))
"""

from .alignment import dense_field, global_shift, local_shifts, patch_grid, phase_correlation, prepare_reference, warp
from .burst import Burst
from .defects import (DefectMap, correct_defects, detect_defects_dark, detect_hot_flat, fit_gaussian_wls,
                      load_defect_map, save_defect_map)
from .estimate import GroundTruth, GroundTruthConfig, estimate_ground_truth, stream_mean
from .intensity import align_intensity, frame_outliers
from .robust_mean import RobustMean, censored_mle, plain_mean, robust_mean, wls_cdf_fit, wls_objective
from .synthetic_burst import SyntheticBurst

__all__ = [
    "Burst", "DefectMap", "GroundTruth", "GroundTruthConfig", "RobustMean", "SyntheticBurst",
    "align_intensity", "censored_mle", "correct_defects", "dense_field", "detect_defects_dark", "detect_hot_flat",
    "estimate_ground_truth", "fit_gaussian_wls", "frame_outliers", "global_shift", "load_defect_map", "local_shifts",
    "patch_grid", "phase_correlation", "plain_mean", "prepare_reference", "robust_mean", "save_defect_map",
    "stream_mean", "warp", "wls_cdf_fit", "wls_objective",
]
