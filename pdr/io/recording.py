"""The canonical recording of CONTRACT.md: a directory with ``meta.toml`` and ``imu.csv`` (and optional files).

``load_recording`` reads and validates; ``save_recording`` writes atomically; ``validate_imu`` / ``validate_gnss``
check one table and raise an :class:`InputError` that says what was expected and what was found.
Nothing is ever fixed silently: data in g, deg/s, unsorted time or NaN runs are errors with a hint.
"""

from __future__ import annotations

import dataclasses
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pdr.constants import GRAVITY_MPS2
from pdr.errors import InputError
from pdr.io.atomic import CSV_DIGITS, atomic_dir, write_csv, write_text
from pdr.io.tomlio import dumps_toml, read_toml
from pdr.schema import require_table

PLACEMENTS = (
    "waist", "trunk", "pocket", "hand", "bag", "arm", "neck", "head",
    "foot_left", "foot_right", "shank_left", "shank_right", "unknown",
)
TRUNK_PLACEMENTS = ("waist", "trunk")  # sensors that move with the trunk (lower back, sacrum, belt)
SUBJECT_KEYS = (
    "height_m", "mass_kg", "leg_length_m", "sensor_height_m", "thigh_length_m", "shank_length_m", "foot_length_m",
)
SUBJECT_HEIGHT_RANGE_M = (0.9, 2.5)  # a body height in metres (a number above is centimetres or a typo)
SUBJECT_PART_KEYS = ("leg_length_m", "sensor_height_m", "thigh_length_m", "shank_length_m", "foot_length_m")
SUBJECT_LEG_PER_HEIGHT_RANGE = (0.40, 0.62)  # standing hip height / height: 0.53 on average (Winter 2009)
ACC_COLUMNS = ("acc_x_mps2", "acc_y_mps2", "acc_z_mps2")
GYR_COLUMNS = ("gyr_x_radps", "gyr_y_radps", "gyr_z_radps")
MAG_COLUMNS = ("mag_x_ut", "mag_y_ut", "mag_z_ut")
IMU_COLUMNS = ("t_s", *ACC_COLUMNS, *GYR_COLUMNS, *MAG_COLUMNS, "baro_hpa")
GNSS_COLUMNS = ("t_s", "lat_deg", "lon_deg", "e_m", "n_m", "alt_m", "u_m", "h_acc_m")
REFERENCE_TABLES = {
    "steps": ("t_s",),
    "strides": ("t_start_s", "t_end_s", "foot", "length_m"),
    "trajectory": ("t_s", "e_m", "n_m"),
    "landmarks": ("t_s", "e_m", "n_m"),
    "bouts": ("t_start_s", "t_end_s"),
    "handling": ("t_start_s", "t_end_s", "action"),
}
VIDEO_NAMES = ("video.avi", "video.mp4")

# Plausibility bounds used to catch wrong units (never to "fix" them).
ACC_G_MEDIAN_RANGE = (0.5, 1.5)  # median |a| in this range: the file is in g
ACC_MPS2_MEDIAN_RANGE = (4.0, 30.0)  # a body-worn sensor in m/s² has median |a| near 9.8
GYR_MAX_PLAUSIBLE_RADPS = 40.0  # 2,300 deg/s: beyond any human segment; larger values mean deg/s
MAG_UT_MEDIAN_RANGE = (5.0, 500.0)  # the Earth's field is 25-65 µT; indoors 5-500
BARO_HPA_RANGE = (250.0, 1100.0)
MAX_DT_SPREAD = 4.0  # interquartile ratio of sample intervals above which the rate "varies wildly"
# Below this rate t_s is not in seconds: milliseconds read as seconds give 0.1 Hz for a 100 Hz IMU. A real 5 Hz phone
# export passes (no steps can be found below 7 Hz, twice the highest cadence: pdr run then follows the GNSS alone).
MIN_IMU_RATE_HZ = 1.0
# [subject] values a person has (adults and children; CDC growth charts, Winter 2009 Table 4.1 for the segment
# ratios to height): beyond these the unit is wrong (a height in cm, a mass in g).
SUBJECT_RANGES = {
    "height_m": (0.5, 2.5), "mass_kg": (2.0, 350.0), "leg_length_m": (0.2, 1.4), "sensor_height_m": (0.0, 2.5),
    "thigh_length_m": (0.1, 0.7), "shank_length_m": (0.1, 0.7), "foot_length_m": (0.05, 0.4),
}
REFERENCE_TEXT_COLUMNS = ("foot", "mechanics_source", "action")  # every other column of a reference table holds numbers


@dataclasses.dataclass
class Recording:
    """One recording, in SI units, validated.

    Attributes
    ----------
    meta : the parsed ``meta.toml`` (``recording``, optional ``subject`` and ``geo`` tables).
    imu : the main IMU table (``imu.csv``), columns of CONTRACT.md.
    extra_imus : further IMUs by placement (``imu_<placement>.csv``), same columns and clock.
    gnss : ``gnss.csv`` or None.
    camera : the parsed ``camera.toml`` or None; ``video_path`` and ``frames`` (``frames.csv``) go with it.
    reference : ground truth tables by name (``steps``, ``strides``, ``trajectory``, ``landmarks``) and
        ``summary`` (a dict); only evaluation reads it.
    path : where it was loaded from (None for an in-memory recording).
    """

    meta: dict[str, Any]
    imu: pd.DataFrame
    extra_imus: dict[str, pd.DataFrame] = dataclasses.field(default_factory=dict)
    gnss: pd.DataFrame | None = None
    camera: dict[str, Any] | None = None
    video_path: Path | None = None
    frames: pd.DataFrame | None = None
    reference: dict[str, Any] = dataclasses.field(default_factory=dict)
    path: Path | None = None

    @property
    def id(self) -> str:
        return str(self.meta["recording"]["id"])

    @property
    def placement(self) -> str:
        return str(self.meta["recording"].get("placement", "unknown"))

    @property
    def subject(self) -> dict[str, float]:
        return dict(self.meta.get("subject", {}))

    @property
    def geo_origin(self) -> tuple[float, float] | None:
        geo = self.meta.get("geo")
        if not geo:
            return None
        return float(geo["origin_lat_deg"]), float(geo["origin_lon_deg"])

    def imus_by_placement(self) -> dict[str, pd.DataFrame]:
        """All IMUs keyed by placement: the main one under its ``meta`` placement, then the extra ones."""
        return {self.placement: self.imu, **self.extra_imus}

    @property
    def sample_rate_hz(self) -> float:
        return sample_rate_hz(self.imu["t_s"].to_numpy())


def sample_rate_hz(t_s: np.ndarray) -> float:
    """The nominal rate: 1 / median sample interval."""
    if len(t_s) < 2:
        return float("nan")
    return float(1.0 / np.median(np.diff(t_s)))


# ----------------------------------------------------------------------------------------------------------------
# Validation of tables
# ----------------------------------------------------------------------------------------------------------------


def numeric_frame(df: pd.DataFrame, what: str) -> pd.DataFrame:
    """Every cell numeric (NaN allowed here, judged later); say where text was found."""
    out = {}
    for col in df.columns:
        s = df[col]
        if pd.api.types.is_numeric_dtype(s) and not pd.api.types.is_bool_dtype(s):
            out[col] = s.astype(float)
            continue
        num = pd.to_numeric(s, errors="coerce")
        bad = num.isna() & s.notna() & (s.astype(str).str.strip() != "")
        if bad.any():
            row = int(np.flatnonzero(bad.to_numpy())[0])
            raise InputError(f"{what}: expected numbers in column {col}, found {str(s.iloc[row])[:30]!r} in data row {row + 1}")
        out[col] = num.astype(float)
    return pd.DataFrame(out, index=df.index)


def check_time(t_s: np.ndarray, what: str, *, min_rows: int = 1) -> None:
    """``t_s`` finite and strictly increasing."""
    if len(t_s) < min_rows:
        raise InputError(f"{what}: expected at least {min_rows} data row(s), found {len(t_s)}")
    finite = np.isfinite(t_s)
    if not finite.all():
        row = int(np.flatnonzero(~finite)[0])
        raise InputError(f"{what}: expected finite t_s, found {t_s[row]} in data row {row + 1}")
    dt = np.diff(t_s)
    if (dt == 0).any():
        row = int(np.flatnonzero(dt == 0)[0]) + 1
        raise InputError(f"{what}: expected strictly increasing t_s, found a repeated time {t_s[row]:.6f} s in data row {row + 1}")
    if (dt < 0).any():
        row = int(np.flatnonzero(dt < 0)[0]) + 1
        raise InputError(
            f"{what}: expected strictly increasing t_s, found {t_s[row]:.6f} s after {t_s[row - 1]:.6f} s in data row {row + 1} (unsorted)"
        )


def _check_nan(df: pd.DataFrame, columns: list[str], what: str) -> None:
    for col in columns:
        nan = df[col].isna().to_numpy() | ~np.isfinite(df[col].to_numpy())
        if nan.any():
            idx = np.flatnonzero(nan)
            # length of the first run
            run_end = idx[0]
            while run_end + 1 < len(nan) and nan[run_end + 1]:
                run_end += 1
            t = df["t_s"].to_numpy()
            raise InputError(
                f"{what}: expected finite values in {col}, found {int(nan.sum())} NaN/inf sample(s), the first run "
                f"from t = {t[idx[0]]:.3f} s to {t[run_end]:.3f} s (remove or interpolate them before import)"
            )


def validate_imu(df: pd.DataFrame, what: str = "imu.csv") -> pd.DataFrame:
    """Check an IMU table against CONTRACT.md and return it with float columns in canonical order."""
    require_table(df, ("t_s", *ACC_COLUMNS), what)
    for group in (GYR_COLUMNS, MAG_COLUMNS):
        present = [c for c in group if c in df.columns]
        if present and len(present) != 3:
            raise InputError(f"{what}: expected all of {', '.join(group)} or none, found only {', '.join(present)}")
    unknown = [c for c in df.columns if c not in IMU_COLUMNS]
    if unknown:
        raise InputError(f"{what}: expected only the columns of CONTRACT.md ({', '.join(IMU_COLUMNS)}), found {', '.join(map(str, unknown))}")
    df = numeric_frame(df[[c for c in IMU_COLUMNS if c in df.columns]], what)
    t = df["t_s"].to_numpy()
    check_time(t, what, min_rows=2)
    _check_nan(df, [c for c in df.columns if c != "t_s"], what)

    dt = np.diff(t)
    rate = 1.0 / float(np.median(dt))
    if rate < MIN_IMU_RATE_HZ:
        hint = " (time stamps in milliseconds? divide t_s by 1000)" if 0.01 <= rate < 1.0 else ""
        raise InputError(f"{what}: expected t_s in seconds at a rate of at least {MIN_IMU_RATE_HZ:g} Hz, found a median "
                         f"sample interval of {1.0 / rate:.6g} s ({rate:.3g} Hz){hint}")
    q25, q75 = np.percentile(dt, [25, 75])
    if q75 / q25 > MAX_DT_SPREAD:
        raise InputError(
            f"{what}: expected a steady sampling rate, found sample intervals varying wildly "
            f"(interquartile {q25 * 1e3:.2f} to {q75 * 1e3:.2f} ms); resample the file first"
        )

    acc_norm = np.linalg.norm(df[list(ACC_COLUMNS)].to_numpy(), axis=1)
    med = float(np.median(acc_norm))
    if ACC_G_MEDIAN_RANGE[0] <= med <= ACC_G_MEDIAN_RANGE[1]:
        raise InputError(
            f"{what}: expected acceleration in m/s² (median |a| near {GRAVITY_MPS2}), found median |a| = {med:.3f}: "
            f"the data look like g; multiply by {GRAVITY_MPS2}"
        )
    if not ACC_MPS2_MEDIAN_RANGE[0] <= med <= ACC_MPS2_MEDIAN_RANGE[1]:
        raise InputError(
            f"{what}: expected acceleration in m/s² with gravity included (median |a| near {GRAVITY_MPS2}), found median |a| = {med:.3g}"
        )
    if "gyr_x_radps" in df.columns:
        gyr_max = float(np.max(np.abs(df[list(GYR_COLUMNS)].to_numpy())))
        if gyr_max > GYR_MAX_PLAUSIBLE_RADPS:
            raise InputError(
                f"{what}: expected angular rate in rad/s (at most {GYR_MAX_PLAUSIBLE_RADPS:g} for a human), found "
                f"|w| up to {gyr_max:.1f}: the data look like deg/s; multiply by pi/180"
            )
    if "mag_x_ut" in df.columns:
        mag_med = float(np.median(np.linalg.norm(df[list(MAG_COLUMNS)].to_numpy(), axis=1)))
        if not MAG_UT_MEDIAN_RANGE[0] <= mag_med <= MAG_UT_MEDIAN_RANGE[1]:
            hint = " (looks like gauss: multiply by 100)" if mag_med < MAG_UT_MEDIAN_RANGE[0] else " (looks like nT: divide by 1000)"
            raise InputError(f"{what}: expected magnetic field in µT (|B| 25-65 outdoors), found median |B| = {mag_med:.4g}{hint}")
    if "baro_hpa" in df.columns:
        p_med = float(np.median(df["baro_hpa"]))
        if not BARO_HPA_RANGE[0] <= p_med <= BARO_HPA_RANGE[1]:
            hint = " (looks like Pa: divide by 100)" if p_med > BARO_HPA_RANGE[1] else ""
            raise InputError(f"{what}: expected pressure in hPa ({BARO_HPA_RANGE[0]:g}-{BARO_HPA_RANGE[1]:g}), found median {p_med:.6g}{hint}")
    return df.reset_index(drop=True)


def validate_gnss(df: pd.DataFrame, what: str = "gnss.csv") -> pd.DataFrame:
    """Check a GNSS table: ``t_s`` and either ``lat_deg, lon_deg`` or ``e_m, n_m``.

    A row with NaN position is a fix the receiver marked invalid; it is kept and skipped by the fusion.
    """
    has_ll = {"lat_deg", "lon_deg"} <= set(df.columns)
    has_en = {"e_m", "n_m"} <= set(df.columns)
    if "t_s" not in df.columns or not (has_ll or has_en):
        raise InputError(f"{what}: expected columns t_s and lat_deg, lon_deg (or e_m, n_m), found {', '.join(map(str, df.columns)) or 'none'}")
    unknown = [c for c in df.columns if c not in GNSS_COLUMNS]
    if unknown:
        raise InputError(f"{what}: expected only the columns {', '.join(GNSS_COLUMNS)}, found {', '.join(map(str, unknown))}")
    df = numeric_frame(df[[c for c in GNSS_COLUMNS if c in df.columns]], what)
    check_time(df["t_s"].to_numpy(), what)
    if has_ll:
        lat, lon = df["lat_deg"].to_numpy(), df["lon_deg"].to_numpy()
        ok = np.isfinite(lat)
        if (np.abs(lat[ok]) > 90).any() or (np.abs(lon[np.isfinite(lon)]) > 180).any():
            raise InputError(f"{what}: expected lat_deg in [-90, 90] and lon_deg in [-180, 180], found values outside")
    if "h_acc_m" in df.columns:
        acc = df["h_acc_m"].to_numpy()
        if (acc[np.isfinite(acc)] <= 0).any():
            raise InputError(f"{what}: expected h_acc_m > 0 (1-sigma horizontal accuracy, m), found a value <= 0")
    return df.reset_index(drop=True)


def check_subject(subject: dict[str, Any], what: str = "meta.toml [subject]") -> None:
    """An InputError (one line) when the ``[subject]`` lengths are not plausible metres of one person: a height in
    centimetres, a leg longer than the body, a sensor above the head."""
    height = subject.get("height_m")
    if height is not None and not SUBJECT_HEIGHT_RANGE_M[0] <= height <= SUBJECT_HEIGHT_RANGE_M[1]:
        hint = f" (in cm? a height in centimetres: write {height / 100:g})" if 90 <= height <= 250 else ""
        raise InputError(f"{what}: expected height_m in metres ({SUBJECT_HEIGHT_RANGE_M[0]:g}-{SUBJECT_HEIGHT_RANGE_M[1]:g}), "
                         f"found {height:g}{hint}")
    for key in SUBJECT_PART_KEYS:
        value = subject.get(key)
        if value is None:
            continue
        if value >= SUBJECT_HEIGHT_RANGE_M[1]:
            raise InputError(f"{what}: expected {key} in metres (below {SUBJECT_HEIGHT_RANGE_M[1]:g}), found {value:g} "
                             f"(in centimetres? write {value / 100:g})")
        if height is not None and value >= height:
            part = "a sensor above the head" if key == "sensor_height_m" else f"a {key[:-9].replace('_', ' ')} longer than the body"
            raise InputError(f"{what}: expected {key} below height_m ({height:g} m), found {value:g} m ({part})")
    leg = subject.get("leg_length_m")
    if leg is not None and height is not None and not SUBJECT_LEG_PER_HEIGHT_RANGE[0] <= leg / height <= SUBJECT_LEG_PER_HEIGHT_RANGE[1]:
        raise InputError(f"{what}: expected leg_length_m (standing hip height) {SUBJECT_LEG_PER_HEIGHT_RANGE[0]:g}-"
                         f"{SUBJECT_LEG_PER_HEIGHT_RANGE[1]:g} of height_m ({height:g} m), found {leg:g} m")


def _validate_meta(meta: dict[str, Any], what: str) -> None:
    rec = meta.get("recording")
    if not isinstance(rec, dict) or "id" not in rec:
        raise InputError(f"{what}: expected a [recording] table with id, found {sorted(meta) or 'nothing'}")
    start = rec.get("start_unix_s")
    if start is not None and (isinstance(start, bool) or not isinstance(start, (int, float)) or not np.isfinite(start)):
        raise InputError(f"{what}: expected [recording] start_unix_s a number (Unix time of t_s = 0, s), found {start!r}")
    placement = rec.get("placement", "unknown")
    if placement not in PLACEMENTS:
        raise InputError(f"{what}: expected placement one of {', '.join(PLACEMENTS)}, found {placement!r}")
    subject = meta.get("subject", {})
    for key, value in subject.items():
        if key not in SUBJECT_KEYS:
            raise InputError(f"{what}: expected [subject] keys among {', '.join(SUBJECT_KEYS)}, found {key!r}")
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise InputError(f"{what}: expected a number for subject.{key}, found {value!r}")
    check_subject(subject, f"{what} [subject]")  # lengths of one person: cm, a leg longer than the body, ...
    for key, value in subject.items():
        lo, hi = SUBJECT_RANGES[key]
        if not lo <= value <= hi:
            unit = key.rsplit("_", 1)[1]
            hint = (" (in cm? divide by 100)" if unit == "m" and 100 * lo <= value <= 100 * hi
                    else " (in g? divide by 1000)" if unit == "kg" and value > hi else "")
            raise InputError(f"{what}: expected subject.{key} between {lo:g} and {hi:g} {unit}, found {value!r}{hint}")
    geo = meta.get("geo")
    if geo is not None:
        try:
            lat, lon = float(geo["origin_lat_deg"]), float(geo["origin_lon_deg"])
        except (KeyError, TypeError, ValueError):
            raise InputError(f"{what}: expected [geo] origin_lat_deg and origin_lon_deg numbers, found {geo!r}") from None
        if abs(lat) > 90 or abs(lon) > 180:
            raise InputError(f"{what}: expected a geo origin on Earth, found lat {lat}, lon {lon}")


# ----------------------------------------------------------------------------------------------------------------
# Load / save
# ----------------------------------------------------------------------------------------------------------------


def read_csv(path: Path, what: str | None = None, *, empty_is_missing: bool = False) -> pd.DataFrame:
    """A header-row CSV; empty or unreadable files become InputErrors. With ``empty_is_missing`` only an empty cell
    is a missing value: text such as ``N/A`` or ``null`` stays text (and a number check then names it)."""
    what = what or str(path)
    if not path.is_file():
        raise InputError(f"{what}: expected a file, found nothing there")
    if path.stat().st_size == 0:
        raise InputError(f"{what}: expected a header row and data, found an empty file")
    try:
        df = (pd.read_csv(path, skipinitialspace=True, keep_default_na=False, na_values=[""]) if empty_is_missing
              else pd.read_csv(path, skipinitialspace=True))
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError, ValueError) as exc:
        raise InputError(f"{what}: expected a CSV table, found unreadable content ({str(exc).splitlines()[0][:120]})") from None
    df.columns = [str(c).strip() for c in df.columns]
    return df


def _reference_summary(raw: dict[str, Any]) -> dict[str, Any]:
    """``reference/summary.toml``: its ``[summary]`` table, or the same keys written at the top level without one."""
    if "summary" in raw:
        if not isinstance(raw["summary"], dict) or len(raw) > 1:
            raise InputError("reference/summary.toml: expected one [summary] table (or its keys at the top level), found "
                             f"{', '.join(sorted(raw))}")
        return raw["summary"]
    tables = sorted(k for k, v in raw.items() if isinstance(v, dict))
    if tables:
        raise InputError(f"reference/summary.toml: expected a [summary] table (or its keys at the top level), found the "
                         f"table(s) {', '.join(tables)}")
    return raw


def _load_reference(ref_dir: Path) -> dict[str, Any]:
    reference: dict[str, Any] = {}
    if not ref_dir.is_dir():
        return reference
    for name, required in REFERENCE_TABLES.items():
        path = ref_dir / f"{name}.csv"
        if path.is_file():
            what = f"{ref_dir}/{name}.csv"
            df = read_csv(path, what, empty_is_missing=True)
            missing = [c for c in required if c not in df.columns]
            if missing:
                raise InputError(f"{what}: expected columns {', '.join(required)}, found {', '.join(df.columns)}")
            numeric = [c for c in df.columns if c not in REFERENCE_TEXT_COLUMNS]
            df[numeric] = numeric_frame(df[numeric], what)
            reference[name] = df
    if (ref_dir / "summary.toml").is_file():
        reference["summary"] = _reference_summary(read_toml(ref_dir / "summary.toml", what=f"{ref_dir}/summary.toml"))
    return reference


def load_recording(path: str | Path, *, with_reference: bool = True) -> Recording:
    """Read and validate a canonical recording directory; raise InputError on the first problem found."""
    path = Path(path)
    if not path.is_dir():
        raise InputError(f"{path}: expected a recording folder (meta.toml + imu.csv), found {'a file' if path.exists() else 'nothing'}")
    meta = read_toml(path / "meta.toml", what=f"{path}/meta.toml")
    _validate_meta(meta, f"{path}/meta.toml")
    imu = validate_imu(read_csv(path / "imu.csv"), f"{path}/imu.csv")
    extra = {}
    for p in sorted(path.glob("imu_*.csv")):
        placement = p.stem[len("imu_"):]
        if placement not in PLACEMENTS:
            raise InputError(f"{p}: expected imu_<placement>.csv with a placement of CONTRACT.md, found {placement!r}")
        extra[placement] = validate_imu(read_csv(p), str(p))
    gnss = (validate_gnss(read_csv(path / "gnss.csv", empty_is_missing=True), f"{path}/gnss.csv")
            if (path / "gnss.csv").exists() else None)
    if gnss is not None and "lat_deg" in gnss.columns and "geo" not in meta:
        raise InputError(f"{path}/meta.toml: expected a [geo] origin because gnss.csv has lat_deg/lon_deg, found none")
    camera = video = frames = None
    videos = [path / n for n in VIDEO_NAMES if (path / n).exists()]
    if videos or (path / "camera.toml").exists():
        if not videos or not (path / "camera.toml").exists():
            raise InputError(f"{path}: expected video.avi or video.mp4 together with camera.toml, found only one of them")
        camera = read_toml(path / "camera.toml", what=f"{path}/camera.toml")
        video = videos[0]
        if (path / "frames.csv").exists():
            frames = numeric_frame(read_csv(path / "frames.csv"), f"{path}/frames.csv")
            if "t_s" not in frames.columns:
                raise InputError(f"{path}/frames.csv: expected column t_s, found {', '.join(frames.columns)}")
            check_time(frames["t_s"].to_numpy(), f"{path}/frames.csv")
    reference = _load_reference(path / "reference") if with_reference else {}
    return Recording(meta=meta, imu=imu, extra_imus=extra, gnss=gnss, camera=camera, video_path=video,
                     frames=frames, reference=reference, path=path)


TIME_RESOLUTION_S = 1e-5  # time columns are written to 10 µs at least: 1/1000 of a 100 Hz sample interval
TIME_COLUMNS = ("t_s", "t_start_s", "t_end_s")


def exact_time_column(df: pd.DataFrame, column: str = "t_s") -> pd.DataFrame:
    """``df`` with ``column`` as text when ``CSV_DIGITS`` significant digits would round its times by more than
    ``TIME_RESOLUTION_S`` (or merge or reorder distinct, increasing times).

    The CSV tables are written with 9 significant digits: 10 µs or better up to 10,000 s. A clock far from zero (a
    Unix time: 1.7e9 s) needs more; the column then gets the digits that keep ``TIME_RESOLUTION_S`` at its largest
    time (15 at 1.7e9 s), and more while increasing times would repeat (up to 17, exact). A fixed resolution rather
    than the fewest digits that keep the order: those round a phone's jittered sample instants to 1 ms at 1.7e9 s,
    a tenth of a 100 Hz interval, and reference times (landmarks 10 s apart) to 10 s. Otherwise ``df`` is returned
    unchanged (the usual case, so files stay as they were)."""
    if column not in df.columns:
        return df
    t = df[column].to_numpy(float)
    finite = np.abs(t[np.isfinite(t)])
    if not len(finite) or not finite.max() > 0:
        return df
    digits = max(CSV_DIGITS, int(np.floor(np.log10(finite.max()))) + 1 - int(round(np.log10(TIME_RESOLUTION_S))))
    digits = min(digits, 17)
    increasing = len(t) > 1 and np.isfinite(t).all() and (np.diff(t) > 0).all()
    while increasing and digits < 17 and not (np.diff(np.char.mod(f"%.{digits}g", t).astype(float)) > 0).all():
        digits += 1
    if digits == CSV_DIGITS:
        return df
    out = df.copy()
    out[column] = np.where(np.isfinite(t), np.char.mod(f"%.{digits}g", t), "")
    return out


def exact_time_columns(df: pd.DataFrame) -> pd.DataFrame:
    """:func:`exact_time_column` for each time column of ``df`` (``TIME_COLUMNS``)."""
    for column in TIME_COLUMNS:
        df = exact_time_column(df, column)
    return df


def save_recording(rec: Recording, dest: str | Path, *, force: bool = False) -> Path:
    """Write a recording folder atomically (validated first). An existing ``dest`` needs ``force``."""
    dest = Path(dest)
    _validate_meta(rec.meta, "meta")
    imu = validate_imu(rec.imu, "imu")
    extra = {k: validate_imu(v, f"imu_{k}") for k, v in rec.extra_imus.items()}
    gnss = validate_gnss(rec.gnss, "gnss") if rec.gnss is not None else None
    with atomic_dir(dest, force=force) as tmp:
        write_text(tmp / "meta.toml", dumps_toml(rec.meta))
        write_csv(tmp / "imu.csv", exact_time_column(imu))
        for placement, df in extra.items():
            write_csv(tmp / f"imu_{placement}.csv", exact_time_column(df))
        if gnss is not None:
            write_csv(tmp / "gnss.csv", exact_time_column(gnss))
        if rec.camera is not None:
            write_text(tmp / "camera.toml", dumps_toml(rec.camera))
            if rec.video_path is not None:
                shutil.copyfile(rec.video_path, tmp / rec.video_path.name)
        if rec.frames is not None:
            write_csv(tmp / "frames.csv", exact_time_column(rec.frames))
        if rec.reference:
            (tmp / "reference").mkdir()
            for name, value in rec.reference.items():
                if name == "summary":
                    write_text(tmp / "reference" / "summary.toml", dumps_toml({"summary": value}))
                else:
                    write_csv(tmp / "reference" / f"{name}.csv", exact_time_columns(value))
    return dest
