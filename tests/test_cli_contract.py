"""Every command of CONTRACT.md as a new user meets it, through ``main([...])``: outputs true to the contract,
``validate`` checking everything ``run`` reads, outputs never lost, plain errors, usage errors, ``--help``."""

from __future__ import annotations

import errno
import json
import shutil
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import pdr.pipelines.batch as batch_module
import pdr.report.writers as writers_module
from pdr.cli.main import build_parser, main
from pdr.io.recording import Recording, save_recording
from pdr.io.tomlio import dumps_toml, read_toml
from pdr.sim.camera import write_video
from pdr.step_length import RegressionStepLength
from pdr.step_length.io import save_model

from conftest import ROOT, make_imu

SCENARIO = ROOT / "configs" / "sim" / "walk_short.toml"


def _cli(argv, capsys) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    cap = capsys.readouterr()
    return code, cap.out, cap.err


def _one_error(code: int, err: str) -> str:
    lines = [line for line in err.splitlines() if not line.startswith("warning:")]
    assert code == 1 and len(lines) == 1 and lines[0].startswith("error:"), err
    assert "internal failure" not in lines[0]
    return lines[0]


@pytest.fixture(scope="module")
def walk(tmp_path_factory) -> Path:
    """The simulated two-minute walk (GNSS with outliers, gyroscope, magnetometer), made once."""
    rec = tmp_path_factory.mktemp("walk") / "rec"
    assert main(["simulate", str(SCENARIO), "-o", str(rec), "--seed", "1"]) == 0
    return rec


def _copy(rec: Path, dest: Path) -> Path:
    shutil.copytree(rec, dest)
    return dest


def _wrap_deg(a: np.ndarray) -> np.ndarray:
    return np.degrees(np.abs(np.angle(np.exp(1j * a))))


# ---------------------------------------------------------------------------------------------------------------
# Outputs true to the contract
# ---------------------------------------------------------------------------------------------------------------


def test_steps_heading_is_the_fused_east_north_heading(walk, tmp_path, capsys):
    assert _cli(["run", walk, "-o", tmp_path / "out"], capsys)[0] == 0
    steps = pd.read_csv(tmp_path / "out" / "steps.csv")
    traj = pd.read_csv(tmp_path / "out" / "trajectory.csv")
    np.testing.assert_allclose(steps["heading_rad"], traj["heading_rad"].iloc[1:], atol=1e-6)
    truth = pd.read_csv(walk / "reference" / "trajectory.csv")
    true_heading = np.interp(steps["t_s"], truth["t_s"], np.unwrap(truth["heading_rad"]))
    assert np.median(_wrap_deg(steps["heading_rad"].to_numpy() - true_heading)) < 10.0


def test_position_std_grows_from_the_start_prior_without_gnss(walk, tmp_path, capsys):
    rec = _copy(walk, tmp_path / "acc_only")
    (rec / "gnss.csv").unlink()
    imu = pd.read_csv(rec / "imu.csv")
    imu[["t_s", "acc_x_mps2", "acc_y_mps2", "acc_z_mps2"]].to_csv(rec / "imu.csv", index=False)  # an Oxford-like phone
    code, _, err = _cli(["run", rec, "-o", tmp_path / "out", "--plot"], capsys)
    assert code == 0
    assert "()" not in err  # every warning gives its reason
    traj = pd.read_csv(tmp_path / "out" / "trajectory.csv")
    std = np.hypot(traj["e_std_m"], traj["n_std_m"]).to_numpy()
    assert np.isfinite(std).all() and std[0] < 0.01 and std[-1] > 10 * std[1]
    walked = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(traj["e_m"]), np.diff(traj["n_m"])))])
    assert (traj[["e_std_m", "n_std_m"]].max(axis=1) <= walked + 0.01).all()  # never beyond the distance walked

    assert _cli(["run", walk, "-o", tmp_path / "no_gnss", "--no-gnss"], capsys)[0] == 0  # gyro + magnetometer
    traj = pd.read_csv(tmp_path / "no_gnss" / "trajectory.csv")
    assert traj[["e_std_m", "n_std_m"]].notna().all().all() and traj["e_std_m"].iloc[-1] > traj["e_std_m"].iloc[1]


def test_fixes_reporting_a_poor_accuracy_are_unusable(walk, tmp_path, capsys):
    rec = _copy(walk, tmp_path / "rec")
    gnss = pd.read_csv(rec / "gnss.csv")
    bad = np.arange(40, 60)
    gnss.loc[bad, "h_acc_m"] = 999.0
    gnss.loc[50, "lat_deg"] += 30.0 / 111_320.0  # a 30 m outlier among them
    gnss.to_csv(rec / "gnss.csv", index=False)
    code, _, err = _cli(["run", rec, "-o", tmp_path / "out"], capsys)
    assert code == 0 and "gnss_inaccurate" in err and "max_h_acc_m = 50 m" in err
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["gnss"]["inaccurate"] == len(bad)
    assert summary["gnss"]["used"] <= summary["gnss"]["valid"] - len(bad)
    (w,) = [w for w in summary["warnings"] if w["kind"] == "gnss_inaccurate"]
    assert (w["t_start_s"], w["t_end_s"]) == (float(gnss["t_s"][bad[0]]), float(gnss["t_s"][bad[-1]]))


def test_run_json_records_the_model_given_not_the_fitted_one(walk, tmp_path, capsys):
    model = tmp_path / "model.json"
    save_model(RegressionStepLength.population(a_m=0.114), model)
    code, _, err = _cli(["run", walk, "-o", tmp_path / "out", "--model", model], capsys)
    assert code == 0
    run = json.loads((tmp_path / "out" / "run.json").read_text())
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert run["config"]["step_length"]["params"]["a_m"] == pytest.approx(0.114)
    if summary["solver"]["converged"]:  # calibrated in the graph from GNSS
        assert summary["step_model"]["params"]["a_m"] != pytest.approx(0.114)
    else:  # the alternation did not settle: said so, and the model given is the one used
        assert "the step model given is kept" in err and summary["step_model"]["params"]["a_m"] == pytest.approx(0.114)


def test_evaluate_step_count_errors_are_both_signed(walk, tmp_path, capsys):
    assert _cli(["run", walk, "-o", tmp_path / "out"], capsys)[0] == 0
    ref = _copy(walk, tmp_path / "rec")
    steps = pd.read_csv(ref / "reference" / "steps.csv")
    steps.iloc[: len(steps) // 2].to_csv(ref / "reference" / "steps.csv", index=False)  # fewer reference steps
    summary = read_toml(ref / "reference" / "summary.toml")
    summary["summary"]["n_steps"] = len(steps) // 2
    (ref / "reference" / "summary.toml").write_text(dumps_toml(summary))
    code, out, _ = _cli(["evaluate", tmp_path / "out", ref], capsys)
    m = json.loads(out)
    assert code == 0 and m["step_count_error"] > 0
    assert m["step_count_error_pct"] == pytest.approx(100.0 * m["step_count_error"] / m["n_steps_ref"], rel=1e-6)
    assert "signed" in build_parser()._subparsers._group_actions[0].choices["evaluate"].description


def test_gpx_has_times_and_imports_back(walk, tmp_path, capsys):
    rec = _copy(walk, tmp_path / "rec")
    meta = read_toml(rec / "meta.toml")
    meta["recording"]["start_unix_s"] = 1_717_236_000.25  # 2024-06-01T10:00:00.25Z
    (rec / "meta.toml").write_text(dumps_toml(meta))
    assert _cli(["run", rec, "-o", tmp_path / "out"], capsys)[0] == 0
    ns = {"g": "http://www.topografix.com/GPX/1/1"}
    points = ET.parse(tmp_path / "out" / "trajectory.gpx").getroot().findall(".//g:trkpt", ns)
    assert points[0].find("g:time", ns).text.startswith("2024-06-01T10:00:")
    (rec / "gnss.csv").unlink()
    code, _, _ = _cli(["import", "gpx", tmp_path / "out" / "trajectory.gpx", rec], capsys)
    assert code == 0
    traj = pd.read_csv(tmp_path / "out" / "trajectory.csv")
    back = pd.read_csv(rec / "gnss.csv")
    np.testing.assert_allclose(back["t_s"], traj["t_s"], atol=1e-6)
    np.testing.assert_allclose(back["lat_deg"], traj["lat_deg"], atol=1e-8)


# ---------------------------------------------------------------------------------------------------------------
# validate checks everything run reads
# ---------------------------------------------------------------------------------------------------------------


def _camera_recording(tmp_path: Path) -> Path:
    rng = np.random.default_rng(0)
    frames = rng.integers(0, 255, (60, 24, 32), dtype=np.uint8)
    video = tmp_path / "src" / "video.avi"
    video.parent.mkdir()
    write_video(video, frames, 100.0)
    camera = {"camera": {"fps": 100.0, "focal_px": 40.0, "cx_px": 15.5, "cy_px": 11.5, "width_px": 32, "height_px": 24},
              "mount": {"segment": "shank_left", "distance_from_knee_m": 0.25}}
    rec = Recording(meta={"recording": {"id": "cam", "placement": "waist"}, "subject": {"height_m": 1.75}},
                    imu=make_imu(8.0), camera=camera, video_path=video,
                    frames=pd.DataFrame({"t_s": np.arange(60) / 100.0}))
    return save_recording(rec, tmp_path / "cam")


def _no_focal(rec: Path) -> str:
    cam = read_toml(rec / "camera.toml")
    del cam["camera"]["focal_px"]
    (rec / "camera.toml").write_text(dumps_toml(cam))
    return "focal_px"


def _half_video(rec: Path) -> str:
    data = (rec / "video.avi").read_bytes()
    (rec / "video.avi").write_bytes(data[: len(data) // 2])
    return "video.avi"


def _stub_video(rec: Path) -> str:
    (rec / "video.avi").write_bytes((rec / "video.avi").read_bytes()[:5000])
    return "video.avi"


def _reference_text(rec: Path) -> str:
    (rec / "reference").mkdir(exist_ok=True)
    (rec / "reference" / "steps.csv").write_text("t_s,foot\n1.0,left\nabout two,right\n")
    return "reference/steps.csv"


def _milliseconds(rec: Path) -> str:
    imu = pd.read_csv(rec / "imu.csv")
    imu["t_s"] *= 1000.0
    imu.to_csv(rec / "imu.csv", index=False)
    return "milliseconds"


def _height_in_cm(rec: Path) -> str:
    meta = read_toml(rec / "meta.toml")
    meta["subject"]["height_m"] = 175
    (rec / "meta.toml").write_text(dumps_toml(meta))
    return "in cm"


def _gnss_na(rec: Path) -> str:
    t = np.arange(0.0, 8.0)
    lines = ["t_s,e_m,n_m"] + [f"{x},{'N/A' if x == 3 else x},0" for x in t]
    (rec / "gnss.csv").write_text("\n".join(lines) + "\n")
    return "'N/A'"


@pytest.mark.parametrize("spoil", [_no_focal, _half_video, _stub_video, _reference_text, _milliseconds, _height_in_cm,
                                   _gnss_na])
def test_validate_refuses_what_run_refuses(tmp_path, capsys, spoil):
    rec = _camera_recording(tmp_path)
    assert _cli(["validate", rec], capsys)[0] == 0
    expected = spoil(rec)
    message = _one_error(*_cli(["validate", rec], capsys)[::2])
    assert expected in message
    if spoil is not _reference_text:  # run never reads reference/
        run_message = _one_error(*_cli(["run", rec, "-o", tmp_path / "out"], capsys)[::2])
        assert run_message == message and not (tmp_path / "out").exists()


# ---------------------------------------------------------------------------------------------------------------
# Outputs that are never lost
# ---------------------------------------------------------------------------------------------------------------


def test_existing_output_needs_force_and_keeps_the_users_files(walk, tmp_path, capsys):
    out = tmp_path / "out"
    assert _cli(["run", walk, "-o", out, "--plot"], capsys)[0] == 0
    (out / "notes.txt").write_text("mine")
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    message = _one_error(*_cli(["run", walk, "-o", out], capsys)[::2])
    assert "--force" in message and {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert _cli(["run", walk, "-o", out, "--force", "--no-gnss"], capsys)[0] == 0
    assert (out / "notes.txt").read_text() == "mine"
    assert not (out / "trajectory.png").exists()  # the earlier run's plot, a file pdr run writes, is gone
    assert json.loads((out / "run.json").read_text())["options"]["use_gnss"] is False
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # no temporary folder left


def test_interrupted_batch_still_says_what_finished(walk, tmp_path, capsys, monkeypatch):
    second = _copy(walk, tmp_path / "second")
    meta = read_toml(second / "meta.toml")
    meta["recording"]["id"] = "second"
    (second / "meta.toml").write_text(dumps_toml(meta))

    def one_then_interrupted(jobs, run_kwargs, workers, progress):
        yield batch_module.run_one(*jobs[0][:2], run_kwargs, jobs[0][2])
        raise KeyboardInterrupt

    monkeypatch.setattr(batch_module, "_run_local", one_then_interrupted)
    code, _, err = _cli(["batch", walk, second, "-o", tmp_path / "batch"], capsys)
    assert code == 130 and "interrupted" in err
    table = pd.read_csv(tmp_path / "batch" / "summary.csv")
    assert sorted(table["status"]) == ["ok", "pending"]


# ---------------------------------------------------------------------------------------------------------------
# Errors, usage errors and help
# ---------------------------------------------------------------------------------------------------------------


def test_unwritable_output_is_one_plain_line_naming_the_users_path(walk, tmp_path, capsys, monkeypatch):
    (tmp_path / "a_file").write_text("x")
    for argv in (["run", walk, "-o", tmp_path / "a_file" / "out"], ["steps", walk, "-o", tmp_path / "a_file" / "s.csv"],
                 ["simulate", SCENARIO, "-o", tmp_path / "a_file" / "rec"]):
        message = _one_error(*_cli(argv, capsys)[::2])
        assert f"{argv[3]}:" in message and "is a file, not a folder" in message and ".tmp" not in message

    def disk_full(path, *args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device", str(path))

    monkeypatch.setattr(writers_module, "write_csv", disk_full)
    message = _one_error(*_cli(["run", walk, "-o", tmp_path / "out"], capsys)[::2])
    assert message.startswith(f"error: {tmp_path / 'out'}:") and "No space left on device" in message
    assert ".tmp" not in message and not (tmp_path / "out").exists()


def test_evaluate_names_file_and_column_of_text_in_a_reference(walk, tmp_path, capsys):
    assert _cli(["run", walk, "-o", tmp_path / "out"], capsys)[0] == 0
    rec = _copy(walk, tmp_path / "rec")
    ref = pd.read_csv(rec / "reference" / "trajectory.csv").astype(object)
    ref.loc[5, "e_m"] = "n/a"
    ref.to_csv(rec / "reference" / "trajectory.csv", index=False)
    message = _one_error(*_cli(["evaluate", tmp_path / "out", rec], capsys)[::2])
    assert "reference/trajectory.csv" in message and "column e_m" in message


def test_usage_errors_exit_2(walk, tmp_path, capsys):
    for argv in (["batch", walk, "-o", tmp_path / "b", "--workers", "0"], ["import", "gaitmap", walk, tmp_path / "g",
                                                                          "--rate-hz", "-5"]):
        with pytest.raises(SystemExit) as exc:
            main([str(a) for a in argv])
        assert exc.value.code == 2
        assert "expected" in capsys.readouterr().err


def test_debug_after_the_command_and_paths_printed_once(tmp_path, capsys):
    (tmp_path / "rec").mkdir()
    message = _one_error(*_cli(["validate", tmp_path / "rec"], capsys)[::2])
    assert message.count(str(tmp_path / "rec" / "meta.toml")) == 1
    with pytest.raises(Exception, match="meta.toml"):
        main(["validate", str(tmp_path / "rec"), "--debug"])
    with pytest.raises(Exception, match="meta.toml"):
        main(["--debug", "validate", str(tmp_path / "rec")])


def _commands(parser, prefix=()):
    for action in parser._actions:
        if action.__class__.__name__ == "_SubParsersAction":
            for name, sub in action.choices.items():
                yield prefix + (name,), sub
                yield from _commands(sub, prefix + (name,))


def test_help_of_every_command_says_what_it_writes_with_an_example(capsys):
    commands = list(_commands(build_parser()))
    assert len(commands) > 15
    for names, sub in commands:
        with pytest.raises(SystemExit) as exc:
            main([*names, "--help"])
        text = capsys.readouterr().out
        assert exc.value.code == 0 and "writes:" in text and "example:\n  pdr " in text, names
        assert sub.description, names
        assert all(a.help for a in sub._actions), (names, [a.dest for a in sub._actions if not a.help])


# ---------------------------------------------------------------------------------------------------------------
# Warnings: one channel (the pdr logger), one warning: line each on the CLI
# ---------------------------------------------------------------------------------------------------------------


def _low_rate_recording(tmp_path: Path) -> Path:
    imu = make_imu(duration_s=20.0, rate_hz=100.0).iloc[::25].reset_index(drop=True)  # 4 Hz: below twice the cadence
    return save_recording(Recording(meta={"recording": {"id": "slow", "placement": "waist"}}, imu=imu), tmp_path / "rec")


def test_library_warnings_are_log_records_not_python_warnings(tmp_path, caplog):
    import logging
    import warnings

    from pdr.pipelines.steps import detect_steps
    from pdr.io.recording import load_recording

    rec = load_recording(_low_rate_recording(tmp_path))
    with warnings.catch_warnings(record=True) as python_warnings, caplog.at_level(logging.WARNING, logger="pdr"):
        warnings.simplefilter("always")
        detect_steps(rec, {})
    assert not python_warnings  # a notebook user or a test suite is not sprayed with UserWarnings
    records = [r for r in caplog.records if r.name == "pdr" and r.levelno == logging.WARNING]
    assert len(records) == 1 and "below twice the highest cadence" in records[0].getMessage()


def test_cli_prints_each_warning_once_even_with_logging_configured(tmp_path, capsys):
    import logging

    root = logging.getLogger()
    handler = logging.StreamHandler()  # an application that configured logging: the CLI's line is still the only one
    root.addHandler(handler)
    try:
        code, _, err = _cli(["validate", _low_rate_recording(tmp_path)], capsys)
    finally:
        root.removeHandler(handler)
    lines = [line for line in err.splitlines() if "highest cadence" in line]
    assert code == 0 and len(lines) == 1 and lines[0].startswith("warning: slow: sampling rate"), err
    assert logging.getLogger("pdr").handlers == [] and logging.getLogger("pdr").propagate  # restored after the command
