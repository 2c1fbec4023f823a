"""Faults planted in a solver's compiled tick, to drive its fallback paths (test helper)."""

import math

from cbha_inverse.core._kernels.projection import target_status
from cbha_inverse.core._kernels.tick import NOT_FACTORED


def refuse_cholesky(solver, monkeypatch):
    """
    Make every linearisation of the solver's compiled tick end as a failed block Cholesky does.

    The compiled entry (``solver._control_tick``) is wrapped: a call that linearises checks the
    targets as the entry does (a target it refuses leaves everything to the entry: nothing is
    done), applies the pending step and linearises, then returns
    :data:`~cbha_inverse.core._kernels.tick.NOT_FACTORED` with nothing solved, so the solver
    takes the fallback chain; the other calls (a QP on the fallback's projection) run as they
    are. ``monkeypatch.undo()`` restores the entry.
    """
    entry = solver._control_tick

    def refused(targets, record, materialise, linearise, solve, apply_step):
        checked = solve and target_status(targets, record.base, record.reach) != 0
        if not linearise or checked:
            return entry(targets, record, materialise, linearise, solve, apply_step)
        entry(targets, record, materialise, True, False, False)
        return NOT_FACTORED, 0, math.nan, math.nan, False, math.nan

    monkeypatch.setattr(solver, '_control_tick', refused)
