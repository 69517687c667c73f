"""What is wrong with a recording before it is fitted: the effects of real drivers that make a
fit of the impacts wrong without saying so, each detected, estimated and named with what to
do about it.

* ``DIFFERENCE_RATES``: the published rates are exact finite differences of the published
  positions (backward or central): the mean rate over a period, not the rate at the stamp,
  smeared across an impact;
* ``FILTERED_RATES``: the rates are those differences through a first-order low-pass;
* ``STAMP_JITTER``: the stamps scatter about a regular grid while the values follow the grid
  (stamps taken on arrival, not at sampling);
* ``EFFORT_DELAY``: the reported efforts are late (or early) against the joint states, from
  the power balance of the free flight (the change of the arm's energy between two samples is
  the work of the joint torques over the joint angles swept);
* ``POSITION_NOISE``: the positions scatter far more than the encoder's resolution (the
  smallest step of the positions);
* ``WRENCH_LAG``: the wrench rises later (or earlier) than the impacts the joint rates show.

``diagnose`` only reports; ``correct`` applies the corrections the user asks for (a known
effort or wrench latency, difference rates read as the mean rates of their periods, regular
stamps) to a copy of the recording. Nothing is changed unless asked.

findings (what is reported) -> stamps (the clock: consecutive samples, jitter), rates,
delays (efforts, wrench), noise (one check each) -> diagnosis (every check in turn);
corrections (what the user asks for, applied to a copy of the recording).
"""

from .corrections import Corrections, correct, rates_as_period_means
from .diagnosis import diagnose
from .findings import FindingKind
from .noise import encoder_resolution
from .rates import central_rates
from .stamps import SampleTimes, stamp_jitter

__all__ = [
    'Corrections',
    'FindingKind',
    'SampleTimes',
    'central_rates',
    'correct',
    'diagnose',
    'encoder_resolution',
    'rates_as_period_means',
    'stamp_jitter',
]
