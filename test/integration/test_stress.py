"""Stability at the extremes: the fast cases of the stress matrix.

Each case must finish with finite, physically consistent impacts (phases in order, δm > 0,
0 <= δr < δm, δ >= 0, contact adds no energy, the impacts the geometry forces all found) or
stop with an error naming the limit it crossed. The checks live in
bench/impact_arm_bench/stress.py; `impact-arm bench stress` runs the full sweep and the soak.
Only scene shapes the rest of the suite already compiles are used.
"""

import pytest

from impact_arm_bench import stress

# cases that must stop, and the words of the limit their message must name
NAMED_STOPS = {
    'E = 1e+07 Pa': 'yield strain',  # steel's S_y on a rubbery modulus
    'E = 1e+07 Pa, S_y = 53000 Pa': 'penetration exceeds the tip radius',
    'E = 1e+13 Pa': 'residual indentation fit',  # δm/δc beyond the Etsion fit
    'tip radius 0.0001 m': 'penetration exceeds the tip radius',
    'S_y 1e5 Pa (yields at once)': 'penetration exceeds the tip radius',
}


@pytest.mark.parametrize('case', stress.FAST, ids=[c.name for c in stress.FAST])
def test_case_finishes_consistently_or_stops_with_a_named_limit(case):
    outcome = stress.run_case(case, deadline=120)
    assert outcome.outcome != stress.FAIL, outcome.message
    if case.name in NAMED_STOPS:
        assert outcome.outcome == stress.STOPPED
        assert NAMED_STOPS[case.name] in outcome.message
    else:
        assert outcome.outcome == stress.OK, outcome.message
        assert outcome.impacts >= 1


def test_the_checker_reports_a_missed_impact():
    """The grazing case with a wrong expectation must fail: the checks can fail."""
    grazing = next(c for c in stress.FAST if c.name.startswith('grazing'))
    wrong = stress.Case(**dict(grazing.__dict__, expect_impacts=2))
    outcome = stress.run_case(wrong, deadline=120)
    assert outcome.outcome == stress.FAIL and 'impact missed' in outcome.message


def test_elastic_frictionless_impact_conserves_energy():
    """Hertz without friction is conservative: the balance error is the integrator's only."""
    case = next(c for c in stress.FAST if c.name.startswith('mu = 0'))
    outcome = stress.run_case(case, deadline=120)
    assert outcome.outcome == stress.OK
    assert 0 < outcome.energy_error < 1e-6  # measured, not assumed zero
