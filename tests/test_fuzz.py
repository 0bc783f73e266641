"""Fuzzing (hypothesis) of every importer of ``pdr import``, of ``pdr validate`` and of ``pdr gait-camera estimate``,
through the CLI ``main(argv)``.

Each case takes a small valid source (trimmed real data from ``datasets/`` or the hand-written exports of
``tests/importers/``), damages one of its files with one to three mutations (random truncation, random bytes, swapped
columns, NaN / inf / empty runs, duplicated and reversed rows, a column partly in other units, a number replaced by a
special value, an empty / header-only / one-row file; for the phone apps optionally zipped, and the zip itself damaged)
and runs the command. The property:

- exit 0: every printed recording loads and validates, and DEST holds exactly those recordings; or
- exit 1 with exactly one ``error:`` line on stderr (other lines may only be ``warning:`` lines), DEST unchanged;
- never an escaped exception: ``main`` turns one into ``error: internal failure ...``, which fails the test;
- never a leftover temporary file (the temporary folder of the process is redirected into the case folder);
- never a hang: each case runs under a ``SIGALRM`` of ``CASE_TIMEOUT_S``.

Profiles (environment ``PDR_FUZZ``): ``short`` (default, in ``make test``: a few derandomised examples per target,
under a minute in all) and ``long`` (``make fuzz``: ``PDR_FUZZ_EXAMPLES`` per target, default 1,200, over 12
targets: > 10,000 cases; counts and the slowest case go to ``out/fuzz/stats.json``).
Every crash found is kept below as an explicit ``@example`` of the target that found it.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
import re
import shutil
import signal
import tempfile
import time
import zipfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from pdr.cli.main import main
from pdr.io.recording import Recording, load_recording, save_recording

from conftest import DATASETS
from pdr.io.datasets import missing_files
from pdr.errors import collect_warnings

ROOT = Path(__file__).resolve().parents[1]
HAND = Path(__file__).resolve().parent / "importers"

PROFILE = os.environ.get("PDR_FUZZ", "short")
if PROFILE not in ("short", "long"):
    raise RuntimeError(f"PDR_FUZZ: expected short or long, found {PROFILE!r}")
LONG = PROFILE == "long"
EXAMPLES = int(os.environ.get("PDR_FUZZ_EXAMPLES", "1200")) if LONG else 25
CASE_TIMEOUT_S = 120.0  # generous: the machine is shared; a hang is minutes, a slow case a few seconds
FUZZ = settings(max_examples=EXAMPLES, deadline=None, derandomize=not LONG, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much],
                print_blob=True)
STATS: dict[str, dict] = {}


# ---------------------------------------------------------------------------------------------------------------
# Mutations of a file's bytes
# ---------------------------------------------------------------------------------------------------------------

SPECIAL = [b"nan", b"NaN", b"inf", b"-inf", b"", b"1e400", b"-0", b"NA", b"0x10", b"1,5", b"\xff\xfe"]
FACTORS = [9.80665, 1 / 9.80665, 180 / math.pi, math.pi / 180, 1e3, 1e-3, 1e9, 100.0, -1.0]
_NUMBER = re.compile(rb"-?\d+(?:[.,]\d+)?(?:[eE][-+]?\d+)?")

frac = st.floats(0.0, 1.0)
OPS = st.one_of(
    st.tuples(st.just("truncate"), frac),
    st.tuples(st.just("bytes"), frac, st.binary(min_size=1, max_size=24), st.booleans()),
    st.tuples(st.just("swap_columns"), st.integers(0, 12), st.integers(0, 12), st.booleans()),
    st.tuples(st.just("special_run"), st.integers(0, 12), frac, st.integers(1, 80), st.sampled_from(SPECIAL)),
    st.tuples(st.just("duplicate_rows"), frac, st.integers(1, 30)),
    st.tuples(st.just("reverse_rows"), frac, st.integers(2, 80)),
    st.tuples(st.just("units"), st.integers(0, 12), frac, st.integers(1, 400), st.sampled_from(FACTORS)),
    st.tuples(st.just("time_jump"), frac, st.sampled_from([-1e9, -5.0, -0.01, 0.0, 3.0, 600.0, 1e12])),
    st.tuples(st.just("number"), frac, st.sampled_from(SPECIAL + [b"1e308", b"-1e308", b"99999999999999999999"])),
    st.tuples(st.just("rows"), st.sampled_from([-1, 0, 1, 2])),
)
MUTATIONS = st.lists(OPS, min_size=1, max_size=3)


def _sep(lines: list[bytes]) -> bytes:
    sample = b"\n".join(lines[-5:])
    for sep in (b";", b",", b"\t"):
        if sep in sample and (sep != b"," or b";" not in sample):
            return sep
    return b" "


def _is_number(cell: bytes) -> bool:
    try:
        float(cell.strip().strip(b'"').replace(b",", b"."))
        return True
    except ValueError:
        return False


def _header_lines(lines: list[bytes], sep: bytes) -> int:
    for i, line in enumerate(lines[:60]):
        first = line.strip().split(sep)[0] if line.strip() else b""
        if first and _is_number(first):
            return i
    return min(1, len(lines))


def _fmt(x: float) -> bytes:
    return repr(float(x)).encode()


def mutate(data: bytes, ops) -> bytes:
    """Apply ``ops`` (see ``OPS``) in turn; operations on rows and cells act on the data rows below the header."""
    for op in ops:
        kind = op[0]
        if kind == "truncate":
            data = data[: int(op[1] * len(data))]
            continue
        if kind == "bytes":
            _, where, blob, insert = op
            i = int(where * len(data))
            data = data[:i] + blob + data[i + (0 if insert else len(blob)):]
            continue
        if kind == "number":
            hits = list(_NUMBER.finditer(data))
            if hits:
                m = hits[min(int(op[1] * len(hits)), len(hits) - 1)]
                data = data[: m.start()] + op[2] + data[m.end():]
            continue
        lines = data.split(b"\n")
        end = len(lines) - 1 if lines and lines[-1] == b"" else len(lines)
        sep = _sep(lines[:end] or [b""])
        h = _header_lines(lines[:end], sep)
        body = lines[h:end]
        if kind == "rows":
            keep = op[1]
            lines = [] if keep < 0 else lines[:h] + body[:keep] + [b""]
            data = b"\n".join(lines)
            continue
        if not body:
            continue
        n = len(body)
        if kind == "swap_columns":
            _, a, b, with_header = op  # with the header: the same data in another column order
            for k in range(0 if with_header else h, end):
                cells = lines[k].split(sep)
                if a < len(cells) and b < len(cells):
                    cells[a], cells[b] = cells[b], cells[a]
                    lines[k] = sep.join(cells)
        elif kind in ("special_run", "units"):
            col, start, length = op[1], int(op[2] * n), op[3]
            for k in range(h + start, min(h + start + length, end)):
                cells = lines[k].split(sep)
                if col < len(cells):
                    if kind == "special_run":
                        cells[col] = op[4]
                    elif _is_number(cells[col]):
                        cells[col] = _fmt(float(cells[col].strip().strip(b'"').replace(b",", b".")) * op[4])
                    lines[k] = sep.join(cells)
        elif kind == "duplicate_rows":
            i = h + int(op[1] * n)
            lines[i:i] = lines[i:min(i + op[2], end)]
        elif kind == "reverse_rows":
            i = h + int(op[1] * n)
            j = min(i + op[2], end)
            lines[i:j] = lines[i:j][::-1]
        elif kind == "time_jump":  # a clock that steps by op[2] (in the file's own time unit) from a row on
            i = h + int(op[1] * n)
            for k in range(i, end):
                cells = lines[k].split(sep)
                if cells and _is_number(cells[0]):
                    cells[0] = _fmt(float(cells[0].strip().strip(b'"').replace(b",", b".")) + op[2])
                    lines[k] = sep.join(cells)
        data = b"\n".join(lines)
    return data


# ---------------------------------------------------------------------------------------------------------------
# Seeds: small valid sources, built once
# ---------------------------------------------------------------------------------------------------------------


def _head(src: Path, dest: Path, n_lines: int) -> None:
    with open(src, "rb") as f:
        lines = [next(f) for _ in range(n_lines)]
    dest.write_bytes(b"".join(lines))


@pytest.fixture(scope="module")
def seeds(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("seeds")
    out = {}
    if not missing_files("oxford_step_counter", DATASETS):
        ox = root / "oxford"
        ox.mkdir()
        _head(DATASETS / "oxford_step_counter" / "validation" / "user1_armband_1506423438471.csv",
              ox / "user1_armband_1506423438471.csv", 1200)
        out["oxford"] = ox / "user1_armband_1506423438471.csv"
    if not missing_files("xio_foot_imu_loop_walk", DATASETS):
        xio = root / "xio"
        xio.mkdir()
        _head(DATASETS / "xio_foot_imu_loop_walk" / "short_walk.csv", xio / "short_walk.csv", 900)
        out["xio"] = xio / "short_walk.csv"
    if not missing_files("gaitmap_foot_imu_mocap", DATASETS):
        gm = root / "gaitmap"
        gm.mkdir()
        _head(DATASETS / "gaitmap_foot_imu_mocap" / "imu_sample.csv", gm / "imu_sample.csv", 700)
        _head(DATASETS / "gaitmap_foot_imu_mocap" / "imu_sample_healthy_stair_up.csv",
              gm / "imu_sample_healthy_stair_up.csv", 500)
        out["gaitmap"] = gm
    if not missing_files("humolire_phone_landmarks", DATASETS):
        hu = root / "humolire" / "seq"
        hu.mkdir(parents=True)
        src = DATASETS / "humolire_phone_landmarks" / "data" / "imus" / "1" / "square_2x"
        for name in ("accelerometer-calibrated.txt", "gyroscope-calibrated.txt"):
            _head(src / name, hu / name, 1500)
        for name in ("keypoints.json", "references.txt", "record.properties"):
            shutil.copy(src / name, hu / name)
        out["humolire"] = hu
    out["mobgap"] = DATASETS / "mobgap_lowerback_tvs_lab" / "lab" / "HA" / "001"
    out["sensorlogger"] = HAND / "sensorlogger_android"
    out["sensorlogger_ios"] = HAND / "sensorlogger_ios"
    out["phyphox"] = HAND / "phyphox_multi"
    out["phyphox_semicolon"] = HAND / "phyphox_rawdata_semicolon"
    out["sensorlogger_ios_clocks"] = HAND / "sensorlogger_ios_clocks"
    out["sensorlogger_ios_uncalibrated"] = HAND / "sensorlogger_ios_uncalibrated"
    out["phyphox_custom"] = HAND / "phyphox_custom"
    out["gpx"] = HAND / "track.gpx"
    # a recording for `pdr import gpx` (it adds gnss.csv to it) and one for `pdr validate`
    t = np.arange(0.0, 12.0, 0.01)
    rng = np.random.default_rng(3)
    imu = pd.DataFrame({"t_s": t, "acc_x_mps2": 0.3 * rng.standard_normal(len(t)), "acc_y_mps2": 0.3 * rng.standard_normal(len(t)),
                        "acc_z_mps2": 9.80665 + 2.0 * np.sin(2 * np.pi * 1.8 * t),
                        "gyr_x_radps": 0.05 * rng.standard_normal(len(t)), "gyr_y_radps": 0.05 * rng.standard_normal(len(t)),
                        "gyr_z_radps": 0.05 * rng.standard_normal(len(t)),
                        "mag_x_ut": 20 + rng.standard_normal(len(t)), "mag_y_ut": 5 + rng.standard_normal(len(t)),
                        "mag_z_ut": -40 + rng.standard_normal(len(t)), "baro_hpa": 1013.25 - 0.001 * t})
    meta = {"recording": {"id": "target", "placement": "waist", "start_unix_s": 1717236000.0}, "subject": {"height_m": 1.75}}
    out["gpx_target"] = save_recording(Recording(meta=meta, imu=imu), root / "gpx_target" / "target")
    tg = np.arange(0.0, 12.0, 1.0)
    gnss = pd.DataFrame({"t_s": tg, "lat_deg": 50.78 + 1e-5 * tg, "lon_deg": 7.59 + 0 * tg, "h_acc_m": 3.0 + 0 * tg})
    meta_v = {**meta, "recording": {"id": "valid", "placement": "pocket"},
              "geo": {"origin_lat_deg": 50.78, "origin_lon_deg": 7.59}}
    out["validate"] = save_recording(Recording(meta=meta_v, imu=imu, gnss=gnss,
                                               reference={"steps": pd.DataFrame({"t_s": [1.0, 1.5, 2.0]}),
                                                          "summary": {"n_steps": 3}}), root / "validate" / "valid")
    return out


@pytest.fixture(scope="module", autouse=True)
def _stats():
    yield
    if LONG and STATS:
        path = ROOT / "out" / "fuzz" / "stats.json"
        path.parent.mkdir(parents=True, exist_ok=True)
        total = sum(s["cases"] for s in STATS.values())
        path.write_text(json.dumps({"total_cases": total, "targets": STATS}, indent=2, sort_keys=True) + "\n")


# ---------------------------------------------------------------------------------------------------------------
# Running one case and checking the property
# ---------------------------------------------------------------------------------------------------------------


class CaseTimeout(BaseException):
    """Raised by SIGALRM inside a case (a BaseException, so that ``main`` cannot swallow it)."""


def _alarm(signum, frame):
    raise CaseTimeout()


def _listing(folder: Path) -> dict[str, bytes]:
    if not folder.exists():
        return {}
    return {p.relative_to(folder).as_posix(): (p.read_bytes() if p.is_file() else b"<dir>") for p in sorted(folder.rglob("*"))}


def run_cli(argv: list[str], case_dir: Path, target: str) -> tuple[int, str, str]:
    """``main(argv)`` with stdout/stderr captured, the process's temporary folder inside ``case_dir``, a time bound."""
    tmp = case_dir / "proc_tmp"
    tmp.mkdir()
    out, err = io.StringIO(), io.StringIO()
    old_tempdir, old_handler = tempfile.tempdir, signal.signal(signal.SIGALRM, _alarm)
    tempfile.tempdir = str(tmp)
    t0 = time.perf_counter()
    signal.setitimer(signal.ITIMER_REAL, CASE_TIMEOUT_S)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):  # main prints each warning to stderr
            rc = main([str(a) for a in argv])
    except CaseTimeout:
        raise AssertionError(f"{target}: a case ran longer than {CASE_TIMEOUT_S} s (a hang?)") from None
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old_handler)
        tempfile.tempdir = old_tempdir
    elapsed = time.perf_counter() - t0
    s = STATS.setdefault(target, {"cases": 0, "exit_0": 0, "exit_1": 0, "max_case_s": 0.0})
    s["cases"] += 1
    s[f"exit_{rc}"] = s.get(f"exit_{rc}", 0) + 1
    s["max_case_s"] = round(max(s["max_case_s"], elapsed), 3)
    leftovers = sorted(p.name for p in tmp.iterdir())
    assert not leftovers, f"temporary files left behind: {leftovers}"
    tmp.rmdir()
    return rc, out.getvalue(), err.getvalue()


def check_outcome(rc: int, out: str, err: str, *, dest: Path | None = None, before: dict | None = None,
                  recordings: bool = True) -> None:
    lines = [line for line in err.splitlines() if line.strip()]
    errors = [line for line in lines if line.startswith("error:")]
    stray = [line for line in lines if not line.startswith(("error:", "warning:"))]
    assert not any("internal failure" in line for line in errors), err  # an exception other than InputError escaped
    assert not stray, f"stderr lines that are neither error: nor warning: {stray}"
    assert rc in (0, 1), (rc, err)
    if rc == 1:
        assert len(errors) == 1, err
        if dest is not None:
            assert _listing(dest) == before, "a failed command changed its destination"
        return
    assert not errors, err
    if recordings:
        paths = [Path(p) for p in out.split()]
        assert paths
        for p in paths:
            rec = load_recording(p)  # a valid recording
            t = rec.imu["t_s"].to_numpy()
            assert np.isfinite(rec.imu.to_numpy()).all() and (np.diff(t) > 0).all()
        if dest is not None and before == {}:
            assert sorted(p.name for p in dest.iterdir()) == sorted(p.name for p in paths)
    if dest is not None:
        hidden = [p for p in dest.rglob(".*")] + [p for p in dest.parent.glob(".*")]
        assert not hidden, f"temporary output left behind: {hidden}"


def _copy_source(seed: Path, work: Path) -> Path:
    target = work / seed.name
    if seed.is_dir():
        shutil.copytree(seed, target)
    else:
        shutil.copy(seed, target)
    return target


def _mutated_file(source: Path, pick: int) -> Path:
    files = sorted(p for p in source.rglob("*") if p.is_file()) if source.is_dir() else [source]
    return files[pick % len(files)]


def fuzz_import(fmt: str, seed: Path, ops, pick: int, *, zip_it: bool = False, zip_ops=None,
                extra: tuple[str, ...] = (), target: str | None = None) -> None:
    with tempfile.TemporaryDirectory(prefix="pdr-fuzz-") as tmp:
        case = Path(tmp)
        (case / "src").mkdir()
        source = _copy_source(seed, case / "src")
        victim = _mutated_file(source, pick)
        victim.write_bytes(mutate(victim.read_bytes(), ops))
        if zip_it:
            archive = case / "src" / f"{source.name}.zip"
            with zipfile.ZipFile(archive, "w", zipfile.ZIP_DEFLATED) as zf:
                for p in sorted(source.rglob("*")):
                    zf.write(p, p.relative_to(source.parent).as_posix())
            if zip_ops:
                archive.write_bytes(mutate(archive.read_bytes(), zip_ops))
            source = archive
        dest = case / "out" / "recs"
        rc, out, err = run_cli(["import", fmt, source, dest, *extra], case, target or fmt)
        check_outcome(rc, out, err, dest=dest, before={})


# ---------------------------------------------------------------------------------------------------------------
# Targets
# ---------------------------------------------------------------------------------------------------------------


@pytest.mark.real_data("oxford_step_counter")
@FUZZ
@given(ops=MUTATIONS)
@example(ops=[("rows", 1)])  # one row: IndexError in the clock check (fixed in _common.steady_clock)
@example(ops=[("swap_columns", 0, 5, False)])  # time in the step-count column: np.repeat of 89 GiB (fixed in oxford)
def test_fuzz_oxford(seeds, ops):
    fuzz_import("oxford", seeds["oxford"], ops, 0)


@pytest.mark.real_data("xio_foot_imu_loop_walk")
@FUZZ
@given(ops=MUTATIONS)
@example(ops=[("time_jump", 0.5, 1e12)])  # written with 9 digits, t_s repeated: an invalid recording (fixed in save_recording)
@example(ops=[("number", 0.0, b"-1e308")])  # a clock over 1e308 s resampled at 1 Hz: "Maximum allowed size" (steady_clock)
def test_fuzz_xio(seeds, ops):
    fuzz_import("xio", seeds["xio"], ops, 0)


@pytest.mark.real_data("gaitmap_foot_imu_mocap")
@FUZZ
@given(ops=MUTATIONS, pick=st.integers(0, 1), rate=st.sampled_from([None, "204.8", "102.4"]))
@example(ops=[("special_run", 0, 0.0, 1, b"1,5")], pick=0, rate=None)  # an extra cell: flat column labels, TypeError
def test_fuzz_gaitmap(seeds, ops, pick, rate):
    fuzz_import("gaitmap", seeds["gaitmap"], ops, pick, extra=("--rate-hz", rate) if rate else ())


@pytest.mark.real_data("humolire_phone_landmarks")
@FUZZ
@given(ops=MUTATIONS, pick=st.integers(0, 4))
def test_fuzz_humolire(seeds, ops, pick):
    fuzz_import("humolire", seeds["humolire"], ops, pick)


BYTE_OPS = st.lists(st.one_of(
    st.tuples(st.just("truncate"), frac),
    st.tuples(st.just("bytes"), frac, st.binary(min_size=1, max_size=24), st.booleans()),
    st.tuples(st.just("rows"), st.sampled_from([-1, 0, 1])),
), min_size=1, max_size=3)


@pytest.mark.real_data("mobgap_lowerback_tvs_lab")
@FUZZ
@given(ops=BYTE_OPS, pick=st.integers(0, 2))
def test_fuzz_mobgap(seeds, ops, pick):
    fuzz_import("mobgap", seeds["mobgap"], ops, pick)


@FUZZ
@given(ops=MUTATIONS, pick=st.integers(0, 7), zip_it=st.booleans(), zip_ops=st.none() | BYTE_OPS)
@example(ops=[("truncate", 0.0)], pick=0, zip_it=True, zip_ops=[("bytes", 0.5, b"\x00", False)])  # zlib.error escaped
def test_fuzz_sensorlogger(seeds, ops, pick, zip_it, zip_ops):
    fuzz_import("sensorlogger", seeds["sensorlogger"], ops, pick, zip_it=zip_it, zip_ops=zip_ops)


@FUZZ
@given(ops=MUTATIONS, pick=st.integers(0, 3), zip_it=st.booleans())
def test_fuzz_sensorlogger_ios(seeds, ops, pick, zip_it):
    fuzz_import("sensorlogger", seeds["sensorlogger_ios"], ops, pick, zip_it=zip_it, target="sensorlogger_ios")


@FUZZ
@given(ops=MUTATIONS, pick=st.integers(0, 6), zip_it=st.booleans(), zip_ops=st.none() | BYTE_OPS)
@example(ops=[("bytes", 0.0, b"\x00", False)], pick=0, zip_it=True, zip_ops=[("bytes", 0.90625, b"\x00", False)])  # zlib
def test_fuzz_phyphox(seeds, ops, pick, zip_it, zip_ops):
    fuzz_import("phyphox", seeds["phyphox"], ops, pick, zip_it=zip_it, zip_ops=zip_ops)


@FUZZ
@given(ops=MUTATIONS, pick=st.integers(0, 4), zip_it=st.booleans(), which=st.sampled_from(["clocks", "uncalibrated"]))
def test_fuzz_sensorlogger_ios_quirks(seeds, ops, pick, zip_it, which):
    fuzz_import("sensorlogger", seeds[f"sensorlogger_ios_{which}"], ops, pick, zip_it=zip_it,
                target=f"sensorlogger_ios_{which}")


@FUZZ
@given(ops=MUTATIONS, pick=st.integers(0, 4), zip_it=st.booleans())
def test_fuzz_phyphox_custom(seeds, ops, pick, zip_it):
    fuzz_import("phyphox", seeds["phyphox_custom"], ops, pick, zip_it=zip_it, target="phyphox_custom")


@FUZZ
@given(ops=MUTATIONS, zip_it=st.booleans())
@example(ops=[("units", 0, 0.0, 150, -1.0)], zip_it=False)  # every time negated: an empty series escaped
def test_fuzz_phyphox_semicolon(seeds, ops, zip_it):
    fuzz_import("phyphox", seeds["phyphox_semicolon"], ops, 0, zip_it=zip_it, target="phyphox_semicolon")


@FUZZ
@given(ops=MUTATIONS, force=st.booleans())
@example(ops=[("number", 0.0, b"nan"), ("number", 0.0, b"nan")], force=False)  # encoding="UTFnan": LookupError
def test_fuzz_gpx(seeds, ops, force):
    with tempfile.TemporaryDirectory(prefix="pdr-fuzz-") as tmp:
        case = Path(tmp)
        track = case / "track.gpx"
        track.write_bytes(mutate(seeds["gpx"].read_bytes(), ops))
        rec = case / "recs" / "target"
        shutil.copytree(seeds["gpx_target"], rec)
        before = _listing(rec)
        rc, out, err = run_cli(["import", "gpx", track, rec, *(["--force"] if force else [])], case, "gpx")
        check_outcome(rc, out, err, dest=rec, before=before)
        if rc == 0:
            assert (rec / "gnss.csv").is_file()


@FUZZ
@given(ops=MUTATIONS, pick=st.integers(0, 5))
def test_fuzz_validate(seeds, ops, pick):
    with tempfile.TemporaryDirectory(prefix="pdr-fuzz-") as tmp:
        case = Path(tmp)
        rec = case / "valid"
        shutil.copytree(seeds["validate"], rec)
        victim = _mutated_file(rec, pick)
        victim.write_bytes(mutate(victim.read_bytes(), ops))
        before = _listing(rec)
        rc, out, err = run_cli(["validate", rec], case, "validate")
        check_outcome(rc, out, err, recordings=False)
        assert _listing(rec) == before  # validate never writes
        if rc == 0:
            loaded = load_recording(rec)  # what validate accepted is what the contract promises
            t = loaded.imu["t_s"].to_numpy()
            assert np.isfinite(loaded.imu.to_numpy()).all() and (np.diff(t) > 0).all()
            if loaded.gnss is not None:
                assert (np.diff(loaded.gnss["t_s"].to_numpy()) > 0).all()


@pytest.fixture(scope="module")
def thigh_camera(tmp_path_factory) -> dict[str, Path]:
    """A short simulated thigh-camera folder (1.5 s, every 4th frame kept) and templates to estimate it with."""
    from pdr.pipelines.gait_camera import fit_templates, write_thigh_camera
    from pdr.sim.thigh_camera import form_walk, simulate_thigh_camera, training_table

    root = tmp_path_factory.mktemp("thigh_camera")
    plan = [("walk", 7.0, 1.3), ("fast_walk", 7.0, 1.8), ("walk", 7.0, 1.3)]
    training_table([plan], subject_seed=1, walk_seeds=[21]).to_csv(root / "mocap.csv", index=False)
    with collect_warnings():
        fit_templates([root / "mocap.csv"], root / "templates.json")
    walk = form_walk([("walk", 4.0, 1.25)], subject_seed=1, walk_seed=5)
    sim = simulate_thigh_camera(walk, t_start_s=walk.t_walk_s[0], t_end_s=walk.t_walk_s[0] + 1.5, seed=5)
    return {"folder": write_thigh_camera(root / "walk", sim), "templates": root / "templates.json"}


@FUZZ
@given(ops=MUTATIONS, pick=st.integers(0, 3))
@example(ops=[("bytes", 1.0, b"\x00", False)], pick=1)  # text in frames.csv t_s: float conversion (fixed: _numeric)
@example(ops=[("number", 0.0, b"99999999999999999999")], pick=0)  # a TOML integer past float64 (ThighCameraModel)
def test_fuzz_gait_camera(thigh_camera, ops, pick):
    # the thigh-camera folder of `pdr gait-camera estimate` (an input beyond CONTRACT.md): camera.toml, frames,
    # observations, points
    with tempfile.TemporaryDirectory(prefix="pdr-fuzz-") as tmp:
        case = Path(tmp)
        folder = case / "walk"
        shutil.copytree(thigh_camera["folder"], folder, ignore=shutil.ignore_patterns("reference"))
        victim = sorted(p for p in folder.iterdir() if p.is_file())[pick]
        victim.write_bytes(mutate(victim.read_bytes(), ops))
        dest = case / "out" / "est"
        rc, out, err = run_cli(["gait-camera", "estimate", folder, "--templates", thigh_camera["templates"], "-o", dest],
                               case, "gait_camera")
        check_outcome(rc, out, err, recordings=False)
        assert (rc == 0) == dest.is_dir()
        if rc == 0:
            assert sorted(p.name for p in dest.iterdir()) == ["cycles.csv", "joints.csv", "states.csv", "summary.json"]
        hidden = list(case.rglob(".*"))
        assert not hidden, f"temporary output left behind: {hidden}"


def test_mutations_do_what_they_say():
    data = b"t,a,b\n0,1,2\n1,3,4\n2,5,6\n"
    assert mutate(data, [("swap_columns", 1, 2, True)]) == b"t,b,a\n0,2,1\n1,4,3\n2,6,5\n"
    assert mutate(data, [("swap_columns", 1, 2, False)]) == b"t,a,b\n0,2,1\n1,4,3\n2,6,5\n"
    assert mutate(data, [("reverse_rows", 0.0, 3)]) == b"t,a,b\n2,5,6\n1,3,4\n0,1,2\n"
    assert mutate(data, [("duplicate_rows", 0.4, 1)]) == b"t,a,b\n0,1,2\n1,3,4\n1,3,4\n2,5,6\n"
    assert mutate(data, [("special_run", 2, 0.0, 2, b"nan")]) == b"t,a,b\n0,1,nan\n1,3,nan\n2,5,6\n"
    assert mutate(data, [("units", 1, 0.7, 5, 1000.0)]) == b"t,a,b\n0,1,2\n1,3,4\n2,5000.0,6\n"
    assert mutate(data, [("time_jump", 0.5, 10.0)]) == b"t,a,b\n0,1,2\n11.0,3,4\n12.0,5,6\n"
    assert mutate(data, [("rows", 1)]) == b"t,a,b\n0,1,2\n"
    assert mutate(data, [("rows", -1)]) == b""
    assert mutate(data, [("truncate", 0.5)]) == data[:12]
