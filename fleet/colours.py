"""Each robot's colour, the same in the live view and in the report.

Colours are ``#rrggbb`` strings, which rich (the terminal view) and matplotlib (the report)
both take as they are. A robot named ``<anything>-<n>`` gets colour ``n`` of the palette (so
robot-0 is always blue, whichever robots are alive); any other name gets a colour from a hash
of the name, stable across processes and runs. The palette leaves out green and red, which the
report uses for cleaned and missed floor.
"""

from __future__ import annotations

import zlib

ROBOT_COLOURS = (
    "#1f77b4",  # blue
    "#ff7f0e",  # orange
    "#9467bd",  # purple
    "#17becf",  # cyan
    "#8c564b",  # brown
    "#e377c2",  # pink
    "#bcbd22",  # olive
    "#000080",  # navy
)


def robot_colour(robot: str) -> str:
    """The ``#rrggbb`` colour of ``robot``: by the number after its last ``-``, else by hash."""
    _, dash, number = robot.rpartition("-")
    index = int(number) if dash and number.isdigit() else zlib.crc32(robot.encode())
    return ROBOT_COLOURS[index % len(ROBOT_COLOURS)]
