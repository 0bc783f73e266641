"""``pdr simulate``: a scenario file -> a canonical recording with its ``reference/`` truth.

Scenario keys (TOML; every table but ``[[segment]]`` and ``[route]`` is optional; unknown keys are errors):

``[simulation]`` ``id`` (recording id; default the file name), ``description``.
``[subject]`` ``height_m`` (default: drawn, 1.60-1.90 m), ``mass_kg``, ``cohort`` (``healthy``, ``older``, ``impaired``;
    default healthy; :data:`pdr.sim.people.COHORTS`). The person's leg proportion, step-length law and pelvis excursion
    are drawn per seed (:class:`pdr.sim.people.GaitUser`); ``meta.toml`` ``[subject]`` gets what a user would know:
    the height to the centimetre, the leg length and (waist IMU) the sensor height tape-measured to +-1 cm
    (:data:`MEASURE_STD_M`); no segment lengths.
``[geo]`` ``origin_lat_deg``, ``origin_lon_deg`` (default 46.5191, 6.5668), ``origin_alt_m`` (default 400).
``[route]`` ``waypoints_m`` ([[east, north], ...], the polyline walked), ``loop`` (repeat it, closed, as long as
    needed; default true), ``grades`` (slope per leg, rise/run; default flat), ``turn_smoothing_m`` (default 0.8).
``[[segment]]`` in order: ``duration_s``, ``speed_mps`` (0 = standing; > 2.2 runs), ``indoor`` (default false:
    no GNSS, magnetic disturbances near steel).
``[[imu]]`` one table per IMU; the first is ``imu.csv``, the others ``imu_<placement>.csv``: ``placement``
    (waist, pocket, hand, foot_left, foot_right, shank_left, shank_right), ``rate_hz`` and the error parameters
    of :class:`pdr.sim.sensors.ImuSpec` (a phone in the hand: ``in_pocket_s``, ``handling_s``, the phone taken out
    of and put back into the trouser pocket; the first IMU's handling goes to ``reference/handling.csv``).
    Default: one waist IMU at 100 Hz.
``[gnss]`` the parameters of :class:`pdr.sim.gnss.GnssSpec` (``enabled``, ``noise_m``, ``markov_sigma_m``,
    ``markov_tau_s``, ``outlier_fraction``, ``outlier_m``, ``outages_s`` = [[start, end], ...], ...).
``[magnetic]`` ``field_ut``, ``inclination_deg``, ``declination_deg``, ``steel_ut`` (dipole strength, µT at 1 m),
    ``steel_spacing_m`` (one steel source per this many metres of indoor path; 0 = none).
``[barometer]`` ``drift_hpa_per_h`` (1-sigma of the weather drift rate).
``[gait]`` ``cv_slow``, ``cv_fast`` (per-step step-length variability at 0.6 and 1.7 m/s; default: the cohort's,
:data:`pdr.sim.people.COHORTS`).
``[camera]`` a leg camera rendered by :mod:`pdr.sim.camera`: ``fps, focal_px, cx_px, cy_px, width_px, height_px,
    segment, distance_from_knee_m, texture`` (``gravel``/``brick``/``grass``/a path), optional ``t_start_s, t_end_s``;
    ``camera.toml`` gets the mount distance as a user measures it, to +-0.5 cm (:data:`MOUNT_STD_M`).
``[[fault]]`` / ``[faults]`` sensor faults injected into the recording (:mod:`pdr.sim.faults`): explicit ones
    (``kind``, ``t_start_s``, ``duration_s``, ...) and/or random ones (``fraction``, ``kinds``, ...); their truth goes
    to ``reference/faults.csv``.

Randomness: ``numpy.random.default_rng([seed, k])`` with a fixed ``k`` per component (person, steps, each IMU,
GNSS, steel), so a seed gives byte-identical files.
"""

from __future__ import annotations

import dataclasses
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pdr.errors import InputError, check_keys
from pdr.gait.mechanics import bout_table, step_energies, step_intervals
from pdr.geo import en_to_latlon
from pdr.io.recording import Recording, save_recording
from pdr.io.tomlio import read_toml
from pdr.sim.gait import WalkKinematics
from pdr.sim.people import LEG_SCALE_SD, Body, GaitUser, plan_walk
from pdr.sim.gnss import GnssSpec, simulate_gnss
from pdr.sim.route import Route
from pdr.sim.sensors import (
    ImuSpec, MagneticField, handling_intervals, place_steel, synthesize_imu, waist_sensor_above_hip_m,
)

SECTIONS = ("simulation", "subject", "geo", "route", "segment", "imu", "gnss", "magnetic", "barometer", "gait", "camera",
            "fault", "faults")
KEYS = {
    "simulation": {"id": str, "description": str},
    "subject": {"height_m": float, "mass_kg": float, "cohort": str},
    "geo": {"origin_lat_deg": float, "origin_lon_deg": float, "origin_alt_m": float},
    "route": {"waypoints_m": list, "loop": bool, "grades": list, "turn_smoothing_m": float},
    "segment": {"duration_s": float, "speed_mps": float, "indoor": bool, "label": str},
    "magnetic": {"field_ut": float, "inclination_deg": float, "declination_deg": float, "steel_ut": float,
                 "steel_spacing_m": float},
    "barometer": {"drift_hpa_per_h": float},
    "gait": {"cv_slow": float, "cv_fast": float},
}
TRAJECTORY_RATE_HZ = 10.0
MECHANICS_RATE_HZ = 100.0  # pelvis samples per second for the reference mechanics (reference/bouts.csv)
DEFAULT_ORIGIN = (46.5191, 6.5668, 400.0)
# fixed sub-stream keys of the seed
_RNG_PERSON, _RNG_STEPS, _RNG_GNSS, _RNG_STEEL, _RNG_BARO, _RNG_CAMERA, _RNG_MEASURE, _RNG_IMU = 1, 2, 3, 4, 5, 6, 7, 10
MEASURE_STD_M = 0.01  # a tape-measured body length or sensor height
MOUNT_STD_M = 0.005  # the leg camera's distance below the knee joint line, measured on the strapped camera


def _typed(section: str, table: dict, spec: dict[str, type]) -> dict:
    if not isinstance(table, dict):
        raise InputError(f"scenario [{section}]: expected a table, found {type(table).__name__}")
    for key, value in table.items():
        if key not in spec:
            raise InputError(f"scenario [{section}]: unknown key {key!r}; expected some of: {', '.join(spec)}")
        want = spec[key]
        ok = isinstance(value, (int, float)) and not isinstance(value, bool) if want is float else isinstance(value, want)
        if not ok:
            raise InputError(f"scenario [{section}] {key}: expected a {want.__name__}, found {value!r}")
    return table


def _dataclass_from(cls, section: str, table: dict):
    names = {f.name: f for f in dataclasses.fields(cls)}
    if not isinstance(table, dict):
        raise InputError(f"scenario [{section}]: expected a table, found {type(table).__name__}")
    check_keys(table, list(names), f"scenario [{section}]")
    kwargs = {}
    for key, value in table.items():
        default = names[key].default
        if isinstance(default, bool):
            if not isinstance(value, bool):
                raise InputError(f"scenario [{section}] {key}: expected true or false, found {value!r}")
        elif isinstance(default, (int, float)):
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise InputError(f"scenario [{section}] {key}: expected a number, found {value!r}")
            value = float(value)
        elif isinstance(default, tuple):
            if not isinstance(value, list) or not all(isinstance(v, list) and all(isinstance(x, (int, float)) for x in v) for v in value):
                raise InputError(f"scenario [{section}] {key}: expected a list of [start, end] pairs, found {value!r}")
            value = tuple(tuple(float(x) for x in v) for v in value)
        elif isinstance(default, str) and not isinstance(value, str):
            raise InputError(f"scenario [{section}] {key}: expected a string, found {value!r}")
        kwargs[key] = value
    return cls(**kwargs)


@dataclasses.dataclass
class Scenario:
    """A validated scenario (see the module docstring for the keys)."""

    id: str
    segments: list[dict[str, Any]]
    route: dict[str, Any]
    imus: list[ImuSpec]
    gnss: GnssSpec
    subject: dict[str, Any]
    geo: tuple[float, float, float]
    magnetic: dict[str, Any]
    barometer: dict[str, Any]
    gait: dict[str, Any]
    camera: dict[str, Any] | None
    description: str = ""

    @property
    def duration_s(self) -> float:
        return float(sum(s["duration_s"] for s in self.segments))


def parse_scenario(raw: dict[str, Any], default_id: str = "sim") -> Scenario:
    """Check a parsed scenario file and fill the defaults; every problem is an InputError naming the key."""
    if not isinstance(raw, dict):
        raise InputError("scenario: expected TOML tables, found something else")
    check_keys(raw, SECTIONS, "scenario", what="table")
    sim = _typed("simulation", raw.get("simulation", {}), KEYS["simulation"])
    segments = raw.get("segment")
    if not isinstance(segments, list) or not segments:
        raise InputError("scenario: expected at least one [[segment]] table (duration_s, speed_mps), found none")
    for i, seg in enumerate(segments):
        _typed(f"segment {i + 1}", seg, KEYS["segment"])
        if "duration_s" not in seg or "speed_mps" not in seg:
            raise InputError(f"scenario [[segment]] {i + 1}: expected duration_s and speed_mps, found {', '.join(seg) or 'nothing'}")
        if not 0 < seg["duration_s"] <= 86400 or not 0 <= seg["speed_mps"] <= 6.0:
            raise InputError(f"scenario [[segment]] {i + 1}: expected 0 < duration_s <= 86400 and 0 <= speed_mps <= 6, "
                             f"found {seg['duration_s']} s at {seg['speed_mps']} m/s")
    route = _typed("route", raw.get("route", {}), KEYS["route"])
    if "waypoints_m" not in route:
        raise InputError("scenario [route]: expected waypoints_m = [[east, north], ...], found none")
    imu_tables = raw.get("imu", [{}])
    if isinstance(imu_tables, dict):
        imu_tables = [imu_tables]
    imus = [_dataclass_from(ImuSpec, "imu", t) for t in imu_tables]
    places = [s.placement for s in imus]
    if len(set(places)) != len(places):
        raise InputError(f"scenario [[imu]]: expected each placement once, found {', '.join(places)}")
    gnss = _dataclass_from(GnssSpec, "gnss", raw.get("gnss", {}))
    subject = _typed("subject", raw.get("subject", {}), KEYS["subject"])
    geo = _typed("geo", raw.get("geo", {}), KEYS["geo"])
    origin = (float(geo.get("origin_lat_deg", DEFAULT_ORIGIN[0])), float(geo.get("origin_lon_deg", DEFAULT_ORIGIN[1])),
              float(geo.get("origin_alt_m", DEFAULT_ORIGIN[2])))
    if abs(origin[0]) > 85 or abs(origin[1]) > 180:
        raise InputError(f"scenario [geo]: expected a latitude within +-85 and a longitude within +-180, found {origin[:2]}")
    camera = raw.get("camera")
    if camera is not None and not isinstance(camera, dict):
        raise InputError("scenario [camera]: expected a table")
    return Scenario(id=str(sim.get("id", default_id)), description=str(sim.get("description", "")), segments=segments,
                    route=route, imus=imus, gnss=gnss, subject=subject, geo=origin,
                    magnetic=_typed("magnetic", raw.get("magnetic", {}), KEYS["magnetic"]),
                    barometer=_typed("barometer", raw.get("barometer", {}), KEYS["barometer"]),
                    gait=_typed("gait", raw.get("gait", {}), KEYS["gait"]), camera=camera)


def _intervals(segments: list[dict], flag: str) -> list[tuple[float, float]]:
    out, t = [], 0.0
    for seg in segments:
        if seg.get(flag, False):
            out.append((t, t + seg["duration_s"]))
        t += seg["duration_s"]
    return out


def _inside(t: np.ndarray, intervals) -> np.ndarray:
    m = np.zeros(len(t), bool)
    for a, b in intervals:
        m |= (t >= a) & (t < b)
    return m


def build_walk(sc: Scenario, seed: int) -> WalkKinematics:
    """The person, the route and the walk of a scenario (the body kinematics every sensor is made from)."""
    rng_person = np.random.default_rng([seed, _RNG_PERSON])
    height = float(sc.subject.get("height_m", np.clip(rng_person.normal(1.74, 0.08), 1.6, 1.9)))
    cv = {k: float(sc.gait[k]) for k in ("cv_slow", "cv_fast") if k in sc.gait}
    user = GaitUser.draw(rng_person, **cv, cohort=str(sc.subject.get("cohort", "healthy")))
    body = Body(height, leg_scale=float(np.clip(1.0 + LEG_SCALE_SD * rng_person.standard_normal(), 0.9, 1.1)))
    bouts = plan_walk([(float(s["duration_s"]), float(s["speed_mps"])) for s in sc.segments], user, body,
                      np.random.default_rng([seed, _RNG_STEPS]))
    if not bouts:
        raise InputError("scenario: expected walking segments long enough for 3 steps, found only standing")
    need = float(sum(b.target_length_m.sum() for b in bouts)) + 10.0
    route = Route(sc.route["waypoints_m"], grades=sc.route.get("grades"), loop=bool(sc.route.get("loop", True)),
                  turn_smoothing_m=float(sc.route.get("turn_smoothing_m", 0.8)), min_length_m=need)
    return WalkKinematics(body, user, bouts, route)


def true_bouts(kin: WalkKinematics, steps: pd.DataFrame, mass_kg: float | None) -> pd.DataFrame:
    """``reference/bouts.csv``: the columns of ``bouts.csv`` from the body itself: the pelvis centre's height and its
    forward speed along the path (the derivative of its path length), sampled at ``MECHANICS_RATE_HZ`` between the
    true contacts, with the definitions of :mod:`pdr.gait.mechanics`."""
    t, bout = steps["t_s"].to_numpy(float), steps["bout_id"].to_numpy(int)
    k, _ = step_intervals(t, bout)  # every true interval is one step
    t0, t1 = t[k - 1], t[k]
    grid = np.arange(np.floor(t0[0] * MECHANICS_RATE_HZ), np.ceil(t1[-1] * MECHANICS_RATE_HZ) + 1) / MECHANICS_RATE_HZ
    grid = grid[np.searchsorted(t1, grid, side="right") < len(t1)]
    pelvis = kin.pelvis_state(grid)
    z = kin.route.to_world(pelvis["s_m"], np.zeros(len(grid)), pelvis["h_m"])[:, 2]  # the height of pelvis_position_m
    v = np.gradient(pelvis["s_m"], grid)
    lengths = steps["step_length_m"].to_numpy(float)
    mech = pd.DataFrame({"bout_id": bout[k], "t_start_s": t0, "t_end_s": t1, "speed_mps": lengths[k] / (t1 - t0)})
    mech = pd.concat([mech, step_energies(grid, z, v, t0, t1, mass_kg)], axis=1)
    out = bout_table(steps, mech)
    out["mechanics_source"] = "simulator"
    return out


def _reference(kin: WalkKinematics, sc: Scenario, gnss_truth: pd.DataFrame | None) -> dict[str, Any]:
    steps = kin.true_steps()
    step_len = steps["step_length_m"].to_numpy()
    strides = kin.true_strides()
    t_traj = np.arange(int(np.floor(sc.duration_s * TRAJECTORY_RATE_HZ)) + 1) / TRAJECTORY_RATE_HZ
    ps = kin.pelvis_state(t_traj)
    pos = kin.pelvis_position_m(t_traj)
    traj = pd.DataFrame({"t_s": t_traj, "e_m": pos[:, 0], "n_m": pos[:, 1], "u_m": pos[:, 2],
                         "heading_rad": kin.route.heading_rad(ps["s_m"])})
    fine = np.arange(0.0, sc.duration_s, 0.02)
    pf = kin.pelvis_position_m(fine)
    seg_d = np.hypot(*np.diff(pf[:, :2], axis=0).T)
    bounds = np.cumsum([0.0] + [s["duration_s"] for s in sc.segments])
    seg_speed = [float(seg_d[(fine[:-1] >= a) & (fine[:-1] < b)].sum() / (b - a)) for a, b in zip(bounds[:-1], bounds[1:])]
    indoor = _inside(fine[:-1], _intervals(sc.segments, "indoor"))
    summary = {
        "distance_m": float(step_len.sum()),
        "path_length_m": float(seg_d.sum()),
        "n_steps": int(len(steps)),
        "n_strides": int(len(strides)),
        "duration_s": float(sc.duration_s),
        "walking_time_s": float(sum(b.t_s[-1] - b.t_s[0] for b in kin.bouts)),
        "mean_step_length_m": float(step_len.mean()),
        "segment_speed_mps": [round(v, 4) for v in seg_speed],
        "segment_target_speed_mps": [float(s["speed_mps"]) for s in sc.segments],
        "indoor_distance_m": float(seg_d[indoor].sum()),
        "height_m": float(kin.body.height_m),
        "step_length_coef": float(kin.user.length_coef),
        "step_length_exponent": float(kin.user.length_exponent),
        "cohort": kin.user.cohort,
        "leg_length_m": float(kin.body.leg_length_m),
        "pelvis_arc_gain": float(kin.user.arc_gain),
        "distance_definition": "sum of step_length_m: horizontal pelvis distance between consecutive foot contacts",
    }
    if gnss_truth is not None:
        summary["gnss_fixes"] = int(len(gnss_truth))
        summary["gnss_outliers"] = int(gnss_truth["outlier"].sum())
        ok = gnss_truth["outlier"] == 0
        summary["gnss_error_rms_m"] = float(np.sqrt(np.mean(gnss_truth.loc[ok, "error_m"] ** 2))) if ok.any() else float("nan")
    bouts = true_bouts(kin, steps, sc.subject.get("mass_kg"))
    return {"steps": steps, "strides": strides, "trajectory": traj, "bouts": bouts, "summary": summary}


def _render_camera(kin: WalkKinematics, cfg: dict[str, Any], seed: int, workdir: Path, duration_s: float):
    """The leg-camera hook: renders ``video.avi`` + ``frames.csv`` through :mod:`pdr.sim.camera`."""
    from pdr.sim import camera as cam

    cfg = dict(cfg)
    texture = cfg.pop("texture", "gravel")
    t0 = float(cfg.pop("t_start_s", 0.0))
    t1 = float(cfg.pop("t_end_s", min(duration_s, kin.duration_s)))
    mount = {k: cfg.pop(k) for k in cam.MOUNT_KEYS if k in cfg}
    cam_keys = {k: cfg.pop(k) for k in cam.CAMERA_KEYS if k in cfg}
    model = cam.CameraModel.from_toml({"camera": cam_keys, "mount": mount}, what="scenario [camera]")
    frames, frames_df = cam.render_leg_camera(kin, model, t0, t1, cam.load_texture(texture),
                                              seed=int(np.random.default_rng([seed, _RNG_CAMERA]).integers(2**31)), **cfg)
    video = workdir / "video.avi"
    cam.write_video(video, frames, model.fps)
    return model.to_toml(), video, frames_df


def simulate(scenario: dict[str, Any], seed: int, *, workdir: Path | None = None, default_id: str = "sim") -> Recording:
    """Simulate a recording (in memory) from a parsed scenario; deterministic for a seed.

    ``workdir`` holds the rendered video when the scenario has a ``[camera]`` (a new temporary folder if None).

    Example
    -------
    >>> rec = simulate({"route": {"waypoints_m": [[0, 0], [50, 0]]},
    ...                 "segment": [{"duration_s": 3, "speed_mps": 0}, {"duration_s": 10, "speed_mps": 1.3}]}, seed=1)
    >>> rec.placement, rec.reference["summary"]["n_steps"] > 10
    ('waist', True)
    """
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputError(f"simulate: expected a seed that is an integer >= 0, found {seed!r}")
    sc = parse_scenario(scenario, default_id)
    kin = build_walk(sc, seed)
    origin = sc.geo
    duration = sc.duration_s
    indoor = _intervals(sc.segments, "indoor")
    # magnetic field with steel along the indoor parts of the walk
    mcfg = sc.magnetic
    mag = MagneticField(field_ut=float(mcfg.get("field_ut", 48.0)), inclination_deg=float(mcfg.get("inclination_deg", 64.0)),
                        declination_deg=float(mcfg.get("declination_deg", 2.0)), steel_ut=float(mcfg.get("steel_ut", 25.0)))
    if indoor:
        t_in = np.concatenate([np.arange(a, b, 0.5) for a, b in indoor])
        src, mom = place_steel(kin.pelvis_position_m(t_in), float(mcfg.get("steel_spacing_m", 6.0)),
                               np.random.default_rng([seed, _RNG_STEEL]))
        mag = dataclasses.replace(mag, sources_enu=src, moments=mom)
    imus = {}
    for i, spec in enumerate(sc.imus):
        n = int(np.floor(duration * spec.rate_hz)) + 1
        t = np.arange(n) / spec.rate_hz
        imus[spec.placement] = synthesize_imu(kin, spec, t, np.random.default_rng([seed, _RNG_IMU + i]), mag=mag,
                                              origin_alt_m=origin[2],
                                              baro_drift_hpa_per_h=float(sc.barometer.get("drift_hpa_per_h", 0.3)))
    gnss = gnss_truth = None
    if sc.gnss.enabled:
        t_g = np.arange(int(np.ceil(duration * sc.gnss.rate_hz))) / sc.gnss.rate_hz
        avail = ~_inside(t_g, indoor + [tuple(iv) for iv in sc.gnss.outages_s])
        truth = kin.pelvis_position_m(t_g)
        fixes, gnss_truth = simulate_gnss(sc.gnss, t_g, truth, avail, np.random.default_rng([seed, _RNG_GNSS]))
        lat, lon = en_to_latlon(fixes["e_m"].to_numpy(), fixes["n_m"].to_numpy(), origin[:2])
        gnss = pd.DataFrame({"t_s": fixes["t_s"], "lat_deg": lat, "lon_deg": lon, "alt_m": origin[2] + fixes["u_m"],
                             "h_acc_m": fixes["h_acc_m"]})
    reference = _reference(kin, sc, gnss_truth)
    if sc.imus[0].in_pocket_s:
        reference["handling"] = handling_intervals(sc.imus[0], duration)
    if gnss_truth is not None:
        reference["gnss_truth"] = gnss_truth
    main = sc.imus[0].placement
    subject = kin.body.subject(sc.subject.get("mass_kg"))
    rng_measure = np.random.default_rng([seed, _RNG_MEASURE])
    subject["leg_length_m"] = round(kin.body.leg_length_m + MEASURE_STD_M * rng_measure.standard_normal(), 3)
    if main == "waist":  # the sensor rides on the lower back, above the hip joints
        sensor = kin.body.leg_length_m + waist_sensor_above_hip_m(kin.body)
        subject["sensor_height_m"] = round(sensor + MEASURE_STD_M * rng_measure.standard_normal(), 3)
    meta = {"recording": {"id": sc.id, "placement": main, "source": "pdr simulate", "seed": int(seed)},
            "subject": subject,
            "geo": {"origin_lat_deg": origin[0], "origin_lon_deg": origin[1]}}
    rec = Recording(meta=meta, imu=imus[main], extra_imus={k: v for k, v in imus.items() if k != main}, gnss=gnss,
                    reference=reference)
    if "fault" in scenario or "faults" in scenario:
        from pdr.sim.faults import inject_faults, scenario_faults

        rec, truth = inject_faults(rec, scenario_faults(scenario, duration, seed), seed)
        rec.reference["faults"] = truth
    if sc.camera is not None:
        workdir = Path(tempfile.mkdtemp(prefix="pdr-sim-")) if workdir is None else workdir
        rec.camera, rec.video_path, rec.frames = _render_camera(kin, sc.camera, seed, workdir, duration)
        mount = rec.camera["mount"]
        measured = mount["distance_from_knee_m"] + MOUNT_STD_M * rng_measure.standard_normal()
        mount["distance_from_knee_m"] = round(measured, 3)
    return rec


def simulate_to_disk(config: Path, out: Path, seed: int = 0, force: bool = False) -> Path:
    """Read a scenario file, simulate, write the recording atomically; return its path."""
    config = Path(config)
    raw = read_toml(config, what="scenario")
    with tempfile.TemporaryDirectory(prefix="pdr-sim-") as tmp:
        rec = simulate(raw, seed, workdir=Path(tmp), default_id=config.stem)
        return save_recording(rec, out, force=force)
