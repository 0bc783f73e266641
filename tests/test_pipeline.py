"""The Python API: ``pdr.Pipeline`` (parameters as JSON data, a run that leaves them unchanged, the same results as
``pdr run``) and a light ``import pdr``."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import pdr
from pdr.config import load_config
from pdr.errors import InputError, collect_warnings
from pdr.fusion import EkfFusion
from pdr.io.recording import Recording, save_recording
from pdr.pipelines.run import run_recording
from pdr.report.writers import dumps_json

from conftest import make_imu

ORIGIN = {"origin_lat_deg": 46.52, "origin_lon_deg": 6.57}
CONFIG = {"steps": {"method": "peak"}, "gnss": {"mask_intervals_s": [[5.0, 8.0]]},
          "step_length": {"model": "weinberg"}, "fusion": {"method": "graph", "huber_k": 2.0}}


@pytest.fixture
def walk(tmp_path: Path) -> Path:
    meta = {"recording": {"id": "walk", "placement": "pocket"}, "subject": {"height_m": 1.75}, "geo": dict(ORIGIN)}
    t = np.arange(0.0, 20.0)
    gnss = pd.DataFrame({"t_s": t, "lat_deg": ORIGIN["origin_lat_deg"] + 1e-5 * t, "lon_deg": ORIGIN["origin_lon_deg"],
                         "h_acc_m": 3.0})
    return save_recording(Recording(meta=meta, imu=make_imu(duration_s=20.0, rate_hz=100.0), gnss=gnss), tmp_path / "walk")


def test_import_pdr_is_light_and_the_api_is_there():
    code = ("import sys, pdr; assert not [m for m in sys.modules if m.startswith(('pdr.', 'pandas', 'gtsam'))]; "
            "print(pdr.Pipeline.__module__, pdr.load_recording.__module__)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["pdr.pipelines.pipeline", "pdr.io.recording"]
    with pytest.raises(AttributeError, match="no attribute 'Pipelin'"):
        pdr.Pipelin  # noqa: B018


def test_python_api_gives_what_pdr_run_writes(walk, tmp_path):
    with collect_warnings():
        res = pdr.Pipeline().run(pdr.load_recording(walk))
        summary = run_recording(walk, tmp_path / "out")
    assert res.summary_["n_steps"] == summary["n_steps"] == len(res.steps_) > 10
    assert res.summary_["distance_m"] == summary["distance_m"]
    traj = pd.read_csv(tmp_path / "out" / "trajectory.csv")
    np.testing.assert_allclose(traj[["e_m", "n_m"]].to_numpy(), res.trajectory_[["e_m", "n_m"]].to_numpy(), atol=1e-4)  # mm
    steps = pd.read_csv(tmp_path / "out" / "steps.csv")
    np.testing.assert_allclose(steps["step_length_m"], res.steps_["step_length_m"], atol=1e-4)
    assert res.strides_ is None and list(res.bouts_["bout_id"]) == list(pd.read_csv(tmp_path / "out" / "bouts.csv")["bout_id"])
    run_json = json.loads((tmp_path / "out" / "run.json").read_text())
    assert run_json["pipeline"] == pdr.Pipeline.from_config(None).get_params()  # run.json records the parameters


def test_run_json_rebuilds_the_pipeline_exactly(walk, tmp_path):
    config = tmp_path / "config.toml"  # floats that 9 significant digits would change
    config.write_text("[fusion]\nhuber_k = 1.3450000000000002\nlateral_std_m = 0.021234567891234\n"
                      "[steps]\nmethod = \"peak\"\n")
    with collect_warnings():
        run_recording(walk, tmp_path / "out", config_path=config)
    params = json.loads((tmp_path / "out" / "run.json").read_text())["pipeline"]
    assert params["fusion"]["huber_k"] == 1.3450000000000002 and float(dumps_json(1.3450000000000002)) == 1.345
    built = pdr.Pipeline.from_config(load_config(config))
    assert pdr.Pipeline(**params).get_params() == built.get_params()


def test_params_are_json_and_rebuild_the_same_pipeline(walk):
    pipe = pdr.Pipeline.from_config(CONFIG)
    params = json.loads(json.dumps(pipe.get_params(), allow_nan=False))
    assert params["steps"] == {"method": "peak"} and params["fusion"]["huber_k"] == 2.0
    assert params["step_length"]["model"] == "weinberg" and params["step_length_choice"]["source"] == "configuration"
    rebuilt = pdr.Pipeline(**params)
    assert rebuilt.get_params() == pipe.get_params()
    rec = pdr.load_recording(walk)
    with collect_warnings():
        a, b = pipe.run(rec), rebuilt.run(rec)
    assert a.get_params() == params  # the run leaves the parameters as they were
    pd.testing.assert_frame_equal(a.trajectory_, b.trajectory_)
    assert a.summary_["step_model"]["choice"]["source"] == "configuration"
    assert a.config_["fusion"] == {"method": "graph", "params": pipe.fusion.get_params()}
    assert a.summary_["gnss"]["masked"] == 4  # the fixes at 5, 6, 7, 8 s


def test_stages_may_be_given_as_algorithms(walk):
    pipe = pdr.Pipeline(fusion=EkfFusion())
    assert pipe.get_params()["fusion"]["method"] == "ekf"
    with collect_warnings():
        res = pipe.run(pdr.load_recording(walk))
    assert res.summary_["solver"]["fusion"] == "ekf" and pipe.fusion.get_params() == EkfFusion().get_params()
    assert not hasattr(pipe.fusion, "trajectory_")  # the run works on a copy


def test_bad_pipeline_input_is_one_error(walk):
    with pytest.raises(InputError, match=r"\[steps\]: expected method one of wavelet, peak, found 'nope'"):
        pdr.Pipeline.from_config({"steps": {"method": "nope"}})
    with pytest.raises(InputError, match="unknown parameter"):
        pdr.Pipeline.from_config({"fusion": {"huber": 1.0}})
    with pytest.raises(InputError, match="gait_forms"):
        pdr.Pipeline.from_config({"gait_forms": {"form": "forms.json"}})
    with pytest.raises(InputError, match="expected a dict of sections"):
        pdr.Pipeline.from_config(["steps"])
    with pytest.raises(InputError, match="expected a recording"):
        pdr.Pipeline().run(walk)


def test_the_readme_python_example_runs(walk, tmp_path, monkeypatch):
    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text(encoding="utf-8")
    section = readme[readme.index("### Python API"):]
    code = section[section.index("```python\n") + len("```python\n"):section.index("```\n", section.index("```python"))]
    walk.rename(tmp_path / "sim_short")
    monkeypatch.chdir(tmp_path)
    scope: dict = {}
    with collect_warnings():
        exec(compile(code, "README.md", "exec"), scope)  # noqa: S102
    assert scope["res"].summary_["n_steps"] == len(scope["res"].steps_) > 10


def test_a_foot_ins_chain_is_scaled_under_the_ins_prior_and_leaves_the_step_model(tmp_path):
    # with shoe IMUs the graph's chain is the foot INS path: GNSS calibrates one scale of it under the foot INS's own
    # prior (2%), not the waist step model's (5%), and the step model reported is the one given, not scaled by it
    from pdr.sim import simulate_to_disk
    from pdr.step_length import body_model

    root = Path(__file__).resolve().parents[1]
    text = (root / "configs" / "sim" / "foot_imus.toml").read_text()
    config = tmp_path / "walk.toml"
    config.write_text(text.replace("duration_s = 70.0", "duration_s = 25.0").replace("duration_s = 60.0", "duration_s = 20.0"))
    rec = simulate_to_disk(config, tmp_path / "walk", seed=1)
    with collect_warnings():
        summary = run_recording(rec, tmp_path / "out", force=True)
    assert summary["n_strides"] > 0 and summary["step_scale"]["calibrated"]
    assert summary["step_scale"]["prior_std"] == pytest.approx(0.02)
    recording = pdr.load_recording(rec)
    given, _ = body_model(recording.subject, recording.placement)
    assert summary["step_model"]["params"]["k_scale"] == pytest.approx(given.k_scale)
