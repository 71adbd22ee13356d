"""The contract every method follows (:class:`Observer`), what it returns, and the pieces every method
shares: convergence rules, the step discretisation, gains checks, progress.
"""

from ._convergence import (settled, moved, informed, divergence_bound, DIVERGENCE_FACTOR, DIVERGENCE_GRACE,
    SETTLE_FRACTION, SETTLE_TOLERANCE, EVIDENCE_TOLERANCE)
from ._result import (ObserverResult, initial_calibration, split_calibration, calibration_uncertainty,
    offset_from_c, offset_std)
from ._samples import (check_sample, pack_input)
from ._state import (StateLayout, INPUT)
from ._discretise import (position_increment, velocity_increment, move, start_velocity, START_WINDOW)
from ._progress import (progress_bar, MIN_SAMPLES, EVERY)
from ._gains import (double_pole_gains, check_gains, GainReport, SubsystemGains, sampled_poles)
from ._glitches import (Glitches, find_glitches, bridge_glitches, reading_noise, glitch_threshold, HALF_WINDOW,
    FALSE_ALARM)
from ._base import (Observer, RecursiveObserver, Estimate, RunData, log_inputs, MAX_S0, ENGINES)
# The small matrix helpers every method's step uses (``mx.col``, ``mx.flat``, ...), by their module's public
# name for the other subpackages (``from fmscal.observers.core import matrix as mx``); not in __all__: plumbing.
from . import _matrix as matrix

__all__ = ["settled", "moved", "informed", "divergence_bound", "ObserverResult", "double_pole_gains", "check_gains",
           "GainReport", "SubsystemGains", "sampled_poles", "Observer", "RecursiveObserver", "Estimate", "Glitches",
           "find_glitches", "bridge_glitches", "reading_noise"]
