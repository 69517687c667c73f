"""Every check the recording (and the scene's model) allows, run in turn: the impacts found
once, the findings, the estimates and the checks that could not run gathered in a
``Diagnosis``."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..identify import IdentifyError, JointRecording, contact_test, find_impacts
from .delays import check_effort_delay, check_wrench_lag
from .findings import Diagnosis, Finding, FindingKind
from .noise import check_position_noise
from .rates import check_difference_rates, check_filtered_rates
from .stamps import check_stamp_jitter

if TYPE_CHECKING:
    from ...physics.model import ArmModel


def _impacts(rec: JointRecording, model: ArmModel | None) -> list[int]:
    """The impacts of the recording; with a model, only steps with the tip near a surface."""
    if model is None:
        return find_impacts(rec)
    # the fit's own test: near a surface, the tip moving down before the step and less so
    # after it (a torque step near the surface, a drive leaving its limit, is no contact)
    return find_impacts(rec, is_contact=contact_test(model))


def diagnose(rec: JointRecording, model: ArmModel | None = None) -> Diagnosis:
    """Every check that the recording (and the scene's ``model``, for the power balance and to
    tell contacts from other steps of the rates) allows."""
    out = Diagnosis()

    def ran(kind: FindingKind, found: Finding | None, estimate: float | None) -> None:
        out.checked.append(kind)
        if estimate is not None:
            out.estimates[kind] = estimate
        if found is not None:
            out.findings.append(found)

    found = check_difference_rates(rec)
    ran(FindingKind.DIFFERENCE_RATES, found, found.estimate if found else None)
    found = None if found else check_filtered_rates(rec)
    ran(FindingKind.FILTERED_RATES, found, found.estimate if found else None)
    ran(FindingKind.STAMP_JITTER, *check_stamp_jitter(rec))
    try:
        impacts = _impacts(rec, model)
    except IdentifyError as exc:
        impacts = []
        why = str(exc)
    else:
        why = 'no impact found in the joint rates'
    if model is None:
        out.skipped[FindingKind.EFFORT_DELAY] = 'needs the scene (the power balance)'
    else:
        finding, estimate = check_effort_delay(rec, model, impacts)
        if estimate is None:
            out.skipped[FindingKind.EFFORT_DELAY] = 'too little work of the torques in free flight'
        else:
            ran(FindingKind.EFFORT_DELAY, finding, estimate)
    finding, ratio, why_not = check_position_noise(rec, impacts)
    if why_not:
        out.skipped[FindingKind.POSITION_NOISE] = why_not
    else:
        ran(FindingKind.POSITION_NOISE, finding, ratio)
    if rec.wrench is None:
        out.skipped[FindingKind.WRENCH_LAG] = 'no wrench recorded'
    elif not impacts:
        out.skipped[FindingKind.WRENCH_LAG] = why
    else:
        ran(FindingKind.WRENCH_LAG, *check_wrench_lag(rec, impacts, model))
    return out
