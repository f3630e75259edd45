"""Studies of the MULS paper's questions, each a function that returns a plain, JSON-ready dict.

- :func:`waveform_study`: CH0-CH3 of one pulse, noisy over noise-free (paper Figures 7, 8, 10, 12);
- :func:`maxrange_study`: maximum detectable range, single channel vs the MUL's near and far fields
  (paper section 5, Figure 14 and Table 3);
- :func:`precision_study`: range precision and mean deviation per channel (paper Table 2, Figure 11);
- :func:`coaxial_study`: water-column backscatter of coaxial vs non-coaxial optics (paper Figure 13);
- :func:`experiment_study`: the paper's pond and pool tests predicted per distance and channel (Table 2,
  Figures 7, 8, 10 and 11);
- :func:`budget_study`: the photon budget of every study point, and where a reported range exceeds it;
- :func:`edge_bias_study`: the range bias of a plate at the blind-zone edge in every water, and its cause;
- :func:`bench_study`: pulses per second of :func:`muls.simulate.simulate` on this machine;
- :func:`multiscatter_study` and :func:`multiscatter_waters_study`: the Monte Carlo (:mod:`muls.montecarlo`) beside
  MULS, one plate (``muls multiscatter``) and per water and range (``muls multiscatter-study``).

Every study goes through the instrument's own digitiser and ranging (:func:`muls.simulate.simulate`);
randomness comes only from the ``seed`` given to it, and each shot has its own pulse id. Units are SI
inside; JSON keys carry the unit (``_m``, ``_ns``, ``_w``). The decisions behind each study (gate
placement, detection criterion, shots) are written down in docs/studies.md.
"""

from .bench import bench_study
from .budget import budget_study
from .coaxial import coaxial_study
from .common import (
                     COARSE_START_M,
                     COARSE_STEP_M,
                     DETECTION_FRACTION,
                     DETECTION_TOLERANCE_BINS,
                     FINE_STEP_M,
                     MAXRANGE_WATERS,
                     detections,
                     experiment_gate_s,
                     far_gate_delay_s,
                     range_tolerance_m,
)
from .edge import EDGE_RANGES_M, edge_bias_study
from .experiment import experiment_study
from .maxrange import maxrange_study
from .multiscatter import (
    ATTENUATION_RULES,
    CHECK_RANGES_M,
    DEFAULT_PACKETS,
    DETECTION_FACTORS,
    STUDY_PACKETS,
    STUDY_RANGES_M,
    STUDY_WATERS,
    multiscatter_study,
    multiscatter_waters_study,
)
from .precision import precision_study
from .waveform import waveform_study

__all__ = [
    "COARSE_START_M",
    "COARSE_STEP_M",
    "DETECTION_FRACTION",
    "DETECTION_TOLERANCE_BINS",
    "EDGE_RANGES_M",
    "FINE_STEP_M",
    "MAXRANGE_WATERS",
    "detections",
    "experiment_gate_s",
    "far_gate_delay_s",
    "range_tolerance_m",
    "waveform_study",
    "experiment_study",
    "maxrange_study",
    "precision_study",
    "coaxial_study",
    "bench_study",
    "budget_study",
    "edge_bias_study",
    "ATTENUATION_RULES",
    "CHECK_RANGES_M",
    "DEFAULT_PACKETS",
    "DETECTION_FACTORS",
    "STUDY_PACKETS",
    "STUDY_RANGES_M",
    "STUDY_WATERS",
    "multiscatter_study",
    "multiscatter_waters_study",
]
