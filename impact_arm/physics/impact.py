"""One impact as a typed, frozen record: the fields of the impact record (``metrics``,
docs/outputs.md), SI units, angles in degrees as in the JSON.

``metrics.ImpactBuilder`` makes an ``Impact`` for every impact and the package passes these
records around as they are (``RunResult.impacts``, the observers, the analysis, the tables).
Dicts exist only at the edges: ``to_dict`` gives the record as the JSON, ``/impact_report``
and the MCAP files carry it (sequences as lists, in the fields' order; a sweep's impact
table spreads the same fields over its columns), and ``from_dict`` (``impact_from_json`` for
the text) reads one back, once, where such a record enters the package again."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import dataclasses
import json
from dataclasses import dataclass

from .errors import ImpactArmError


@dataclass(frozen=True)
class Impact:
    """An impact from first contact to separation (docs/outputs.md, "Impact record").

    Per-link sequences are tuples, one entry per link; ``T_before``, ``T_after`` and
    ``cor_energetic`` have one more, the total."""

    index: int  # 1-based impact number
    t_contact: float  # time the tip reaches the surface [s]
    q_contact_deg: tuple[float, ...]  # absolute link angles at contact [deg]
    joints_contact_deg: tuple[float, ...]  # the robot's joint angles at contact [deg]
    duration: float  # contact to separation [s]
    delta_m: float  # maximum indentation [m]
    delta_r: float  # residual indentation [m]
    F_max: float  # largest normal force [N]
    v_before: tuple[float, float]  # tip velocity (vx, vy) at contact [m/s]
    v_after: tuple[float, float]  # tip velocity (vx, vy) at separation [m/s]
    cor_kinematic: float  # -vy after / vy before
    T_before: tuple[float, ...]  # kinetic energy per link, then the total [J]
    T_after: tuple[float, ...]  # the same at separation [J]
    cor_energetic: tuple[float, ...]  # sqrt(T_after / T_before) per link, then the total
    phase_durations: tuple[float, float, float]  # elastic, elasto-plastic, restitution [s]
    q_max_compression_deg: tuple[float, ...]  # absolute link angles at maximum compression
    q_separation_deg: tuple[float, ...]  # absolute link angles at separation [deg]

    def to_dict(self) -> dict[str, Any]:
        """The impact record as the JSON has it (sequences as lists, in the fields' order)."""
        return {
            f.name: list(value) if isinstance(value, tuple) else value
            for f in dataclasses.fields(self)
            for value in (getattr(self, f.name),)
        }

    @classmethod
    def from_dict(cls, record: Mapping[str, Any]) -> Impact:
        """The typed record of an impact record dict (one read from JSON: a file, an
        ``/impact_report``); a one-line ``ImpactArmError`` names a missing or unknown key."""
        names = [f.name for f in dataclasses.fields(cls)]
        missing = [k for k in names if k not in record]
        unknown = sorted(set(record) - set(names))
        if missing or unknown:
            raise ImpactArmError(
                'impact record: '
                + '; '.join(
                    part
                    for part in (
                        f'missing {", ".join(missing)}' if missing else '',
                        f'unknown {", ".join(unknown)}' if unknown else '',
                    )
                    if part
                )
                + f' (the fields are {", ".join(names)})'
            )
        values: dict[str, Any] = {
            k: tuple(v) if isinstance(v, (list, tuple)) else v
            for k, v in ((k, record[k]) for k in names)
        }
        return cls(**values)


def impact_from_json(text: str | bytes) -> Impact:
    """The ``Impact`` of a record's JSON text (an ``/impact_report``'s data): the one
    reader of a record from the wire or a file. A one-line ``ImpactArmError`` when the text
    is no JSON object with the record's fields."""
    try:
        record = json.loads(text)
    except ValueError as exc:  # JSONDecodeError, or bytes that are no UTF-8
        raise ImpactArmError(f'impact record: not JSON ({exc})') from None
    if not isinstance(record, dict):
        raise ImpactArmError(f'impact record: JSON {type(record).__name__}, not an object')
    return Impact.from_dict(record)
