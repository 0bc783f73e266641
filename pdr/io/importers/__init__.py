"""Importers of ``pdr import FORMAT SRC DEST``: other formats -> canonical recordings (CONTRACT.md).

One module per format. Each reads its source, converts units and clocks to SI (seconds, m/s², rad/s, µT, hPa),
puts the truth the source carries into ``reference/`` and writes one recording folder per recording found, atomically.
Every recording's ``meta.toml`` has ``[recording] id`` (the folder name), ``source`` (the format) and, where the source
knows the wall-clock time, ``start_unix_s``: the Unix time (s) of ``t_s = 0``.

Example
-------
>>> from pathlib import Path
>>> from pdr.io.importers import import_recordings
>>> import_recordings("xio", Path("datasets/xio_foot_imu_loop_walk/short_walk.csv"), Path("out/recs"))  # doctest: +SKIP
[PosixPath('out/recs/short_walk')]
"""

from __future__ import annotations

import importlib
from pathlib import Path

from pdr.errors import InputError

FORMATS = ("oxford", "mobgap", "humolire", "gaitmap", "xio", "sensorlogger", "phyphox", "gpx", "openshoe")


def import_recordings(fmt: str, src: Path, dest: Path, *, rate_hz: float | None = None, force: bool = False,
                      foot: str | None = None, closed_loop: bool = False) -> list[Path]:
    """Convert ``src`` (a file, folder or zip of format ``fmt``) into recordings under ``dest``; return their paths.

    For ``gpx``, ``dest`` is an existing recording that receives ``gnss.csv``.
    ``rate_hz`` is the sampling rate of sources whose files carry only a sample index (gaitmap example data, OpenShoe).
    ``foot`` (``left`` / ``right``) names the foot of a single-foot source (``openshoe``, ``xio``); ``closed_loop``
    declares that the walk ends where it started (a reference the source itself does not carry: ``xio``,
    ``openshoe``). An existing output folder is an InputError unless ``force``.
    """
    if fmt not in FORMATS:
        raise InputError(f"import: expected a format among {', '.join(FORMATS)}, found {fmt!r}")
    if rate_hz is not None and not (rate_hz > 0 and rate_hz < 1e5):
        raise InputError(f"import: expected --rate-hz a positive sampling rate in Hz, found {rate_hz}")
    src, dest = Path(src), Path(dest)
    if not src.exists():
        raise InputError(f"{src}: expected a {fmt} source (file or folder), found nothing there")
    src = src.resolve()  # recordings are named after the source: "." or ".." must give the real folder name
    module = importlib.import_module(f"pdr.io.importers.{fmt}")
    options = {k: v for k, v in (("foot", foot), ("closed_loop", closed_loop)) if v not in (None, False)}
    refused = sorted(set(options) - set(getattr(module, "OPTIONS", ())))
    if refused:
        flags = ", ".join("--" + k.replace("_", "-") for k in refused)
        raise InputError(f"import {fmt}: expected no {flags} (the format does not take it), found it given")
    return module.import_source(src, dest, rate_hz=rate_hz, force=force, **options)
