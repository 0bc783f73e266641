"""Nothing half-written: every output goes to a temporary name in the same folder, then is renamed.

A place that cannot be written (a read-only folder, a path under a file, a full disk) is an :class:`UnwritableOutput`:
one line that names the user's path (never the temporary one) and the system's reason.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from pathlib import Path
from typing import Iterable, Iterator

import pandas as pd

from pdr.errors import InputError


def _process_umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


# tempfile creates private files (0600) and folders (0700); outputs get the modes of a plain open()/mkdir()
FILE_MODE = 0o666 & ~_process_umask()
DIR_MODE = 0o777 & ~_process_umask()
CSV_DIGITS = 9  # significant digits of the floats in the CSV tables


class UnwritableOutput(InputError):
    """An output that cannot be written where the user asked; ``reason`` is the system's words."""

    def __init__(self, dest: Path, reason: str):
        super().__init__(f"{dest}: expected a place where the output can be written, found it cannot ({reason})")
        self.reason = reason


@contextlib.contextmanager
def _named_as(dest: Path, tmp: Path | None = None) -> Iterator[None]:
    """OSErrors about ``dest`` or the temporary ``tmp`` (and UnwritableOutput of files inside ``tmp``) re-raised as
    one UnwritableOutput naming ``dest``."""
    try:
        yield
    except UnwritableOutput as exc:
        raise UnwritableOutput(dest, exc.reason) from None
    except OSError as exc:
        names = [str(p) for p in (dest, dest.parent, tmp) if p is not None]
        if exc.filename is not None and not any(str(exc.filename).startswith(n) for n in names):
            raise  # a file read inside the block, not the output
        blocker = next((p for p in dest.parents if p.is_file()), None)
        if blocker is not None:
            raise UnwritableOutput(dest, f"{blocker} is a file, not a folder") from None
        raise UnwritableOutput(dest, exc.strerror or str(exc) or type(exc).__name__) from None


@contextlib.contextmanager
def atomic_path(dest: str | Path) -> Iterator[Path]:
    """Yield a temporary file path beside ``dest``; rename it onto ``dest`` only if the block succeeds."""
    dest = Path(dest)
    with _named_as(dest):
        dest.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{dest.name}.", suffix=".tmp", dir=dest.parent)
        os.close(fd)
    tmp_path = Path(tmp)
    try:
        with _named_as(dest, tmp_path):
            tmp_path.chmod(FILE_MODE)
            yield tmp_path
            os.replace(tmp_path, dest)
    finally:
        tmp_path.unlink(missing_ok=True)


def write_text(dest: str | Path, text: str) -> None:
    with atomic_path(dest) as tmp:
        tmp.write_text(text, encoding="utf-8")


def write_csv(dest: str | Path, df: pd.DataFrame, *, float_format: str | None = f"%.{CSV_DIGITS}g") -> None:
    """CSV with a header row, no index column; floats printed with ``CSV_DIGITS`` significant digits (deterministic)."""
    with atomic_path(dest) as tmp:
        df.to_csv(tmp, index=False, float_format=float_format, lineterminator="\n")


@contextlib.contextmanager
def atomic_dir(dest: str | Path, *, force: bool = False) -> Iterator[Path]:
    """Yield an empty temporary folder beside ``dest``; on success it replaces ``dest``.

    An existing ``dest`` is an InputError unless ``force``; then it is replaced only once the new one is complete.
    """
    dest = Path(dest)
    if dest.exists() and not force:
        raise InputError(f"{dest}: expected a new output folder, found an existing one (use --force to replace it)")
    with _named_as(dest):
        dest.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{dest.name}.", suffix=".tmp", dir=dest.parent))
    try:
        with _named_as(dest, tmp):
            tmp.chmod(DIR_MODE)
            yield tmp
            if dest.exists():
                old = dest.with_name(f".{dest.name}.old-{os.getpid()}")
                os.replace(dest, old)
                os.replace(tmp, dest)
                shutil.rmtree(old, ignore_errors=True)
            else:
                os.replace(tmp, dest)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


@contextlib.contextmanager
def atomic_outputs(dest: str | Path, owned: Iterable[str]) -> Iterator[Path]:
    """Yield an empty temporary folder beside ``dest`` for files named in ``owned``; on success they replace those of
    ``dest``.

    A new ``dest`` is the temporary folder renamed (atomic). In an existing folder each written file is renamed onto
    its name, then the ``owned`` files this run did not write (the plot of an earlier run) are removed; every other
    file of ``dest`` (the user's own) is left alone. A failure inside the block leaves ``dest`` as it was.
    """
    dest, owned = Path(dest), set(owned)
    if not dest.exists():
        with atomic_dir(dest) as tmp:
            yield tmp
        return
    with _named_as(dest):
        tmp = Path(tempfile.mkdtemp(prefix=f".{dest.name}.", suffix=".tmp", dir=dest.parent))
    try:
        with _named_as(dest, tmp):
            tmp.chmod(DIR_MODE)
            yield tmp
            written = {p.name for p in tmp.iterdir()}
            if written - owned:
                raise RuntimeError(f"atomic_outputs: wrote {', '.join(sorted(written - owned))}, not among the owned files")
            for name in sorted(written):
                os.replace(tmp / name, dest / name)
            for name in sorted(owned - written):
                (dest / name).unlink(missing_ok=True)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
