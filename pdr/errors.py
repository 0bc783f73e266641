"""The one exception type that reaches the user as a one-line ``error:`` message (exit code 1), the one way the
library reports a warning (the ``pdr`` logger), and the check of a table's keys that every configuration and scenario
section uses."""

from __future__ import annotations

import logging
import warnings
from contextlib import contextmanager
from typing import Iterable, Iterator, Sequence

LOGGER_NAME = "pdr"


class InputError(Exception):
    """Bad input: say what was expected and what was found, in one line."""


def check_keys(keys: Iterable[str], allowed: Sequence[str], where: str, *, what: str = "key") -> None:
    """An InputError when ``keys`` holds names not in ``allowed``: ``"{where}: unknown {what}(s) a, b; expected some
    of: <allowed, in the given order>"`` (a typo in a configuration never goes unnoticed)."""
    unknown = sorted(set(keys) - set(allowed))
    if unknown:
        raise InputError(f"{where}: unknown {what}(s) {', '.join(unknown)}; expected some of: {', '.join(allowed)}")


def warn(message: str) -> None:
    """Report a problem of the input or of the run that does not stop it, as one line on the ``pdr`` logger (level
    WARNING; Python's logging HOWTO: "logging.warning() if there is nothing the client application can do about the
    situation, but the event should still be noted"). A library user sees it as configured with :mod:`logging` (one
    plain line on stderr when nothing is configured); the CLI prints each as a ``warning:`` line; ``pdr run`` also lists
    them in ``summary.json``."""
    logging.getLogger(LOGGER_NAME).warning(" ".join(str(message).split()))


class _Collector(logging.Handler):
    def __init__(self, messages: list[str]) -> None:
        super().__init__(logging.WARNING)
        self.messages = messages

    def emit(self, record: logging.LogRecord) -> None:
        self.messages.append(record.getMessage())


@contextmanager
def collect_warnings() -> Iterator[list[str]]:
    """Collect, in order and without showing them, the warnings reported inside the block: the ``pdr`` logger's records
    and the Python warnings of the libraries underneath (numpy, pandas, ...), each as one line of text."""
    messages: list[str] = []
    logger = logging.getLogger(LOGGER_NAME)
    saved = logger.handlers[:], logger.propagate, logger.level
    logger.handlers, logger.propagate = [_Collector(messages)], False
    logger.setLevel(logging.WARNING)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("always")
            warnings.showwarning = lambda message, *args, **kwargs: messages.append(" ".join(str(message).split()))
            yield messages
    finally:
        logger.handlers, logger.propagate = saved[:2]
        logger.setLevel(saved[2])
