"""With ``S`` known or held poses: the payload's mass properties, the static fit of a pose table (gravity,
mounting, the reading's sign), coverage and the next poses, and the practitioners' estimators.
"""

from ._coverage import (cone_deg, covariance, weak_directions, describe, in_words, relative_std, next_poses,
    rotation, DETERMINED_REL, DETERMINED_COM, TURNS)
from ._estimate import (PayloadEstimate, PayloadFileError, PAYLOAD_FORMAT, PAYLOAD_FORMATS, PAYLOAD_PARAMETERS,
    NOISE_OF, propagate_covariance, inertia_turn)
from ._payload_fit import (identify_payload, DETERMINED, HOLD, REFERENCES)
from ._static_fit import (StaticFit, fit_static, calibrate_table, other_convention, tilt_warning, mounting_warning,
    rotation_warning, both_rotations_warning, rotation_check, Refit, gravity_up, TILT_RATIO, TILT_SIGMAS,
    MIN_CONE_DEG, ODDS, min_poses, sign_separated, rotations_unresolved, cone_warning, NARROW_CONE_DEG)
from ._practitioners import (ReferenceFit, plain_fit, calib_force, CALIB_FORCE_G)

__all__ = ["cone_deg", "next_poses", "rotation", "PayloadEstimate", "PayloadFileError", "PAYLOAD_FORMAT",
           "PAYLOAD_PARAMETERS", "identify_payload",
           "StaticFit", "fit_static", "calibrate_table", "other_convention", "min_poses", "ReferenceFit", "plain_fit",
           "calib_force"]
