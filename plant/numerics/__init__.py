"""Numerical plumbing shared by every package: one array backend for numpy and casadi, input checks,
compiled casadi steps, packed-state layouts and the toolkit's error type.
"""

from ._errors import (FmscalError, LogError)
from ._backend import (is_symbolic, ops)
from ._checks import (as_finite_array, as_positive_scalar, as_bool, as_number, numbers_only, short_repr, MAX_SCALAR)
from ._compile import (compile_function, compile_functions, compiler, BufferedCall, ChunkedSteps, build_once)
from ._layout import (StateLayout)
from ._threads import (THREAD_VARIABLES, one_blas_thread, one_thread_environment)

__all__ = ["FmscalError", "is_symbolic", "ops", "as_finite_array", "as_positive_scalar", "as_bool", "as_number",
           "compiler", "StateLayout", "THREAD_VARIABLES", "one_blas_thread", "one_thread_environment"]
