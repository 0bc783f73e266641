"""The one exception type that reaches the user as a one-line ``error:`` message (exit code 1), and the check of a
table's keys that every configuration and scenario section uses."""

from __future__ import annotations

from typing import Iterable, Sequence


class InputError(Exception):
    """Bad input: say what was expected and what was found, in one line."""


def check_keys(keys: Iterable[str], allowed: Sequence[str], where: str, *, what: str = "key") -> None:
    """An InputError when ``keys`` holds names not in ``allowed``: ``"{where}: unknown {what}(s) a, b; expected some
    of: <allowed, in the given order>"`` (a typo in a configuration never goes unnoticed)."""
    unknown = sorted(set(keys) - set(allowed))
    if unknown:
        raise InputError(f"{where}: unknown {what}(s) {', '.join(unknown)}; expected some of: {', '.join(allowed)}")
