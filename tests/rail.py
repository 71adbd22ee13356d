"""A second, minimal model for the tests: a payload on a rail (issue 27).

One position ``x``, one force ``f``, a 1x1 ``S``: the smallest problem a
:class:`fmscal.plant.Model` can describe, so that a test shows the sizes flow
from the model into every method. ``tests/test_model.py`` and
``tests/test_model_rail.py`` use it.
"""

from dataclasses import dataclass

import numpy as np

from fmscal.plant.numerics._backend import ops
from fmscal.plant.numerics._layout import StateLayout
from fmscal.plant.physics._model import Model


@dataclass(frozen=True)
class RailPayload:
    """A mass on a frictionless rail."""

    mass: float


class RailModel(Model):
    """``x'' = f / m``: state ``[x, x']``, pose ``x``, reading ``f``."""

    name = "rail"
    wrench_names = ("f",)
    pose_names = ("x",)
    position_names = ("x",)
    nq = nv = 1
    state = StateLayout(("x", 1), ("x_dot", 1))
    q_index, v_index = (0,), (1,)
    linear_channels = True

    def measure(self, x):
        return ops(x).vcat([x[0]])

    def rest_state(self, pose):
        return np.array([float(np.ravel(pose)[0]), 0.0])

    def integrate(self, q, dq):
        """A position moves additively (the EKF's error state, :class:`fmscal.observers.AugmentedEKF`)."""
        return q + dq

    def difference(self, q0, q1):
        return q1 - q0

    def input_matrix(self, x):
        return ops(x).matrix([[1.0 / self.payload.mass]])

    def drift(self, x):
        return ops(x).vcat([0.0])

    def state_derivative(self, x, w):
        return ops(x, w).vcat([x[1], w[0] / self.payload.mass])
