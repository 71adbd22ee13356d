"""The input every recursive observer's step reads, named by :class:`fmscal.plant.numerics.StateLayout`."""

from fmscal.plant.numerics import StateLayout

__all__ = ["StateLayout", "INPUT"]

#: The input of one step: ``[has_pose, theta, X, Y, M, f_x, f_y]`` (pose zeros where ``has_pose`` is 0).
INPUT = StateLayout(("has_pose", 1), ("pose", 3), ("w_hat", 3))
