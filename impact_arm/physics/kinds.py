"""Typed names of states and kinds, in place of free text: each member is its text wherever
text is expected (equal to it, same hash, printed and formatted as it, JSON-encoded as it), so
code, files and messages that spoke the text keep working while new code names the members."""

from __future__ import annotations

from ..contract import TextEnum

__all__ = ['TextEnum', 'EventKind', 'ImpactSide']


class EventKind(TextEnum):
    """What a located event of the integrator is."""

    CONTACT = 'contact'  # the tip reaches a surface
    YIELD = 'yield'  # elastic -> elasto-plastic compression
    MAX_COMPRESSION = 'max_compression'  # compression -> restitution
    SEPARATION = 'separation'  # the tip leaves the surface
    SWITCH = 'switch'  # the controller's down/up switch


class ImpactSide(TextEnum):
    """Where a replayed or recorded impact stands: the free flight before it, the contact, or
    the free flight after a separation (the torque read for a step, the side a window of
    samples grows on)."""

    BEFORE = 'pre'
    CONTACT = 'contact'
    AFTER = 'post'
