"""The toolkit's own exception type.

Every check of user input (a log, a calibration file, a setting, an array at
the public boundary) raises :class:`FmscalError` or a subclass of it. The
``fmscal`` command line prints these as one line with exit status 2; any other
exception is a bug in the toolkit and keeps its traceback.
"""

__all__ = ["FmscalError", "LogError"]


class FmscalError(ValueError):
    """A problem with what the user gave the toolkit: one line, naming the value.

    A subclass of :class:`ValueError`, so ``except ValueError`` still catches it.
    """


class LogError(FmscalError):
    """A log that cannot be used: the message names the problem.

    Defined here, beside :class:`FmscalError`, because the physics checks a
    pose's quaternion (:func:`fmscal.plant.physics.unit_quaternions`) as the
    log reader does, and the physics sits below the files.
    """
