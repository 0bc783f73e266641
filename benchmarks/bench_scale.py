"""Cost against recording length: ``pdr run`` end to end and per stage (``timings_s`` of ``summary.json``), peak memory,
and ``pdr validate`` / ``pdr import`` of the longest recording, on simulated walks of 1 minute to 10 hours.

Each command runs in a child process of its own (``python -m benchmarks.bench_scale --child ...``) that reports its
wall time, its CPU time (user + system: what the machine being shared with other work does not inflate) and its
peak resident memory (``VmHWM`` of /proc: the child's own peak; ``ru_maxrss`` of a child would carry this process's
resident memory over fork + exec). The walks are ``configs/sim/walk_30min_gps.toml`` repeated and cut to length,
simulated by ``pdr.sim`` (not tiled); they are cached under ``out/bench/cache/`` (by length and seed: delete the
folder to simulate them again after a change of the simulator), so a second run skips the simulation (the 10-hour
walk takes 3 to 7 minutes to simulate here and writes 0.3 GB). The cost measured does not depend on the walk's details.

Targets: 10 h end to end under 60 s with peak memory under 2 GB, cost linear in length; 10 h at
100 Hz imported, validated and run under 2 GB.

Run: ``.venv/bin/python -m benchmarks scale`` (1 min, 10 min, 1 h, 10 h); ``--quick``: up to 1 h.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
CACHE = ROOT / "out" / "bench" / "cache"
LENGTHS_S = {"1 min": 60.0, "10 min": 600.0, "1 h": 3600.0, "10 h": 36000.0}
QUICK = ("1 min", "10 min", "1 h")
SEED = 3
TARGET_10H_S = 60.0
TARGET_PEAK_MB = 2048.0
STAGES = ("load_s", "steps_s", "step_length_s", "strides_s", "gnss_s", "fusion_s", "write_s")


# ----------------------------------------------------------------------------------------------------------------
# the child: one command, measured from the inside
# ----------------------------------------------------------------------------------------------------------------

def _child(argv: list[str]) -> int:
    t0 = time.perf_counter()
    if argv[0] == "simulate":
        from benchmarks.bench_batch import scenario_of_length
        from pdr.io.recording import save_recording
        from pdr.sim import simulate

        length_s, out = float(argv[1]), Path(argv[2])
        raw = scenario_of_length(length_s)
        raw["simulation"]["id"] = out.name
        save_recording(simulate(raw, SEED), out, force=True)
        code = 0
    else:
        from pdr.cli.main import main

        code = main(argv)
    import resource

    usage = resource.getrusage(resource.RUSAGE_SELF)
    hwm_kb = next(float(line.split()[1]) for line in open("/proc/self/status") if line.startswith("VmHWM"))
    print(json.dumps({"code": code, "wall_s": time.perf_counter() - t0, "cpu_s": usage.ru_utime + usage.ru_stime,
                      "peak_mb": hwm_kb / 1024.0}), file=sys.stderr)
    return code


def _measure(args: list[str]) -> dict:
    """Run ``args`` in a child process; its own wall time (imports included), CPU time and peak memory."""
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "benchmarks.bench_scale", "--child", *args], cwd=ROOT,
                          capture_output=True, text=True)
    lines = [line for line in proc.stderr.splitlines() if line.startswith("{")]
    if proc.returncode != 0 or not lines:
        raise RuntimeError(f"bench_scale: {' '.join(args)} failed: {proc.stderr.strip()[-500:]}")
    result = json.loads(lines[-1])
    result["process_wall_s"] = time.perf_counter() - t0  # with the interpreter's start and the imports
    return result


# ----------------------------------------------------------------------------------------------------------------
# the recordings
# ----------------------------------------------------------------------------------------------------------------

def recording_of_length(length_s: float) -> tuple[Path, float | None]:
    """The cached simulated walk of ``length_s`` (simulated now when missing); its simulation time if simulated now."""
    rec = CACHE / f"scale_{int(length_s)}s_seed{SEED}"
    if (rec / "meta.toml").is_file() and (rec / "imu.csv").is_file():
        return rec, None
    CACHE.mkdir(parents=True, exist_ok=True)
    r = _measure(["simulate", str(length_s), str(rec)])
    return rec, r["wall_s"]


def write_phyphox_export(rec: Path, dest: Path, chunk_rows: int = 500_000) -> Path:
    """The recording's IMU and GNSS as a phyphox CSV export (one file per sensor), written in chunks."""
    dest.mkdir(parents=True, exist_ok=True)
    files = {"Accelerometer.csv": ("acc_{}_mps2", "m/s^2"), "Gyroscope.csv": ("gyr_{}_radps", "rad/s"),
             "Magnetometer.csv": ("mag_{}_ut", "µT")}
    handles = {name: open(dest / name, "w", encoding="utf-8") for name in files}
    try:
        for name, (_, unit) in files.items():
            handles[name].write(",".join(['"Time (s)"'] + [f'"{a.upper()} ({unit})"' for a in "xyz"]) + "\n")
        for part in pd.read_csv(rec / "imu.csv", chunksize=chunk_rows):
            for name, (col, _) in files.items():
                cols = [col.format(a) for a in "xyz"]
                if all(c in part.columns for c in cols):
                    block = np.column_stack([part["t_s"].to_numpy(float)] + [part[c].to_numpy(float) for c in cols])
                    np.savetxt(handles[name], block, fmt="%.9E", delimiter=",")
    finally:
        for h in handles.values():
            h.close()
    for name, (col, _) in files.items():  # a sensor the recording does not have: no file
        if (dest / name).stat().st_size < 100:
            (dest / name).unlink()
    gnss = rec / "gnss.csv"
    if gnss.is_file():
        g = pd.read_csv(gnss)
        pd.DataFrame({"Time (s)": g["t_s"], "Latitude (°)": g["lat_deg"], "Longitude (°)": g["lon_deg"],
                      "Height (m)": g["alt_m"], "Horizontal Accuracy (m)": g["h_acc_m"]}).to_csv(
            dest / "Location.csv", index=False, float_format="%.9E", quoting=1)
    return dest


# ----------------------------------------------------------------------------------------------------------------
# the table
# ----------------------------------------------------------------------------------------------------------------

def _row(case: str, metric: str, ours: float, unit: str, target: str = "", anchor: str = "") -> dict:
    return {"area": "scale", "case": case, "metric": metric, "ours": round(float(ours), 3), "unit": unit,
            "target": target, "anchor": anchor}


def _load() -> str:
    return " ".join(f"{x:.1f}" for x in os.getloadavg())


def run(quick: bool = False) -> list[dict]:
    names = QUICK if quick else tuple(LENGTHS_S)
    rows: list[dict] = []
    per_hour: dict[str, float] = {}
    cpu_per_hour: dict[str, float] = {}
    longest = names[-1]
    recs: dict[str, Path] = {}
    with tempfile.TemporaryDirectory(prefix="bench_scale_") as tmp:
        tmp_path = Path(tmp)
        for name in names:
            length_s = LENGTHS_S[name]
            rec, sim_s = recording_of_length(length_s)
            recs[name] = rec
            before = _load()
            r = _measure(["run", str(rec), "-o", str(tmp_path / f"out_{int(length_s)}"), "--force"])
            summary = json.loads((tmp_path / f"out_{int(length_s)}" / "summary.json").read_text())
            case = f"simulated walk, {name} ({summary['n_steps']:,} steps, {summary['gnss']['used']:,} GNSS fixes used)"
            hours = length_s / 3600.0
            load = f"load average before {before}, after {_load()}"
            is_10h = length_s == 36000.0
            rows.append(_row(case, "pdr run end to end (wall, interpreter start included)", r["process_wall_s"], "s",
                             f"< {TARGET_10H_S:g}" if is_10h else "", load))
            rows.append(_row(case, "pdr run CPU time (user + system)", r["cpu_s"], "s", "",
                             "not inflated by other processes on the machine"))
            rows.append(_row(case, "pdr run peak memory (VmHWM)", r["peak_mb"], "MB",
                             f"< {TARGET_PEAK_MB:g}" if is_10h else ""))
            per_hour[name] = r["process_wall_s"] / hours
            cpu_per_hour[name] = r["cpu_s"] / hours
            rows.append(_row(case, "wall per recording hour", per_hour[name], "s/h", "", "linear cost: constant"))
            rows.append(_row(case, "CPU per recording hour", cpu_per_hour[name], "s/h", "", "linear cost: constant"))
            timings = summary["timings_s"]
            for stage in [s for s in STAGES if s in timings] + sorted(set(timings) - set(STAGES) - {"total_s"}):
                rows.append(_row(case, f"stage {stage[:-2]} (wall, timings_s)", timings[stage], "s"))
            if sim_s is not None:
                rows.append(_row(case, "pdr.sim simulation + save (not part of run)", sim_s, "s"))
        if "1 h" in per_hour and longest != "1 h":
            rows.append(_row(f"{longest} against 1 h", "CPU per hour ratio (linearity)",
                             cpu_per_hour[longest] / cpu_per_hour["1 h"], "x", "about 1",
                             "target: cost linear in length"))
        # import + validate of the longest recording
        rec = recs[longest]
        case = f"simulated walk, {longest} at 100 Hz"
        r = _measure(["validate", str(rec)])
        rows.append(_row(case, "pdr validate (wall, interpreter start included)", r["process_wall_s"], "s"))
        rows.append(_row(case, "pdr validate peak memory (VmHWM)", r["peak_mb"], "MB", f"< {TARGET_PEAK_MB:g}",
                         "target: import, validate, run of 10 h at 100 Hz under 2 GB"))
        export = write_phyphox_export(rec, tmp_path / "phyphox_export")
        size_mb = sum(p.stat().st_size for p in export.iterdir()) / 1e6
        r = _measure(["import", "phyphox", str(export), str(tmp_path / "imported")])
        rows.append(_row(case, f"pdr import phyphox ({size_mb:.0f} MB of CSV; wall, interpreter start included)",
                         r["process_wall_s"], "s"))
        rows.append(_row(case, "pdr import phyphox peak memory (VmHWM)", r["peak_mb"], "MB", f"< {TARGET_PEAK_MB:g}",
                         "target: import, validate, run of 10 h at 100 Hz under 2 GB"))
    return rows


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        sys.exit(_child(sys.argv[2:]))
    print(pd.DataFrame(run(quick="--quick" in sys.argv)).to_string(index=False))
