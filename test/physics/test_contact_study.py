"""The contact laws alone (a sphere dropped on a flat, no arm) against published closed forms:
Hertz's impact, and the coefficient of restitution's shape against Thornton (1997)."""

import pytest

from impact_arm.physics.sphere_drop import thornton_cor
from impact_arm.tools.contact_study import cor_table, hertz_case


def test_hertz_impact_of_the_aluminium_sphere_matches_the_closed_form():
    # 1 % would do; the laws and a tight DOP853 give far better
    for key, (model, theory) in hertz_case().items():
        assert model == pytest.approx(theory, rel=1e-6), key
    delta_m, F_max, duration = (theory for _, theory in hertz_case().values())
    # the closed form itself, by hand for these numbers: m = 11.306 kg, E* = 76.92 GPa
    assert delta_m == pytest.approx(4.9717e-5, rel=1e-4)
    assert F_max == pytest.approx(1.13699e4, rel=1e-4)
    assert duration == pytest.approx(2.9432 * delta_m / 0.2, rel=1e-4)


def test_cor_is_one_below_the_yield_speed_and_falls_monotonically_above():
    rows = cor_table((0.5, 0.9, 1.0, 1.2, 2.0, 5.0, 20.0, 100.0))
    below = [r['cor'] for r in rows if r['V_over_Vy'] <= 1.0]
    above = [r['cor'] for r in rows if r['V_over_Vy'] > 1.0]
    assert below == pytest.approx([1.0] * len(below), abs=1e-8)
    assert all(a > b for a, b in zip([1.0] + above, above))
    # the integration reproduces the laws' energy balance (no time integration there)
    for r in rows:
        assert r['cor'] == pytest.approx(r['cor_energy_balance'], rel=1e-6)
    # beyond ~1.5 V_y the Jackson-Green loading is stiffer than Thornton's pressure cap,
    # less work goes into plastic flow: a higher CoR (docs/studies.md)
    assert all(r['cor'] > r['cor_thornton'] for r in rows if r['V_over_Vy'] >= 2)


def test_thornton_closed_form_as_transcribed():
    assert thornton_cor(1.0) == 1.0 and thornton_cor(0.3) == 1.0
    assert thornton_cor(1.0 + 1e-9) == pytest.approx(1.0, abs=1e-6)  # continuous at V_y
    # Thornton's large-velocity asymptote e = 1.185 (V_y / V)^(1/4)
    assert thornton_cor(1e8) == pytest.approx(1.185 * 1e8**-0.25, rel=1e-3)
