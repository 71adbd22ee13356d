"""The payload's mass properties: mass, inertia about G, sensor offset rho."""

from dataclasses import dataclass

import numpy as np

from fmscal.plant.numerics import FmscalError, as_finite_array, as_positive_scalar

__all__ = ["Payload", "PAPER_PAYLOAD"]


@dataclass(frozen=True)
class Payload:
    """Mass properties of the planar payload (section 2 of the paper).

    Parameters
    ----------
    mass : float
        Mass ``m`` in kg, positive.
    inertia : float
        Moment of inertia ``I_G`` about the z axis through the centre of
        mass G, in kg m^2, positive.
    rho : array_like, shape (2,)
        Position ``[rho_x, rho_y]`` of the sensor interface from G, in the
        body frame B, in m.

    Examples
    --------
    >>> Payload(2.5, 0.75, [0.2, 0.25])
    Payload(mass=2.5, inertia=0.75, rho=(0.2, 0.25))
    """

    mass: float
    inertia: float
    rho: tuple

    def __post_init__(self):
        object.__setattr__(self, "mass", as_positive_scalar(self.mass, "mass"))
        object.__setattr__(self, "inertia", as_positive_scalar(self.inertia, "inertia"))
        try:
            rho = as_finite_array(self.rho, (2,), "rho")
        except ValueError as err:
            raise FmscalError(f"{err} (rho is the offset [rho_x, rho_y] in m)") from None
        object.__setattr__(self, "rho", tuple(float(r) for r in rho))

    def to_dict(self):
        """Return ``{"mass", "inertia", "rho"}`` for JSON files."""
        return {"mass": self.mass, "inertia": self.inertia, "rho": list(self.rho)}

    @classmethod
    def from_dict(cls, data):
        """Build from a mapping with keys ``mass``, ``inertia``, ``rho``."""
        return cls(data["mass"], data["inertia"], data["rho"])

    def isclose(self, other, rtol=1e-9):
        """Return True if ``other`` has the same mass properties."""
        return bool(
            np.isclose(self.mass, other.mass, rtol=rtol)
            and np.isclose(self.inertia, other.inertia, rtol=rtol)
            and np.allclose(self.rho, other.rho, rtol=rtol, atol=1e-12)
        )


#: The payload of the paper's section 4: 2.5 kg, 0.75 kg m^2, rho = [0.2, 0.25] m.
PAPER_PAYLOAD = Payload(2.5, 0.75, (0.2, 0.25))
