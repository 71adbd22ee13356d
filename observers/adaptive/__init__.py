"""The adaptive observers: the paper's Lyapunov law as printed, the law at the floor (any model), and the
high-gain observer of Parsa and Aghili.
"""

from ._highgain import (HighGainObserver, DEFAULT_HIGH_GAIN, REF4_HIGH_GAIN)
from ._spatial import (SPATIAL_LAM, WARM_UP)
from ._adaptive import (AdaptiveObserver, SpatialAdaptiveObserver, DEFAULT_LAM, GAINS)
from ._paper import (PaperAdaptiveObserver, PAPER_K1, PAPER_K2, PAPER_DELTA, injection_matrix, output_error)

__all__ = ["HighGainObserver", "AdaptiveObserver", "SpatialAdaptiveObserver", "PaperAdaptiveObserver",
           "injection_matrix", "output_error"]
