"""`UsageError`: a value the user gave (a common option, a key file, an address to bind or
advertise) that is missing or makes no sense. Raised where the value is used, as low as the
sockets (`--keys`, `--max-message-size`) and the addresses (`--host`, `--bind`); the common
options (service.options) raise it for what they parse, and a program stops with its one line.
"""

from miro_gen.exceptions import ActionableError


class UsageError(ActionableError, ValueError):
    """A common option is missing its value or has one that makes no sense (a bad command
    line: status 2)."""

    exit_status = 2
