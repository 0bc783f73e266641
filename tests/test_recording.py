"""The canonical recording: load, validate, save; every bad case names what was expected and what was found."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from pdr.cli.main import main
from pdr.errors import InputError
from pdr.io.recording import load_recording, validate_gnss, validate_imu

from conftest import make_imu


def test_round_trip(small_recording):
    rec = load_recording(small_recording)
    assert rec.id == "small" and rec.placement == "waist"
    assert rec.subject["height_m"] == 1.75
    np.testing.assert_allclose(rec.imu["acc_z_mps2"].to_numpy(), make_imu()["acc_z_mps2"].to_numpy(), rtol=1e-8)
    assert abs(rec.sample_rate_hz - 100.0) < 1e-6


def test_validate_cli_ok(small_recording, capsys):
    assert main(["validate", str(small_recording)]) == 0
    assert capsys.readouterr().out.startswith("ok: small")


@pytest.mark.parametrize(
    "mutate, message",
    [
        (lambda d: d.drop(columns="acc_z_mps2"), "expected columns t_s, acc_x_mps2"),
        (lambda d: d.assign(acc_x_mps2=d["acc_x_mps2"].astype(object).where(d.index != 5, "abc")), "expected numbers in column acc_x_mps2"),
        (lambda d: d.assign(t_s=d["t_s"].where(d.index != 3, d["t_s"][2])), "repeated time"),
        (lambda d: d.assign(t_s=d["t_s"].where(d.index != 3, 0.0)), "unsorted"),
        (lambda d: d.assign(t_s=d["t_s"].where(d.index != 4, np.nan)), "expected finite t_s"),
        (lambda d: d.assign(acc_y_mps2=d["acc_y_mps2"].where((d.index < 10) | (d.index > 20), np.nan)), "NaN/inf"),
        (lambda d: d.assign(**{c: d[c] / 9.80665 for c in ["acc_x_mps2", "acc_y_mps2", "acc_z_mps2"]}), "look like g"),
        (lambda d: d.assign(gyr_x_radps=np.degrees(d["gyr_x_radps"] + 3 * np.sin(d["t_s"]))), "deg/s"),
        (lambda d: d.drop(columns="gyr_z_radps"), "expected all of gyr_x_radps"),
        (lambda d: d.assign(t_s=np.cumsum(np.where(np.arange(len(d)) % 2, 0.001, 0.02))), "varying wildly"),
        (lambda d: d.assign(baro_hpa=101325.0), "looks like Pa"),
        (lambda d: d.iloc[:1], "at least 2"),
    ],
)
def test_validate_imu_rejects(mutate, message):
    with pytest.raises(InputError, match=message):
        validate_imu(mutate(make_imu()))


def test_validate_gnss():
    ok = validate_gnss(pd.DataFrame({"t_s": [0.0, 1.0], "e_m": [0.0, 1.0], "n_m": [0.0, 0.5], "h_acc_m": [3.0, 4.0]}))
    assert list(ok.columns) == ["t_s", "e_m", "n_m", "h_acc_m"]
    with pytest.raises(InputError, match="expected columns t_s and lat_deg"):
        validate_gnss(pd.DataFrame({"t_s": [0.0], "x": [1.0]}))
    with pytest.raises(InputError, match="lat_deg in"):
        validate_gnss(pd.DataFrame({"t_s": [0.0], "lat_deg": [95.0], "lon_deg": [1.0]}))


def test_cli_errors_are_one_line(tmp_path, small_recording, capsys):
    assert main(["validate", str(tmp_path / "missing")]) == 1
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1
    (small_recording / "imu.csv").write_text("")
    assert main(["validate", str(small_recording)]) == 1
    assert "empty file" in capsys.readouterr().err
    (small_recording / "imu.csv").write_text("t_s,acc_x_mps2,acc_y_mps2,acc_z_mps2\n0,0,0,9.8\n0.01,0,0,")  # truncated
    assert main(["validate", str(small_recording)]) == 1


def test_usage_error_exit_2():
    with pytest.raises(SystemExit) as exc:
        main(["no-such-command"])
    assert exc.value.code == 2


def test_atomic_outputs_get_the_usual_modes(tmp_path):
    """Temporary files are private (0600); the renamed output must not be."""
    import os
    from pdr.io.atomic import atomic_dir, write_text

    mask = os.umask(0o022)
    os.umask(mask)
    write_text(tmp_path / "a.txt", "x")
    with atomic_dir(tmp_path / "out") as tmp:
        (tmp / "b.txt").write_text("y")
    assert (tmp_path / "a.txt").stat().st_mode & 0o777 == 0o666 & ~mask
    assert (tmp_path / "out").stat().st_mode & 0o777 == 0o777 & ~mask
