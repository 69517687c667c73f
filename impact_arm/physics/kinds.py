"""Typed names of states and kinds, in place of free text: each member is its text wherever
text is expected (equal to it, same hash, printed and formatted as it, JSON-encoded as it), so
code, files and messages that spoke the text keep working while new code names the members."""

from __future__ import annotations

from enum import Enum


class TextEnum(str, Enum):
    """An enum whose members behave as their text (``str(m) == m.value``, ``f'{m}'``,
    dictionary keys), like Python 3.11's StrEnum, for Python 3.10 as well."""

    __str__ = str.__str__
    __hash__ = str.__hash__

    def __format__(self, spec: str) -> str:
        return str.__format__(self.value, spec)

    def __repr__(self) -> str:
        return f'{type(self).__name__}.{self.name}'


class EventKind(TextEnum):
    """What a located event of the integrator is."""

    CONTACT = 'contact'  # the tip reaches a surface
    YIELD = 'yield'  # elastic -> elasto-plastic compression
    MAX_COMPRESSION = 'max_compression'  # compression -> restitution
    SEPARATION = 'separation'  # the tip leaves the surface
    SWITCH = 'switch'  # the controller's down/up switch
