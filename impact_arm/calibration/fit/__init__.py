"""Scene parameters from a recording: each recorded impact replayed on the model, weighted
least squares, and a report that says whether the scene can describe the arm (docs/fit.md).

parameters (keys, bounds, coordinates) -> replay (one impact on the model; efforts: how the
recorded efforts acted between samples) -> problem (the impacts as whitened residuals) ->
search (global stage, trust-region refinement) -> report (covariance, intervals, verdict).
"""

from .efforts import EFFORT_TIMINGS, EffortTiming, TorqueSchedule, effort_timing
from .parameters import FitError, Parameter, parameter_specs, state_fit_keys
from .problem import FitOptions, ImpactSet, RecordedImpacts, contact_test, prepare, read_impacts
from .replay import FailureKind, Prediction, predict_impact, recorded_cor
from .report import FitResult, ParameterEstimate
from .search import fit

__all__ = [
    'EFFORT_TIMINGS',
    'EffortTiming',
    'FailureKind',
    'FitError',
    'FitOptions',
    'FitResult',
    'ImpactSet',
    'Parameter',
    'ParameterEstimate',
    'Prediction',
    'RecordedImpacts',
    'TorqueSchedule',
    'contact_test',
    'effort_timing',
    'fit',
    'parameter_specs',
    'state_fit_keys',
    'predict_impact',
    'prepare',
    'read_impacts',
    'recorded_cor',
]
