"""The linear algebra's threads: numpy's BLAS on one, unless the environment sets its threads.

The fits' matrices are small, and OpenBLAS's further threads spin between calls: CPU spent for no time gained
(``python benchmarks/blas_threads.py`` measures both). The command line runs each command so, and the ROS 2 node
starts its fit's process so.
"""

import contextlib
import os

from threadpoolctl import threadpool_limits

__all__ = ["THREAD_VARIABLES", "one_blas_thread", "one_thread_environment"]

#: The environment variables that set the linear algebra's threads.
THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def one_blas_thread():
    """A context in which numpy's BLAS runs on one thread (threadpoolctl), unless the environment sets one of
    :data:`THREAD_VARIABLES`: a thread count the user chose is kept."""
    if any(name in os.environ for name in THREAD_VARIABLES):
        return contextlib.nullcontext()
    return threadpool_limits(limits=1, user_api="blas")


def one_thread_environment(environ=None):
    """``environ`` (the process's by default) with every one of :data:`THREAD_VARIABLES` set to one: a child
    process's linear algebra on one thread from its start."""
    return {**(os.environ if environ is None else environ), **{name: "1" for name in THREAD_VARIABLES}}
