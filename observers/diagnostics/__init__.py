"""Checks of a log against the model: one constant ``S`` (health), saturation and a moving offset
(faults), and how much a log says about ``S`` (evidence), whether the model fits it (misfit), and what
its residual names (causes: a moving offset or gain, gravity's direction).
"""

from ._evidence import (has_evidence, log_uncertainty, EVIDENCE_PREFIX)
from ._health import (Consistency, consistency_check, DEFAULT_SIGNIFICANCE, DEFAULT_WINDOWS)
from ._misfit import (Misfit, InertiaShape, CentreOfMass, misfit, inertia_note, centre_of_mass_words, inflate,
    MISFIT_SIGNIFICANCE, MISFIT_RATIO, GROSS_RATIO)
from ._faults import (saturation, offset_drift, OffsetDrift, SATURATION_SHARE, SATURATION_RATIO, DRIFT_SIGNIFICANCE,
    DRIFT_PARTS, DRIFT_LAGS, describe_offset)
from ._causes import (Causes, GainDrift, GravityTilt, fit_causes, CAUSE_SIGNIFICANCE)

__all__ = ["has_evidence", "log_uncertainty", "Consistency", "consistency_check", "saturation", "offset_drift",
           "OffsetDrift", "Misfit", "InertiaShape", "CentreOfMass", "misfit", "Causes", "GainDrift", "GravityTilt",
           "fit_causes"]
