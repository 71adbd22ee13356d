"""Gravity's direction and the sensor's mounting where a fit estimated them: the fields the payload fit
(:class:`observers.payload.PayloadFit`) and the static fit (:class:`observers.payload.StaticFit`) share.
"""

from dataclasses import dataclass

import numpy as np

__all__ = []


@dataclass(kw_only=True)
class _Rotations:
    """Gravity's direction and the sensor's mounting where a fit estimated them (None otherwise).

    Attributes
    ----------
    gravity : ndarray, shape (3,), or None
        Gravity in the pose frame, m/s^2.
    gravity_std_deg : float or None
        One-sigma uncertainty of its direction about each of the two axes across it (their rms), degrees.
    mounting : ndarray, shape (3, 3), or None
        The sensor's axes on the tracked frame (sensor vectors to tracked-frame vectors).
    mounting_deg, mounting_std_deg : float or None
        The mounting's angle, and the one-sigma uncertainty of its rotation about each axis (their rms), degrees.
    mounting_axis : ndarray, shape (3,), or None
        The mounting's unit axis (tracked-frame axes).
    """

    gravity: np.ndarray = None
    gravity_std_deg: float = None
    mounting: np.ndarray = None
    mounting_deg: float = None
    mounting_std_deg: float = None
    mounting_axis: np.ndarray = None

    def rotations_dict(self):
        """The six fields as JSON-ready numbers and lists (None where not estimated)."""
        return {"gravity": None if self.gravity is None else [float(v) for v in self.gravity],
                "gravity_std_deg": self.gravity_std_deg,
                "mounting": None if self.mounting is None else np.asarray(self.mounting).tolist(),
                "mounting_deg": self.mounting_deg, "mounting_std_deg": self.mounting_std_deg,
                "mounting_axis": None if self.mounting_axis is None else [float(v) for v in self.mounting_axis]}
