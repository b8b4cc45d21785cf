"""Context-manager behaviour shared by the objects that hold an open file."""

from __future__ import annotations

from collections.abc import Callable
from types import TracebackType
from typing import Self

__all__ = ["Closing"]


class Closing:
    """Mixin: ``with obj:`` closes ``obj`` on exit; set-up that fails closes it too.

    A subclass implements :meth:`close` (releasing its file; idempotent) and
    opens its file in ``__init__`` before calling :meth:`_set_up_or_close`.
    """

    def close(self) -> None:
        """Release the file."""

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def _set_up_or_close(self, set_up: Callable[[], None]) -> None:
        """Run ``set_up`` on the freshly opened file; on any exception close it and re-raise."""
        try:
            set_up()
        except BaseException:
            self.close()
            raise
