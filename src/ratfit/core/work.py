"""A budget of QP solves shared by the parts of one channel's fit.

A count, not seconds: a fit that stops when its budget runs out stops at the same
step on any load and with any ``jobs``, so it gives the same coefficients.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["WorkBudget"]


@dataclass
class WorkBudget:
    """QP solves a part of a fit may spend (``limit`` None: no limit) and has spent.

    Examples
    --------
    >>> from ratfit.core.work import WorkBudget
    >>> w = WorkBudget(2)
    >>> w.spend(); w.exhausted, w.left
    (False, 1)
    >>> w.spend(); w.exhausted, w.left
    (True, 0)
    """

    limit: int | None
    spent: int = 0

    @property
    def exhausted(self) -> bool:
        """No solve is left."""
        return self.limit is not None and self.spent >= self.limit

    @property
    def left(self) -> int | None:
        """Solves left (None: no limit)."""
        return None if self.limit is None else max(self.limit - self.spent, 0)

    def spend(self, solves: int = 1) -> None:
        self.spent += int(solves)
