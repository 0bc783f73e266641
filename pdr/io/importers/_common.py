"""Shared parts of the importers: safe reading of foreign tables, clock repair, resampling, safe zip extraction, output.

Every importer builds its :class:`~pdr.io.recording.Recording` objects in memory, validates all of them, checks that
none of the output folders exists (unless ``force``), and only then writes them through ``save_recording`` (atomic).
"""

from __future__ import annotations

import contextlib
import csv
import lzma
import re
import stat
import tempfile
import zipfile
import zlib
from pathlib import Path, PurePosixPath
from typing import Iterator

import numpy as np
import pandas as pd

from pdr.errors import InputError, warn
from pdr.io.recording import MAX_DT_SPREAD, Recording, save_recording, validate_gnss, validate_imu

# Zip archives (Sensor Logger, phyphox exports) are untrusted input: limits against zip bombs.
MAX_ZIP_TOTAL_BYTES = 2 * 1024**3  # at most 2 GiB uncompressed in total
MAX_ZIP_RATIO = 200.0  # at most 200x compression per member (text CSV compresses 5-20x)
MAX_ZIP_MEMBERS = 10_000
_COPY_CHUNK_BYTES = 1 << 20
MAX_DROPPED_FRACTION = 0.05  # repeated / back-stepping time stamps repaired by dropping; more is an error
MAX_DROPPED_ALWAYS_REPAIRED = 10  # ...except in short files (a GPX track of a few points)
_SAFE_ID = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,127}")


def require_file(path: Path, what: str) -> Path:
    if not path.is_file():
        found = "a folder" if path.is_dir() else "nothing there"
        raise InputError(f"{what}: expected a file {path}, found {found}")
    if path.stat().st_size == 0:
        raise InputError(f"{what}: expected data in {path}, found an empty file")
    return path


def require_dir(path: Path, what: str) -> Path:
    if not path.is_dir():
        found = "a file" if path.is_file() else "nothing there"
        raise InputError(f"{what}: expected a folder {path}, found {found}")
    return path


_TAIL_BYTES = 1 << 16
_EMPTY_ROW = re.compile(r'^[\s"\',;]*$')  # a row of empty cells: `""` (phyphox), `,,`, or blanks
_CUT_NUMBER = re.compile(r"^[-+]?(\d+[.,]?\d*|[.,]\d+)([eE][-+]?\d+)?$")


def _cells(line: str, sep: str | None) -> list[str]:
    if sep is not None and len(sep) > 1:  # a regular expression (whitespace-separated files)
        return re.split(sep, line.strip())
    return next(csv.reader([line], delimiter=sep or ","), [])


def _tail(path: Path, what: str, sep: str | None, last_break: bool) -> int:
    """The number of empty rows (``""``) that end ``path``; an InputError when its last line looks cut off.

    With ``last_break`` (the source always ends its lines with one) a last line without a line break is a cut.
    Otherwise it is normal (Sensor Logger's ``Metadata.csv``, phyphox's data files) and a truncated file is one
    whose last line has fewer cells than the line before it, or whose last cell is no complete
    number while the cell above is one, or is shorter than every cell of that column in the lines before it
    (apps write numbers of a steady width: a cut one is shorter)."""
    size = path.stat().st_size
    with open(path, "rb") as f:
        f.seek(max(0, size - _TAIL_BYTES))
        raw = f.read()
    text = raw.decode("utf-8", errors="replace").replace("\r\n", "\n").replace("\r", "\n")
    lines = text.split("\n")
    if size > _TAIL_BYTES:
        lines = lines[1:]  # the first piece may start mid-line
    broken = not text.endswith("\n")
    n_empty = 0
    while lines and _EMPTY_ROW.match(lines[-1]):
        if lines[-1].strip():
            n_empty += 1
            broken = False  # the row before the empty one ended with a line break
        lines.pop()
    if broken and last_break:
        raise InputError(f"{what}: expected {path.name} to end with a line break, found its last line cut off "
                         "(a truncated file? if it is complete, add a line break at its end)")
    if not broken or len(lines) < 2:
        return n_empty
    last, above = _cells(lines[-1], sep), _cells(lines[-2], sep)
    cut = len(last) < len(above)
    if not cut and last and above:
        cell, ref = last[-1].strip().strip('"'), above[-1].strip().strip('"')
        if _CUT_NUMBER.match(ref):
            rows = [_cells(line, sep) for line in lines[-21:-1]]
            widths = [len(c[-1].strip().strip('"')) for c in rows if len(c) == len(above)]
            cut = not _CUT_NUMBER.match(cell) or len(cell) < min(widths)
    if cut:
        raise InputError(f"{what}: expected complete rows in {path.name}, found its last line cut off (a truncated file?)")
    return n_empty


def read_table(path: Path, what: str, *, last_break: bool = True, **kwargs) -> pd.DataFrame:
    """``pd.read_csv`` whose failures (parse errors, bad encoding, empty file) become one-line InputErrors.

    Empty rows at the end (phyphox writes ``""``) are dropped; a last line cut off is an error (see ``_tail``;
    ``last_break=False`` for sources that may end without a line break)."""
    require_file(path, what)
    n_empty = _tail(path, what, kwargs.get("sep"), last_break)
    try:
        df = pd.read_csv(path, **kwargs)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError, ValueError, IndexError) as exc:
        first = str(exc).splitlines()[0][:120] if str(exc) else type(exc).__name__
        raise InputError(f"{what}: expected a table in {path.name}, found unreadable content ({first})") from None
    if n_empty and len(df) >= n_empty and df.iloc[len(df) - n_empty:].isna().all(axis=None):
        df = df.iloc[: len(df) - n_empty]
    if len(df) == 0:
        raise InputError(f"{what}: expected data rows in {path.name}, found none")
    return df


def numeric_array(df: pd.DataFrame, what: str) -> np.ndarray:
    """All cells as float64; text in a number cell is an InputError naming the column and row."""
    out = np.empty((len(df), df.shape[1]), dtype=float)
    for j, col in enumerate(df.columns):
        s = df[col]
        if pd.api.types.is_numeric_dtype(s) and not pd.api.types.is_bool_dtype(s):
            out[:, j] = s.to_numpy(dtype=float)
            continue
        num = pd.to_numeric(s, errors="coerce")
        bad = num.isna() & s.notna()
        if bad.any():
            row = int(np.flatnonzero(bad.to_numpy())[0])
            raise InputError(f"{what}: expected numbers in column {col!s}, found {str(s.iloc[row])[:30]!r} in data row {row + 1}")
        out[:, j] = num.to_numpy(dtype=float)
    return out


def require_finite(values: np.ndarray, what: str, columns: str) -> None:
    bad = ~np.isfinite(values)
    if bad.any():
        row = int(np.flatnonzero(bad.any(axis=tuple(range(1, values.ndim))) if values.ndim > 1 else bad)[0])
        raise InputError(f"{what}: expected finite numbers in {columns}, found NaN/empty/inf in data row {row + 1} "
                         "(a truncated or damaged file?)")


def increasing_mask(t: np.ndarray, what: str, *, row_offset: int = 0) -> np.ndarray:
    """Keep the samples whose time is later than every earlier sample; warn about what is dropped.

    A source clock that repeats or steps back (the x-io CSV, a few duplicated rows of the Oxford files) is repaired
    this way, never passed on (CONTRACT.md). When more than ``MAX_DROPPED_FRACTION`` of the samples (and more than
    ``MAX_DROPPED_ALWAYS_REPAIRED``) would go, the clock did not stutter but jumped (or the file is unsorted): that is
    an InputError, not a repair that loses data.
    """
    if len(t) == 0:
        return np.zeros(0, dtype=bool)
    prev_max = np.maximum.accumulate(np.concatenate([[-np.inf], t[:-1]]))
    keep = t > prev_max
    n_drop = int((~keep).sum())
    if n_drop:
        first = int(np.flatnonzero(~keep)[0])
        if n_drop > max(MAX_DROPPED_FRACTION * len(t), MAX_DROPPED_ALWAYS_REPAIRED):
            raise InputError(f"{what}: expected increasing time stamps (a few repeats are repaired), found {n_drop} of "
                             f"{len(t)} samples at or before an earlier time, from data row {first + 1 + row_offset} "
                             "(a clock jump or an unsorted file)")
        warn(f"{what}: dropped {n_drop} sample(s) whose time repeats or steps back "
             f"(the first at data row {first + 1 + row_offset})")
    return keep


def uniform_grid(t_start: float, t_end: float, rate_hz: float) -> np.ndarray:
    """Sample instants ``t_start + k / rate_hz`` within ``[t_start, t_end]``."""
    n = int(np.floor((t_end - t_start) * rate_hz + 1e-9)) + 1
    return t_start + np.arange(n) / rate_hz


def interp_columns(t_new: np.ndarray, t: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Linear interpolation of each column of ``values`` (sampled at increasing ``t``) at ``t_new``."""
    values = np.asarray(values, float).reshape(len(t), -1)
    return np.column_stack([np.interp(t_new, t, values[:, j]) for j in range(values.shape[1])])


# ----------------------------------------------------------------------------------------------------------------
# Zip archives
# ----------------------------------------------------------------------------------------------------------------


def _check_member(info: zipfile.ZipInfo, what: str) -> None:
    name = info.filename
    path = PurePosixPath(name.replace("\\", "/"))
    if name.startswith(("/", "\\")) or path.is_absolute() or (len(name) > 1 and name[1] == ":"):
        raise InputError(f"{what}: expected relative paths inside the zip, found the absolute path {name!r}")
    if ".." in path.parts:
        raise InputError(f"{what}: expected paths inside the archive, found {name!r} which escapes the destination")
    mode = info.external_attr >> 16
    if stat.S_ISLNK(mode):
        raise InputError(f"{what}: expected regular files in the zip, found the symbolic link {name!r}")
    if info.flag_bits & 0x1:
        raise InputError(f"{what}: expected an unencrypted zip, found the encrypted member {name!r}")


@contextlib.contextmanager
def source_folder(src: Path, what: str) -> Iterator[Path]:
    """Yield ``src`` itself if it is a folder, or a temporary folder holding a zip's safe extraction.

    Refused: members with absolute paths or ``..`` (escaping the destination), symbolic links, encrypted members,
    more than MAX_ZIP_MEMBERS members, a declared or actual total over MAX_ZIP_TOTAL_BYTES, a member whose
    compression ratio exceeds MAX_ZIP_RATIO (zip bombs). The byte count is enforced while extracting, so a header
    that lies about sizes does not help.
    """
    if src.is_dir():
        yield src
        return
    require_file(src, what)
    if not zipfile.is_zipfile(src):
        raise InputError(f"{what}: expected an export folder or a .zip archive, found the file {src.name} which is not a zip")
    try:
        zf = zipfile.ZipFile(src)
    except (zipfile.BadZipFile, OSError, ValueError) as exc:
        raise InputError(f"{what}: expected a readable zip, found {exc}") from None
    with zf, tempfile.TemporaryDirectory(prefix="pdr-import-") as tmp:
        infos = zf.infolist()
        if len(infos) > MAX_ZIP_MEMBERS:
            raise InputError(f"{what}: expected at most {MAX_ZIP_MEMBERS} members in the zip, found {len(infos)}")
        declared = 0
        for info in infos:
            _check_member(info, what)
            declared += info.file_size
            if info.file_size > 0 and info.file_size > MAX_ZIP_RATIO * max(info.compress_size, 1):
                raise InputError(f"{what}: expected a compression ratio of at most {MAX_ZIP_RATIO:g}, found "
                                 f"{info.file_size / max(info.compress_size, 1):.0f} for {info.filename!r} (a zip bomb?)")
        if declared > MAX_ZIP_TOTAL_BYTES:
            raise InputError(f"{what}: expected at most {MAX_ZIP_TOTAL_BYTES} bytes uncompressed, found {declared} declared")
        root = Path(tmp)
        total = 0
        for info in infos:
            target = root.joinpath(*PurePosixPath(info.filename.replace("\\", "/")).parts)
            if info.is_dir():
                target.mkdir(parents=True, exist_ok=True)
                continue
            target.parent.mkdir(parents=True, exist_ok=True)
            written = 0
            try:
                with zf.open(info) as fin, open(target, "wb") as fout:
                    while chunk := fin.read(_COPY_CHUNK_BYTES):
                        written += len(chunk)
                        total += len(chunk)
                        if written > info.file_size or total > MAX_ZIP_TOTAL_BYTES:
                            raise InputError(f"{what}: expected {info.filename!r} to hold {info.file_size} bytes as declared, "
                                             "found more (a zip bomb?)")
                        fout.write(chunk)
            except (zipfile.BadZipFile, EOFError, OSError, ValueError, NotImplementedError, RuntimeError, zlib.error,
                    lzma.LZMAError) as exc:  # zlib/lzma: a damaged compressed stream
                raise InputError(f"{what}: expected a complete zip, found a damaged member {info.filename!r} ({exc})") from None
        yield root


def find_export_root(folder: Path, names: tuple[str, ...]) -> Path:
    """The folder holding any of ``names`` (an app export zipped with one enclosing folder is accepted)."""
    if any((folder / n).is_file() for n in names):
        return folder
    subs = [p for p in folder.iterdir() if p.is_dir() and not p.name.startswith(("__MACOSX", "."))]
    if len(subs) == 1 and any((subs[0] / n).is_file() for n in names):
        return subs[0]
    return folder


# ----------------------------------------------------------------------------------------------------------------
# Output
# ----------------------------------------------------------------------------------------------------------------


def write_recordings(recordings: list[Recording], dest: Path, *, force: bool) -> list[Path]:
    """Validate every recording, refuse existing output folders (unless ``force``), then write each atomically."""
    if dest.exists() and not dest.is_dir():
        raise InputError(f"{dest}: expected a destination folder, found a file")
    for rec in recordings:
        if not _SAFE_ID.fullmatch(rec.id):
            raise InputError(f"{rec.id!r}: expected a recording name of letters, digits, '.', '_' and '-' (it names a folder), "
                             "found other characters; rename the source")
        what = f"{rec.id}/imu.csv"
        validate_imu(rec.imu, what)
        for placement, df in rec.extra_imus.items():
            validate_imu(df, f"{rec.id}/imu_{placement}.csv")
        if rec.gnss is not None:
            validate_gnss(rec.gnss, f"{rec.id}/gnss.csv")
        target = dest / rec.id
        if target.exists() and not force:
            raise InputError(f"{target}: expected a new recording folder, found an existing one (use --force to replace it)")
    return [save_recording(rec, dest / rec.id, force=force) for rec in recordings]


def imu_frame(t_s: np.ndarray, acc_mps2: np.ndarray, gyr_radps: np.ndarray | None = None,
              mag_ut: np.ndarray | None = None, baro_hpa: np.ndarray | None = None) -> pd.DataFrame:
    """A canonical IMU table from arrays already in SI units."""
    cols: dict[str, np.ndarray] = {"t_s": np.asarray(t_s, float)}
    for prefix, unit, arr in (("acc", "mps2", acc_mps2), ("gyr", "radps", gyr_radps), ("mag", "ut", mag_ut)):
        if arr is not None:
            arr = np.asarray(arr, float)
            for j, axis in enumerate("xyz"):
                cols[f"{prefix}_{axis}_{unit}"] = arr[:, j]
    if baro_hpa is not None:
        cols["baro_hpa"] = np.asarray(baro_hpa, float).ravel()
    return pd.DataFrame(cols)


def steady_clock(t: np.ndarray, values: np.ndarray, what: str) -> tuple[np.ndarray, np.ndarray]:
    """Return ``(t, values)`` unchanged when the rate is steady enough for the validator; otherwise resample them
    linearly onto a uniform grid at the mean rate (rounded to 1 Hz; the median of a wildly varying clock can be any
    of its modes) and warn. Only wild jitter (interquartile ratio
    of the sample intervals above ``MAX_DT_SPREAD``) is resampled."""
    if len(t) < 2:
        raise InputError(f"{what}: expected at least 2 samples with increasing time, found {len(t)}")
    dt = np.diff(t)
    q25, q75 = np.percentile(dt, [25, 75])
    if q25 > 0 and q75 / q25 <= MAX_DT_SPREAD:
        return t, values
    rate = float(max(1.0, round((len(t) - 1) / (t[-1] - t[0]))))
    if (t[-1] - t[0]) * rate + 1 > 2 * len(t):  # a mean rate below 1 Hz: the clock jumped (or is not in seconds)
        raise InputError(f"{what}: expected a sensor clock, found {len(t)} samples spread over {t[-1] - t[0]:.6g} s "
                         f"(the largest interval {float(dt.max()):.6g} s: a clock jump or a wrong time unit?)")
    grid = uniform_grid(t[0], t[-1], rate)
    warn(f"{what}: sample intervals vary wildly (interquartile {q25 * 1e3:.2f} to {q75 * 1e3:.2f} ms); "
         f"resampled linearly to a uniform {rate:g} Hz grid")
    return grid, interp_columns(grid, t, values)


def resample_mean(t_new: np.ndarray, t: np.ndarray, values: np.ndarray, rate_hz: float) -> np.ndarray:
    """Each column of ``values`` (irregular, increasing ``t``) averaged over ``[t_new - h/2, t_new + h/2]``, h = 1/rate.

    The mean over a window of one output period (from the cumulative trapezoid integral, so irregular spacing is
    weighted correctly) is a box low-pass filter with its first null at ``rate_hz``: downsampling an irregular
    ~400 Hz phone clock to 200 Hz this way aliases far less than picking or interpolating samples.
    ``t_new +- h/2`` must lie within ``[t[0], t[-1]]``.
    """
    values = np.asarray(values, float).reshape(len(t), -1)
    h = 1.0 / rate_hz
    dt = np.diff(t)[:, None]
    cum = np.vstack([np.zeros((1, values.shape[1])), np.cumsum(0.5 * (values[1:] + values[:-1]) * dt, axis=0)])
    lo, hi = t_new - h / 2, t_new + h / 2
    # integral at any instant: cumulative value at the previous sample + the trapezoid of the partial interval
    def integral(x: np.ndarray) -> np.ndarray:
        i = np.clip(np.searchsorted(t, x, side="right") - 1, 0, len(t) - 2)
        frac = ((x - t[i]) / (t[i + 1] - t[i]))[:, None]
        v0, v1 = values[i], values[i + 1]
        return cum[i] + (x - t[i])[:, None] * (v0 + 0.5 * frac * (v1 - v0))
    return (integral(hi) - integral(lo)) / h


def safe_id(name: str) -> str:
    """A recording id / folder name from a source's name: letters, digits, '-', '_', '.' only."""
    out = re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("._-")[:128]
    return out or "recording"
