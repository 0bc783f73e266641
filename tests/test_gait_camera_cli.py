"""``pdr gait-camera``: simulate a thigh-camera folder, fit the forms, estimate and evaluate, from the command line;
bad input gets one error line and leaves nothing behind."""

from __future__ import annotations

import json
import shutil

import pandas as pd
import pytest

from pdr.cli.main import main

TRAINING = """
[subject]
seed = 1
""" + "".join(f"""
[[segment]]
form = "{f}"
duration_s = 7.0
speed_mps = {v}
""" for f, v in [("walk", 1.3), ("fast_walk", 1.8), ("walk", 1.3)])
WALK = """
[subject]
seed = 1
[[segment]]
form = "walk"
duration_s = 6.0
speed_mps = 1.25
[[segment]]
form = "fast_walk"
duration_s = 6.0
speed_mps = 1.85
"""


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    """A training walk, the templates fitted on it, a test walk of the same person and its estimate."""
    d = tmp_path_factory.mktemp("gait_camera")
    (d / "train.toml").write_text(TRAINING)
    (d / "walk.toml").write_text(WALK)
    assert main(["gait-camera", "simulate", str(d / "train.toml"), "-o", str(d / "train"), "--seed", "21"]) == 0
    assert main(["gait-camera", "simulate", str(d / "walk.toml"), "-o", str(d / "walk"), "--seed", "5"]) == 0
    assert main(["gait-camera", "fit", str(d / "train" / "reference" / "mocap.csv"), "-o", str(d / "templates.json")]) == 0
    assert main(["gait-camera", "estimate", str(d / "walk"), "--templates", str(d / "templates.json"), "-o", str(d / "est")]) == 0
    return d


def test_simulate_fit_estimate_evaluate(made, capsys):
    d = made
    for name in ("camera.toml", "frames.csv", "observations.csv", "points.csv", "reference/mocap.csv",
                 "reference/cycles.csv", "reference/segments.csv"):
        assert (d / "walk" / name).is_file(), name
    assert json.loads((d / "templates.json").read_text())["forms"] == ["walk", "fast_walk"]
    states = pd.read_csv(d / "est" / "states.csv")
    assert len(states) == len(pd.read_csv(d / "walk" / "frames.csv"))
    assert {"walk", "fast_walk"} <= set(states["form"].dropna())
    summary = json.loads((d / "est" / "summary.json").read_text())
    assert summary["n_frames"] == len(states) and summary["forms"] == ["walk", "fast_walk"]
    capsys.readouterr()
    assert main(["gait-camera", "evaluate", str(d / "est"), str(d / "walk")]) == 0
    metrics = json.loads(capsys.readouterr().out)
    assert metrics["joint_mean_m"] < 0.04  # the target: 5 cm
    assert metrics["form_steady_cycle"] >= 0.8 and metrics["n_switches"] == 1


def _fails(capsys, argv, expect):
    capsys.readouterr()
    assert main(argv) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and expect in err[0], err


def test_bad_input_gets_one_line_and_nothing_written(made, tmp_path, capsys):
    d = made
    tpl = str(d / "templates.json")
    # a forms file of another kind
    other = tmp_path / "forms.json"
    other.write_text(json.dumps({"format": "pdr-gait-forms"}))
    _fails(capsys, ["gait-camera", "estimate", str(d / "walk"), "--templates", str(other), "-o", str(tmp_path / "o1")],
           "expected a pdr-gait-camera-templates file")
    assert not (tmp_path / "o1").exists()
    # a folder without the camera description, observations with a point that is not on the board
    broken = tmp_path / "broken"
    shutil.copytree(d / "walk", broken)
    (broken / "camera.toml").unlink()
    _fails(capsys, ["gait-camera", "estimate", str(broken), "--templates", tpl, "-o", str(tmp_path / "o2")], "camera.toml")
    text = (d / "walk" / "camera.toml").read_text()
    (broken / "camera.toml").write_text(text.replace("fps = 100.0", 'fps = "fast"'))
    _fails(capsys, ["gait-camera", "estimate", str(broken), "--templates", tpl, "-o", str(tmp_path / "o2")], "numbers for fps")
    shutil.copy(d / "walk" / "camera.toml", broken / "camera.toml")
    obs = pd.read_csv(broken / "observations.csv")
    obs.loc[3, "point_id"] = 10**9
    obs.to_csv(broken / "observations.csv", index=False)
    _fails(capsys, ["gait-camera", "estimate", str(broken), "--templates", tpl, "-o", str(tmp_path / "o2")], "unknown")
    obs.loc[3, "point_id"] = obs.loc[2, "point_id"]
    obs["frame"] = obs["frame"].astype(float)
    obs.loc[4, "frame"] += 0.5
    obs.to_csv(broken / "observations.csv", index=False)
    _fails(capsys, ["gait-camera", "estimate", str(broken), "--templates", tpl, "-o", str(tmp_path / "o2")], "whole frame")
    obs.loc[4, "frame"] -= 0.5
    obs.loc[5, "u_px"] = float("nan")
    obs.to_csv(broken / "observations.csv", index=False)
    _fails(capsys, ["gait-camera", "estimate", str(broken), "--templates", tpl, "-o", str(tmp_path / "o2")], "NaN")
    (broken / "frames.csv").write_text("")
    _fails(capsys, ["gait-camera", "estimate", str(broken), "--templates", tpl, "-o", str(tmp_path / "o2")], "empty file")
    assert not (tmp_path / "o2").exists()
    # an existing output is kept without --force
    _fails(capsys, ["gait-camera", "estimate", str(d / "walk"), "--templates", tpl, "-o", str(d / "est")], "--force")
    # a config typo, a segment without a speed, a training table without the form column
    bad = tmp_path / "bad.toml"
    bad.write_text(WALK.replace("[subject]", "[subjekt]"))
    _fails(capsys, ["gait-camera", "simulate", str(bad), "-o", str(tmp_path / "s")], "subjekt")
    bad.write_text(WALK.replace("speed_mps = 1.85\n", ""))
    _fails(capsys, ["gait-camera", "simulate", str(bad), "-o", str(tmp_path / "s")], "speed_mps")
    assert not (tmp_path / "s").exists()
    mocap = pd.read_csv(d / "train" / "reference" / "mocap.csv").drop(columns="form")
    mocap.to_csv(tmp_path / "mocap.csv", index=False)
    _fails(capsys, ["gait-camera", "fit", str(tmp_path / "mocap.csv"), "-o", str(tmp_path / "t.json")], "form")
    assert not (tmp_path / "t.json").exists()


def test_a_folder_without_corners_in_view_gives_a_warning_and_empty_results(made, tmp_path, capsys):
    blind = tmp_path / "blind"
    shutil.copytree(made / "walk", blind)
    (blind / "observations.csv").write_text("frame,point_id,u_px,v_px\n")
    assert main(["gait-camera", "estimate", str(blind), "--templates", str(made / "templates.json"),
                 "-o", str(tmp_path / "out")]) == 0
    assert "warning:" in capsys.readouterr().err  # fewer than 4 known points in every frame
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["n_cycles"] == 0 and summary["form_frames"] == {} and summary["median_reprojection_error_px"] is None
    assert len(pd.read_csv(tmp_path / "out" / "cycles.csv")) == 0
    (blind / "frames.csv").write_text("t_s\n")  # no frame at all
    assert main(["gait-camera", "estimate", str(blind), "--templates", str(made / "templates.json"),
                 "-o", str(tmp_path / "out0")]) == 0
    assert "no frames" in capsys.readouterr().err
    assert json.loads((tmp_path / "out0" / "summary.json").read_text())["n_frames"] == 0

