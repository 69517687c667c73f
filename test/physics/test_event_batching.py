"""The compiled phase machine: the kernel applies the switches it locates and crosses them
without returning, unless asked to stop. Crossing them in one call or stopping at each must
be the same integration; errors the phase machine finds must still stop the run by name."""

import numpy as np
import pytest

from impact_arm.physics.contact import contact_constants, residual_indentation
from impact_arm.physics.integrator import PhaseIntegrator
from impact_arm.physics.model import ArmModel
from impact_arm.physics.scene import Material
from impact_arm.physics.simulate import run

from scenes import scene_from


def events_until(t_end, stop, log_rows=None, **options):
    integ = PhaseIntegrator(ArmModel(scene_from()), **options)
    if log_rows:  # a short event log: the kernel returns each time it fills up
        integ._evlog = integ._evlog[:log_rows]
    events, calls = [], 0
    while integ.state.t < t_end:
        events += integ.advance(t_end, stop_at_event=stop)
        calls += 1
    return events, integ, calls


@pytest.mark.parametrize(
    'method, log_rows', [('dopri5', None), ('rosenbrock', None), ('dopri5', 2)]
)
def test_crossing_events_in_one_call_is_the_same_integration_as_stopping_at_each(method, log_rows):
    options = dict(rtol=1e-6, atol=1e-8, method=method)
    one_by_one, stepped, calls_stepped = events_until(1.2, True, **options)
    batched, crossed, calls_crossed = events_until(1.2, False, log_rows, **options)
    kinds = [e.kind for e in one_by_one]
    assert kinds.count('contact') == 3 and kinds.count('switch') >= 2
    assert calls_stepped == len(one_by_one) + 1 and calls_crossed == 1
    assert crossed.state.t == 1.2
    assert [(e.kind, e.t, e.surface) for e in batched] == [
        (e.kind, e.t, e.surface) for e in one_by_one
    ]
    for a, b in zip(batched, one_by_one):
        assert np.array_equal(a.y, b.y) and a.info == b.info
    assert np.array_equal(crossed.state.y, stepped.state.y)
    assert crossed.stats == stepped.stats


def test_stopping_at_chosen_kinds_returns_at_those_only():
    events, integ, _ = events_until(0.5, ('switch',))
    first = PhaseIntegrator(ArmModel(scene_from()))
    up_to_switch = first.advance(0.5, stop_at_event=('switch',))
    assert [e.kind for e in up_to_switch] == [
        'contact',
        'yield',
        'max_compression',
        'separation',
        'switch',
    ]
    assert first.state.t == up_to_switch[-1].t < 0.5
    assert [e.kind for e in events][:5] == [e.kind for e in up_to_switch]
    # the impact's numbers ride along with its events
    info = up_to_switch[2].info
    assert 0 < info['delta_r'] < info['delta_m'] and info['P_m'] > 0 and info['R_r'] > 0
    assert up_to_switch[3].info['F_max'] >= info['P_m']
    with pytest.raises(ValueError, match='unknown event kind'):
        first.advance(1.0, stop_at_event=('impact',))


def test_residual_indentation_beyond_its_fit_stops_the_run_with_the_reason():
    soft = {'E': 210e9, 'nu': 0.29, 'S_y': 1e8}  # yields at a tiny fraction of the impact
    scene = scene_from(
        {
            ('initial', 'q_deg'): [0.0, -90.0],
            ('initial', 'qd'): [-2.0, 0.0],
            ('controller', 'law'): 'none',
        },
        gravity=0.0,
        cycles=0,
        t_max=0.01,
        materials={'steel': {'E': 210e9, 'nu': 0.29, 'S_y': 1.12e9}, 'soft': soft},
        surfaces=[
            {
                'height': -1.0 - 1e-7,
                'law': 'elastoplastic',
                'mu': 0.0,
                'v_d': 0.02,
                'material': 'soft',
            }
        ],
    )
    result = run(scene, preset='fast')
    assert result.stopped == 'error' and not result.impacts
    assert 'residual indentation fit gives delta_r' in result.error
    assert 'beyond the fit' in result.error
    # the fit itself, outside the kernel, agrees that this δm is past its range
    delta_m = float(result.error.split('delta_m = ')[1].split(' m')[0])
    c = contact_constants(Material(E=210e9, nu=0.29, S_y=1.12e9), Material(**soft), 0.005)
    assert residual_indentation(delta_m, c) >= delta_m * (1 - 1e-3)
