"""User-facing errors.

Every problem with a user's input (a log, a spec, a protocol, a command line)
is raised as :class:`InputError` with a one-line message that names the file,
column, run or key.  The CLI prints the message and exits with status 2; no
traceback reaches the user.
"""


class MotorIdError(Exception):
    """Base class of motorid's own errors."""


class InputError(MotorIdError, ValueError):
    """Bad input: the message is one line and names where the problem is."""

    def __init__(self, message: str):
        super().__init__(" ".join(str(message).split()))
