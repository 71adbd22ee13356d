"""The information floor as a method: the maximum-likelihood estimate behind the Observer contract."""

import numpy as np

from fmscal.plant.numerics import FmscalError

from fmscal.observers.core import Estimate, Observer
from ._max_likelihood import fit_max_likelihood

__all__ = ["MaximumLikelihood"]


class MaximumLikelihood(Observer):
    """Maximum-likelihood estimate of ``S`` from a whole log: what the data allow.

    An offline method (``max-likelihood`` in the registry): it fits the
    whole log with :func:`observers.batch.fit_max_likelihood`
    (a Kalman filter on the motion of eq. (1) with the exact discretisation,
    the reading's noise as process noise, a flat prior on ``[S | c]``, two
    passes; module docstring there) and reports ``S_std`` (and ``b_std``)
    from the information the log held. Every table divides a method's E by
    this one's on the same log (``E / floor``).

    Parameters
    ----------
    model : plant.Model or plant.Payload
        The problem (a payload stands for its case's model). A model without
        linear channels (the spatial one) is linearised about the smoothed
        motion (:func:`fmscal.observers.batch.fit_linearised`), and the checks fail
        where the log leaves a direction of the reading undetermined
        (``result.info["undetermined"]``, the warnings say what to record).
    noise : plant.NoiseSpec, optional
        The log's noise standard deviations; None: estimated from the log
        (reported in ``result.info["noise"]``).
    passes : int
        Filter passes (the process noise of each after the first at the
        previous estimate).
    offset : bool
        Also estimate the sensor's offset ``b`` (``result.b``, ``result.b_std``).
    linearised : bool, optional
        The engine: None (default) as the model declares (the exact filter
        on a model with linear channels, the linearised one without); True:
        the linearised engine on any model (on a planar log it agrees with
        the exact filter within what the two take differently, the angle in
        ``G(theta)`` and the errors-in-variables moments:
        :func:`fmscal.observers.batch.fit_max_likelihood`); False: the exact
        filter, refused without linear channels.

    Examples
    --------
    >>> from fmscal.plant import PAPER_PAYLOAD, get_scenario
    >>> log, truth, _ = get_scenario("paper").with_(duration=5.0).generate(0)
    >>> MaximumLikelihood(PAPER_PAYLOAD).run(log).S_std.shape
    (3, 3)
    """

    name = "max-likelihood"
    online = False

    def __init__(self, model, noise=None, passes=2, offset=False, linearised=None):
        super().__init__(model, offset=offset)
        self.noise = None if noise is None else self.model.check_noise(noise)
        self.passes = passes
        if linearised is not None and not isinstance(linearised, (bool, np.bool_)):
            raise FmscalError(f"linearised must be None, True or False; got {linearised!r}")
        if linearised is False and not self.model.linear_channels:
            raise FmscalError(f"the exact maximum-likelihood filter needs a model linear in its channels; a "
                              f"{self.model.name} model is linearised (linearised=None or True)")
        self.linearised = linearised

    def _estimate(self, log, S0):
        fit = fit_max_likelihood(log, self.model, self.noise, self.offset, self.passes,
                                 compiled=self.run_data.compiled, linearised=self.linearised)
        calibration = fit.S_history.reshape(len(fit.S_history), -1).copy()
        calibration[-1] = fit.S_aug.ravel()          # the whole log's estimate
        info = {"noise": fit.noise.to_dict(), "noise_estimated": fit.noise_estimated, "passes": fit.passes,
                "undetermined": [d.tolist() for d in fit.undetermined]}
        if fit.latency_step is not None:             # the further delay the fit's own likelihood prefers (eq. LF2)
            info["latency_step"] = dict(fit.latency_step)
        return Estimate(calibration, fit.x_history, cov=fit.cov_aug, info=info, checks_passed=not fit.undetermined,
                        warnings=list(fit.warnings))
