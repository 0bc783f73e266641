"""``pdr run`` end to end through ``main([...])``: outputs, determinism, atomicity, output-folder rules, bad input."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import pdr.pipelines.run as run_module
from pdr.cli.main import main
from pdr.io.recording import Recording, save_recording

from conftest import make_imu

ORIGIN = {"origin_lat_deg": 46.52, "origin_lon_deg": 6.57}


def _recording(tmp_path: Path, name: str = "walk", *, gnss: bool = True, broken_reference: bool = False) -> Path:
    meta = {"recording": {"id": name, "placement": "waist"}, "subject": {"height_m": 1.75}, "geo": dict(ORIGIN)}
    imu = make_imu(duration_s=20.0, rate_hz=100.0)
    g = None
    if gnss:
        t = np.arange(0.0, 20.0)
        g = pd.DataFrame({"t_s": t, "lat_deg": ORIGIN["origin_lat_deg"] + 1e-5 * t, "lon_deg": ORIGIN["origin_lon_deg"],
                          "h_acc_m": 3.0})
    path = save_recording(Recording(meta=meta, imu=imu, gnss=g), tmp_path / name)
    if broken_reference:  # run must never read reference/
        (path / "reference").mkdir()
        (path / "reference" / "steps.csv").write_text("nonsense\n1\n")
    return path


def _run(capsys, *argv: str) -> tuple[int, str, str]:
    code = main(["run", *argv])
    cap = capsys.readouterr()
    return code, cap.out, cap.err


def test_run_writes_every_output(tmp_path, capsys):
    rec = _recording(tmp_path, broken_reference=True)
    out = tmp_path / "out"
    code, stdout, _ = _run(capsys, str(rec), "-o", str(out), "--plot")
    assert code == 0
    assert len(stdout.strip().splitlines()) == 1 and "steps" in stdout and str(out) in stdout
    for name in ("steps.csv", "trajectory.csv", "summary.json", "run.json", "trajectory.geojson", "trajectory.tum",
                 "trajectory.gpx", "trajectory.png"):
        assert (out / name).is_file(), name
    steps = pd.read_csv(out / "steps.csv")
    assert list(steps.columns[:7]) == ["step_id", "t_s", "step_length_m", "step_length_std_m", "step_freq_hz", "heading_rad", "source"]
    traj = pd.read_csv(out / "trajectory.csv")
    assert list(traj.columns) == ["t_s", "e_m", "n_m", "heading_rad", "e_std_m", "n_std_m", "lat_deg", "lon_deg"]
    assert len(traj) == len(steps) + 1 and len(steps) > 5
    assert traj["t_s"].iloc[0] < steps["t_s"].iloc[0] and np.all(np.diff(traj["t_s"]) > 0)  # first row: the start
    np.testing.assert_allclose(traj["t_s"].iloc[1:], steps["t_s"])
    summary = json.loads((out / "summary.json").read_text())
    for key in ("distance_m", "n_steps", "duration_s", "step_model", "solver", "timings_s", "warnings", "one_line"):
        assert key in summary
    assert summary["n_steps"] == len(steps)
    assert summary["distance_m"] == pytest.approx(np.sum(np.hypot(np.diff(traj["e_m"]), np.diff(traj["n_m"]))), abs=0.01)
    assert summary["gnss"]["valid"] == 20 and summary["gnss"]["used"] > 10
    assert summary["solver"]["fusion"] == "graph" and summary["solver"]["iterations"] > 0
    prov = json.loads((out / "run.json").read_text())
    assert prov["pdr_version"] and set(prov["inputs"]) == {"meta.toml", "imu.csv", "gnss.csv"}
    assert all(len(h) == 64 for h in prov["inputs"].values())
    assert not list(tmp_path.glob(".out.*"))  # no temporary folder left behind


def test_run_is_deterministic(tmp_path, capsys):
    rec = _recording(tmp_path)
    for out in ("a", "b"):
        assert _run(capsys, str(rec), "-o", str(tmp_path / out))[0] == 0
    for name in ("trajectory.csv", "steps.csv", "run.json", "trajectory.geojson", "trajectory.tum", "trajectory.gpx"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes(), name


def test_no_gnss_and_mask_intervals(tmp_path, capsys):
    rec = _recording(tmp_path)
    assert _run(capsys, str(rec), "-o", str(tmp_path / "a"), "--no-gnss")[0] == 0
    assert json.loads((tmp_path / "a" / "summary.json").read_text())["gnss"]["fixes"] == 0
    cfg = tmp_path / "cfg.toml"
    cfg.write_text("[gnss]\nmask_intervals_s = [[5.0, 9.5], [15, 30]]\n")
    assert _run(capsys, str(rec), "-o", str(tmp_path / "b"), "--config", str(cfg), "--plot")[0] == 0
    summary = json.loads((tmp_path / "b" / "summary.json").read_text())
    assert summary["gnss"]["masked"] == 5 + 5  # t = 5..9 and 15..19
    assert 0 < summary["gnss"]["used"] <= 20 - 10  # masked fixes are never used
    prov = json.loads((tmp_path / "b" / "run.json").read_text())
    assert prov["config"]["gnss"]["mask_intervals_s"] == [[5.0, 9.5], [15.0, 30.0]] and len(prov["config_file_sha256"]) == 64


def test_error_mid_run_leaves_no_output(tmp_path, capsys, monkeypatch):
    rec = _recording(tmp_path)

    def boom(*args, **kwargs):
        raise RuntimeError("injected failure")

    monkeypatch.setattr(run_module, "write_tum", boom)
    code, stdout, err = _run(capsys, str(rec), "-o", str(tmp_path / "out"))
    assert code == 1 and stdout == "" and err.startswith("error:") and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists() and not list(tmp_path.glob(".out*"))


def test_failed_rerun_keeps_the_previous_output(tmp_path, capsys, monkeypatch):
    rec, out = _recording(tmp_path), tmp_path / "out"
    assert _run(capsys, str(rec), "-o", str(out))[0] == 0
    before = {p.name: p.read_bytes() for p in out.iterdir() if p.name != "summary.json"}
    monkeypatch.setattr(run_module, "write_geojson", lambda *a, **k: (_ for _ in ()).throw(RuntimeError("injected")))
    assert _run(capsys, str(rec), "-o", str(out), "--plot")[0] == 1
    assert {p.name: p.read_bytes() for p in out.iterdir() if p.name != "summary.json"} == before


def test_output_folder_rules(tmp_path, capsys):
    rec = _recording(tmp_path)
    other = tmp_path / "other"
    other.mkdir()
    (other / "thesis.txt").write_text("precious")
    code, _, err = _run(capsys, str(rec), "-o", str(other))
    assert code == 1 and "--force" in err and (other / "thesis.txt").read_text() == "precious"
    assert _run(capsys, str(rec), "-o", str(other), "--force")[0] == 0
    assert (other / "thesis.txt").read_text() == "precious" and (other / "run.json").is_file()  # only pdr's files
    code, _, err = _run(capsys, str(rec), "-o", str(other))  # an earlier pdr output too needs --force
    assert code == 1 and "--force" in err
    empty = tmp_path / "empty"
    empty.mkdir()
    assert _run(capsys, str(rec), "-o", str(empty))[0] == 0


def _unsorted(tmp_path: Path) -> Path:
    rec = _recording(tmp_path, "unsorted", gnss=False)
    lines = (rec / "imu.csv").read_text().splitlines()
    lines[10], lines[11] = lines[11], lines[10]
    (rec / "imu.csv").write_text("\n".join(lines) + "\n")
    return rec


def _bad_config(tmp_path: Path) -> tuple[Path, str]:
    cfg = tmp_path / "bad.toml"
    cfg.write_text("[gnss]\nmask_intervals_s = [[9.0, 1.0]]\n")
    return _recording(tmp_path, gnss=True), str(cfg)


def test_fusion_method_from_config(tmp_path, capsys):
    rec = _recording(tmp_path)
    cfg = tmp_path / "ekf.toml"
    cfg.write_text('[fusion]\nmethod = "ekf"\n')
    code, stdout, _ = _run(capsys, str(rec), "-o", str(tmp_path / "out"), "--config", str(cfg))
    assert code == 0 and "ekf fusion" in stdout
    assert json.loads((tmp_path / "out" / "run.json").read_text())["config"]["fusion"]["method"] == "ekf"


@pytest.mark.parametrize("case", ["missing", "unsorted", "bad_config", "missing_model", "gnss_typo", "fusion_method"])
def test_bad_input_exit_1_one_line_no_output(tmp_path, capsys, case):
    extra: list[str] = []
    if case == "missing":
        rec = tmp_path / "nope"
    elif case == "unsorted":
        rec = _unsorted(tmp_path)
    elif case == "bad_config":
        rec, cfg = _bad_config(tmp_path)
        extra = ["--config", cfg]
    elif case == "gnss_typo":
        rec = _recording(tmp_path)
        (tmp_path / "typo.toml").write_text("[gnss]\nmask_interval_s = []\n")
        extra = ["--config", str(tmp_path / "typo.toml")]
    elif case == "fusion_method":
        rec = _recording(tmp_path)
        (tmp_path / "f.toml").write_text('[fusion]\nmethod = "kalman"\n')
        extra = ["--config", str(tmp_path / "f.toml")]
    else:
        rec = _recording(tmp_path)
        extra = ["--model", str(tmp_path / "no_model.json")]
    code, stdout, err = _run(capsys, str(rec), "-o", str(tmp_path / "out"), *extra)
    assert code == 1 and stdout == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:") and "expected" in lines[0]
    assert not (tmp_path / "out").exists()


def test_simulated_walk_run_then_evaluate(tmp_path, capsys):
    """End to end on a simulated walk whose truth is known (loose bounds: the pieces have their own accuracy tests)."""
    from pdr.sim import simulate_to_disk

    root = Path(__file__).resolve().parents[1]
    rec = simulate_to_disk(root / "configs" / "sim" / "walk_short.toml", tmp_path / "sim", seed=3, force=False)
    assert main(["run", str(rec), "-o", str(tmp_path / "out"), "--plot"]) == 0
    assert main(["evaluate", str(tmp_path / "out"), str(rec)]) == 0
    metrics = json.loads(capsys.readouterr().out.split("\n", 1)[1])
    assert metrics["step_f1_tolerance_s"] == 0.25 and metrics["step_f1"] > 0.85
    assert abs(metrics["distance_error_pct"]) < 25.0
    assert metrics["alignment"] in ("none", "origin+heading") and metrics["ate_rmse_m"] < 20.0
    assert (tmp_path / "out" / "trajectory.gpx").is_file()  # the simulator writes a [geo] origin


def test_standing_still_gives_the_start_pose_only(tmp_path, capsys):
    imu = make_imu(duration_s=10.0)
    imu["acc_z_mps2"] = 9.80665 + 0.01 * np.random.default_rng(1).standard_normal(len(imu))
    rec = save_recording(Recording(meta={"recording": {"id": "still", "placement": "waist"}}, imu=imu), tmp_path / "still")
    code, stdout, err = _run(capsys, str(rec), "-o", str(tmp_path / "out"), "--plot")
    assert code == 0 and "0 steps" in stdout and re.search("warning: .*(no steps|no walking)", err)
    traj = pd.read_csv(tmp_path / "out" / "trajectory.csv")
    assert len(traj) == 1 and len(pd.read_csv(tmp_path / "out" / "steps.csv")) == 0
    assert not (tmp_path / "out" / "trajectory.gpx").exists()  # no geo origin
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["distance_m"] == 0.0
