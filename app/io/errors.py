"""The one error type of the run-file layer."""

from __future__ import annotations

from app.core.i18n import Msg

__all__ = ["RunFileError"]


class RunFileError(ValueError):
    """A run file or its metadata is not acceptable.

    Parameters
    ----------
    field : str
        What is wrong: a channel name (``"Z11"``, ``"position"``), a metadata
        field (``"start_time"``, ``"wheel_diameters.11"``, ``"sample_rate_hz"``),
        ``"format"`` (the file type) or ``"file"`` (the file as a whole).
    message : str
        Human-readable explanation of the problem: a :class:`~app.core.i18n.Msg`
        (``_("...")``) is kept as it is, so that the API answers it in the request's language.

    Notes
    -----
    ``str(error) == f"{field}: {message}"``.
    """

    def __init__(self, field: str, message: str) -> None:
        self.field = str(field)
        self.message = message if isinstance(message, Msg) else str(message)
        super().__init__(f"{self.field}: {self.message}")

    def __reduce__(self) -> tuple[type[RunFileError], tuple[str, str]]:
        return (type(self), (self.field, self.message))
