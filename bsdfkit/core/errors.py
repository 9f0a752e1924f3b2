"""The one exception family of bsdfkit.

Every error a user can provoke with bad input is a :class:`BsdfkitError` whose message is a single line
naming *where* (file, and line or field), *what* was expected and what was found. The CLI prints that
line to stderr and exits non-zero; it never shows a traceback for these.
"""
from __future__ import annotations

from pathlib import Path


class BsdfkitError(Exception):
    """Base class: a user-facing, one-line error."""

    def __init__(
        self,
        message: str,
        *,
        file: str | Path | None = None,
        field: str | None = None,
        line: int | None = None,
        expected: str | None = None,
        got: object = None,
    ) -> None:
        self.file = None if file is None else str(file)
        self.field = field
        self.line = line
        self.expected = expected
        self.got = got
        parts = []
        if self.file is not None:
            parts.append(self.file + (f":{line}" if line is not None else ""))
        elif line is not None:
            parts.append(f"line {line}")
        if field is not None:
            parts.append(f"field '{field}'")
        where = ": ".join(parts)
        text = message
        if expected is not None:
            text += f"; expected {expected}"
        if got is not None:
            if hasattr(got, "item") and getattr(got, "ndim", 1) == 0:
                got = got.item()  # numpy scalar: show 385.0, not np.float64(385.0)
            got_text = repr(got)
            if len(got_text) > 80:
                got_text = got_text[:77] + "..."
            text += f", got {got_text}"
        full = f"{where}: {text}" if where else text
        # One line, always: collapse any newline a caller may have let through.
        super().__init__(" ".join(full.split()))


class InputError(BsdfkitError):
    """A file, field or argument does not hold what bsdfkit expects."""


class FormatError(InputError):
    """A file is not in the format it claims (or was asked) to be."""


class ValidationError(InputError):
    """Values parse but are physically or logically invalid (angle out of range, duplicate position...)."""


class NumericalError(BsdfkitError):
    """A computation cannot give a finite, meaningful result (singular system, zero incident power...)."""


class FitError(NumericalError):
    """A fit could not be set up or is degenerate."""


class OutputExistsError(BsdfkitError):
    """An output exists and ``force`` was not given."""


class OutputError(BsdfkitError):
    """An output cannot be written (permission, read-only file system, no space, path is a folder, ...)."""


class BsdfkitWarning(UserWarning):
    """Base class of bsdfkit's own warnings: a one-line message naming the file and what bsdfkit did.

    Library code raises them with :func:`warnings.warn`; the CLI (whose verbs silence library warnings) prints the
    ones a verb asks for as ``bsdfkit VERB: warning: <message>`` on stderr and keeps exit status 0.
    """

    def __init__(self, message: str, *, file: str | Path | None = None, details: object = None) -> None:
        self.file = None if file is None else str(file)
        self.details = details
        super().__init__(" ".join(str(message).split()))


class StatedTisWarning(BsdfkitWarning):
    """A table file's own stated TIS disagrees with the integral of its data beyond the tolerance of
    :func:`bsdfkit.tables.vendor.check_stated_tis`; ``details`` holds the comparison (stated and integrated TIS
    per key and incidence). bsdfkit keeps the data as they are."""


class ArgumentTypeError(InputError, TypeError):
    """An argument of a public function of the wrong type (a list or a path where a dataset is expected): a
    ``TypeError`` too, raised before anything is computed (:func:`bsdfkit.api.check_argument`)."""
