"""The one exception type that reaches the user as a one-line ``error:`` message (exit code 1)."""


class InputError(Exception):
    """Bad input: say what was expected and what was found, in one line."""
