"""The one error type of the run-file layer."""

from __future__ import annotations

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
        Human-readable explanation of the problem.

    Notes
    -----
    ``str(error) == f"{field}: {message}"``.
    """

    def __init__(self, field: str, message: str) -> None:
        self.field = str(field)
        self.message = str(message)
        super().__init__(f"{self.field}: {self.message}")

    def __reduce__(self) -> tuple[type[RunFileError], tuple[str, str]]:
        return (type(self), (self.field, self.message))
