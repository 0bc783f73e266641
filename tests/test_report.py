"""Writers of the ``pdr run`` outputs: round trips of CSV, TUM, GeoJSON, GPX, JSON, and the PNG plot."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET

import numpy as np
import pandas as pd
import pytest

from pdr.errors import InputError
from pdr.geo import latlon_to_en
from pdr.report import (
    dumps_json,
    write_geojson,
    write_gpx,
    write_json,
    write_plot,
    write_steps_csv,
    write_strides_csv,
    write_trajectory_csv,
    write_tum,
    yaw_to_quaternion_xyzw,
)

ORIGIN = (48.8566, 2.3522)


def _traj(n: int = 12) -> pd.DataFrame:
    k = np.arange(n)
    heading = np.where(k < n // 2, 0.0, np.pi / 2)
    return pd.DataFrame({"t_s": 0.5 * k, "e_m": 0.7 * np.minimum(k, n // 2), "n_m": 0.7 * np.maximum(k - n // 2, 0),
                         "heading_rad": heading, "e_std_m": 0.05 * k, "n_std_m": 0.03 * k})


def test_trajectory_csv_round_trip_with_latlon(tmp_path):
    traj = _traj()
    write_trajectory_csv(tmp_path / "t.csv", traj, ORIGIN)
    back = pd.read_csv(tmp_path / "t.csv")
    assert list(back.columns) == ["t_s", "e_m", "n_m", "heading_rad", "e_std_m", "n_std_m", "lat_deg", "lon_deg"]
    np.testing.assert_allclose(back["e_m"], traj["e_m"], atol=1e-9)
    e, n = latlon_to_en(back["lat_deg"], back["lon_deg"], ORIGIN)
    np.testing.assert_allclose(e, traj["e_m"], atol=2e-3)  # 10 significant digits of a degree: ~1 mm
    np.testing.assert_allclose(n, traj["n_m"], atol=2e-3)


def test_trajectory_csv_without_origin_has_no_latlon(tmp_path):
    write_trajectory_csv(tmp_path / "t.csv", _traj(), None)
    assert "lat_deg" not in pd.read_csv(tmp_path / "t.csv").columns


def test_missing_column_is_input_error(tmp_path):
    with pytest.raises(InputError, match="heading_rad"):
        write_trajectory_csv(tmp_path / "t.csv", _traj().drop(columns="heading_rad"))
    assert not (tmp_path / "t.csv").exists()


def test_steps_and_strides_csv_contract_columns(tmp_path):
    steps = pd.DataFrame({"t_s": [1.0, 1.5], "step_length_m": [0.7, 0.72], "step_length_std_m": [0.05, 0.05],
                          "step_freq_hz": [1.9, 2.0], "heading_rad": [0.1, 0.2], "source": "accelerometer",
                          "step_id": [0, 1], "bout_id": [0, 0], "acc_var_m2ps4": [3.0, 3.1]})
    write_steps_csv(tmp_path / "s.csv", steps)
    assert list(pd.read_csv(tmp_path / "s.csv").columns) == [
        "step_id", "t_s", "step_length_m", "step_length_std_m", "step_freq_hz", "heading_rad", "source", "bout_id"]
    strides = pd.DataFrame({"t_start_s": [1.0], "t_end_s": [2.1], "foot": ["left"], "length_m": [1.4],
                            "length_std_m": [0.05], "source": ["foot_imu"]})
    write_strides_csv(tmp_path / "st.csv", strides)
    pd.testing.assert_frame_equal(pd.read_csv(tmp_path / "st.csv"), strides, check_dtype=False)


def _read_tum(path) -> np.ndarray:
    """Parse as evo's TUM reader does: '#' lines are comments, 8 space-separated numbers per row."""
    rows = [line.split() for line in path.read_text().splitlines() if line and not line.startswith("#")]
    assert all(len(r) == 8 for r in rows)
    return np.array(rows, dtype=float)


def test_tum_parseable_and_quaternion_encodes_yaw(tmp_path):
    traj = _traj()
    traj.loc[3, "heading_rad"] = -2.5
    write_tum(tmp_path / "t.tum", traj)
    m = _read_tum(tmp_path / "t.tum")
    assert m.shape == (len(traj), 8)
    np.testing.assert_allclose(m[:, 0], traj["t_s"], atol=1e-6)
    np.testing.assert_allclose(m[:, 1:3], traj[["e_m", "n_m"]], atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(m[:, 4:8], axis=1), 1.0, atol=1e-8)
    yaw = 2 * np.arctan2(m[:, 6], m[:, 7])
    np.testing.assert_allclose(np.angle(np.exp(1j * (yaw - traj["heading_rad"]))), 0.0, atol=1e-8)


def test_quaternion_of_quarter_turn():
    np.testing.assert_allclose(yaw_to_quaternion_xyzw(np.array([np.pi / 2])), [[0, 0, np.sqrt(0.5), np.sqrt(0.5)]], atol=1e-12)


@pytest.mark.parametrize("origin", [ORIGIN, None])
def test_geojson_structure(tmp_path, origin):
    traj = _traj()
    write_geojson(tmp_path / "t.geojson", traj, origin, name="walk")
    gj = json.loads((tmp_path / "t.geojson").read_text())
    assert gj["type"] == "FeatureCollection"
    (feature,) = gj["features"]
    assert feature["type"] == "Feature" and feature["geometry"]["type"] == "LineString"
    coords = np.array(feature["geometry"]["coordinates"])
    assert coords.shape == (len(traj), 2)
    assert len(feature["properties"]["t_s"]) == len(traj)
    if origin is None:
        np.testing.assert_allclose(coords, traj[["e_m", "n_m"]], atol=1e-4)
    else:  # RFC 7946: [lon, lat]
        e, n = latlon_to_en(coords[:, 1], coords[:, 0], origin)
        np.testing.assert_allclose(np.c_[e, n], traj[["e_m", "n_m"]], atol=1e-3)


def test_gpx_parseable(tmp_path):
    traj = _traj()
    write_gpx(tmp_path / "t.gpx", traj, ORIGIN, name="walk")
    root = ET.parse(tmp_path / "t.gpx").getroot()
    ns = {"g": "http://www.topografix.com/GPX/1/1"}
    assert root.tag == "{http://www.topografix.com/GPX/1/1}gpx" and root.get("version") == "1.1"
    pts = root.findall("g:trk/g:trkseg/g:trkpt", ns)
    assert len(pts) == len(traj)
    lat = np.array([float(p.get("lat")) for p in pts])
    lon = np.array([float(p.get("lon")) for p in pts])
    e, n = latlon_to_en(lat, lon, ORIGIN)
    np.testing.assert_allclose(np.c_[e, n], traj[["e_m", "n_m"]], atol=1e-3)


def test_json_deterministic_sorted_and_nan_to_null(tmp_path):
    obj = {"b": np.float64(1.0) / 3, "a": [np.int64(2), float("nan")], "c": {"z": np.bool_(True), "y": None}}
    text = dumps_json(obj)
    assert text == dumps_json(dict(reversed(list(obj.items()))))
    back = json.loads(text)
    assert list(back) == ["a", "b", "c"] and back["a"] == [2, None] and back["b"] == pytest.approx(1 / 3, rel=1e-8)
    write_json(tmp_path / "x.json", obj)
    assert (tmp_path / "x.json").read_text() == text
    with pytest.raises(TypeError):
        dumps_json({"x": object()})


def test_plot_writes_png_with_gnss_used_and_dropped(tmp_path):
    traj = _traj()
    gnss = pd.DataFrame({"t_s": [0.0, 1.0, 2.0], "e_m": [0.0, 1.5, np.nan], "n_m": [0.0, 0.1, np.nan], "used": [True, False, False]})
    write_plot(tmp_path / "t.png", traj, gnss=gnss, title="walk")
    data = (tmp_path / "t.png").read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 5000
    write_plot(tmp_path / "t2.png", traj, gnss=gnss, title="walk")
    assert (tmp_path / "t2.png").read_bytes() == data
