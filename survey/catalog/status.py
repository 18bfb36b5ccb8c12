"""Outcome codes of an integration and of a survey cell: one definition, used by the compiled
integrator (as plain integers), the archive's CF flag variable and the documentation's reference.

Kept free of numba and numpy so that reading an archive never compiles anything.
"""
from __future__ import annotations

import enum


class Status(enum.IntEnum):
    """Outcome of one integration (stored per cell as the CF flag variable `status`)."""

    OK = 0            # reached the final time
    EVENT = 1         # stopped by a terminal event
    COLLISION = 2     # step size collapsed: near collision / singularity
    STEP_LIMIT = 3    # max_steps attempted
    NONFINITE = 4     # the state or its derivative became inf/nan
    INACCESSIBLE = 5  # no initial condition exists at this grid point (set by families)
    TIME_LIMIT = 6    # wall-clock budget spent
    ESCAPED = 7       # a body left the escape radius, unbound (set by the cells: `[escape]`)

    @property
    def meaning(self) -> str:
        return MEANINGS[self]

    @property
    def finished(self) -> bool:
        """The integration ran to its intended end, so its indicators are meaningful."""
        return self in (Status.OK, Status.EVENT)


MEANINGS = {
    Status.OK: "reached t_final",
    Status.EVENT: "stopped by a terminal event",
    Status.COLLISION: "the step size collapsed near a collision or singularity",
    Status.STEP_LIMIT: "max_steps step attempts used up",
    Status.NONFINITE: "the state or its derivative became inf or nan",
    Status.INACCESSIBLE: "no start at this grid point (e.g. U(q0) > target energy)",
    Status.TIME_LIMIT: "the cell's wall-clock budget (cell_time_limit) ran out",
    Status.ESCAPED: "a body crossed the [outcomes] escape radius moving outward, unbound: the run "
                    "stopped there (its time escape_time, the body escaped_body)",
}
