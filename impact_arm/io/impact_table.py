"""The impacts so far as a table a viewer shows as it is: ``/impact_table``.

Each ``/impact_report`` is one impact's JSON at full double precision in SI units. A viewer's
table fed from it holds only the reports it was given since its last seek (after a seek
forward: the latest one alone). So at each impact the visuals also write ``/impact_table``
(std_msgs/String, JSON ``{"rows": [...]}``): every impact so far, one row each, in the units
a reader thinks in (kN, µs, µm) and rounded to ``SIGNIFICANT`` digits. A viewer that seeks
gets the newest message before the seek time, hence the whole table up to then.

Column names carry their units; they are the table's header in Foxglove and Lichtblick.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

import json
import math

if TYPE_CHECKING:
    from ..physics.impact import Impact

SIGNIFICANT = 4  # digits: the model's outputs are not known better than ~0.1 %
# the contact instant: to 0.1 ms, which tells apart every impact and every event frame
# (a contact lasts ~0.14 ms) without 17 digits of simulated time
TIME_DECIMALS = 4


def rounded(value: float, digits: int = SIGNIFICANT) -> float | None:
    """``value`` to ``digits`` significant digits; None (JSON null, an empty cell) for a
    non-finite one, which a table would otherwise print as a number or as nothing at all."""
    if not math.isfinite(value):
        return None
    return 0.0 if value == 0 else float(f'{value:.{digits}g}')


# column -> (``Impact`` field, scale to the column's unit); vectors: their z (index 1 of the
# plane's (x, z)); the energetic CoR: its last entry, the whole arm's
COLUMNS: tuple[tuple[str, str, float], ...] = (
    ('duration [µs]', 'duration', 1e6),
    ('δ max [µm]', 'delta_m', 1e6),
    ('δ residual [µm]', 'delta_r', 1e6),
    ('F max [kN]', 'F_max', 1e-3),
    ('vz before [m/s]', 'v_before', 1.0),
    ('vz after [m/s]', 'v_after', 1.0),
    ('CoR kinematic', 'cor_kinematic', 1.0),
    ('CoR energetic', 'cor_energetic', 1.0),
)
VECTOR_INDEX = {'v_before': 1, 'v_after': 1, 'cor_energetic': -1}


def table_row(record: Impact) -> dict[str, float | int | None]:
    """One impact as a row: its number and time, then each of ``COLUMNS``. Raises
    TypeError or ValueError for a record (read from the wire) with a field that is no
    number."""
    row: dict[str, float | int | None] = {
        'impact': int(record.index),
        't_contact [s]': round(float(record.t_contact), TIME_DECIMALS),
    }
    for column, field, scale in COLUMNS:
        value = getattr(record, field)
        if field in VECTOR_INDEX and isinstance(value, (list, tuple)):
            value = value[VECTOR_INDEX[field]]
        row[column] = rounded(float(value) * scale)
    return row


def table_json(rows: Sequence[Mapping[str, float | int | None]]) -> str:
    """The ``/impact_table`` payload of ``rows`` (UTF-8 JSON, the units' µ and δ as they are)."""
    return json.dumps({'rows': list(rows)}, ensure_ascii=False, allow_nan=False)
