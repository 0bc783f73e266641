"""``pdr batch``: local pool and Dask engines, a bad recording, resume, a dead worker, a scheduler that does not answer."""

from __future__ import annotations

import json
import multiprocessing
import os
import shutil
import socket
import threading
import time
from pathlib import Path

import pandas as pd
import pytest

from pdr.cli.main import main
from pdr.errors import InputError
from pdr.io.recording import save_recording
from pdr.io.tomlio import read_toml
from pdr.pipelines import batch
from pdr.sim import simulate

ROOT = Path(__file__).resolve().parents[1]
N_WALKS = 3


def _short_walk(seed: int) -> dict:
    """walk_short.toml cut to 40 s (stand, walk, turn): about 60 steps, a fraction of a second to run."""
    raw = read_toml(ROOT / "configs" / "sim" / "walk_short.toml", what="scenario")
    raw["simulation"]["id"] = f"walk_{seed}"
    raw["segment"] = [{"duration_s": 3.0, "speed_mps": 0.0}, {"duration_s": 34.0, "speed_mps": 1.3},
                      {"duration_s": 3.0, "speed_mps": 0.0}]
    return raw


@pytest.fixture(scope="module")
def recordings(tmp_path_factory) -> list[Path]:
    """Three short simulated walks and one broken recording (imu.csv without most of its columns)."""
    base = tmp_path_factory.mktemp("batch_recs")
    recs = [save_recording(simulate(_short_walk(seed), seed), base / f"walk_{seed}") for seed in range(N_WALKS)]
    broken = base / "broken"
    broken.mkdir()
    (broken / "meta.toml").write_text('[recording]\nid = "broken"\nplacement = "waist"\n')
    (broken / "imu.csv").write_text("t_s,acc_x_mps2\n0.0,1.0\n0.01,1.0\n")
    return recs + [broken]


@pytest.fixture(scope="module")
def local_out(recordings, tmp_path_factory) -> tuple[Path, int, str]:
    """One CLI run of the local pool (2 workers) over the three walks and the broken recording."""
    out = tmp_path_factory.mktemp("batch_local") / "out"
    import contextlib
    import io

    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        code = main(["batch", *map(str, recordings), "-o", str(out), "--workers", "2"])
    return out, code, err.getvalue()


def _comparable(out_dir: Path) -> dict[str, object]:
    """Every output file's bytes; summary.json without its timings and the output path in its one-line summary."""
    files: dict[str, object] = {}
    for path in sorted(p for p in out_dir.rglob("*") if p.is_file()):
        rel = path.relative_to(out_dir).as_posix()
        if path.name == "summary.json":
            summary = json.loads(path.read_text())
            summary.pop("timings_s")
            summary["one_line"] = summary["one_line"].rsplit(" -> ", 1)[0]
            summary["solver"] = {k: v for k, v in summary["solver"].items() if not k.endswith("time_s")}
            files[rel] = summary
        else:
            files[rel] = path.read_bytes()
    return files


def test_local_pool_bad_recording_fails_its_row_only(local_out, recordings):
    out, code, err = local_out
    assert code == 1
    error_lines = [line for line in err.splitlines() if line.startswith("error:")]
    assert len(error_lines) == 1
    assert "3 ok, 0 skipped (complete), 1 failed" in error_lines[0] and "broken" in error_lines[0]
    table = pd.read_csv(out / "summary.csv", keep_default_na=False)
    assert list(table.columns) == batch.SUMMARY_COLUMNS
    assert list(table["recording_id"]) == ["broken", "walk_0", "walk_1", "walk_2"]  # sorted by id, not by finish
    rows = table.set_index("recording_id")
    assert rows.loc["broken", "status"] == "failed"
    assert "expected columns" in rows.loc["broken", "error"]
    assert rows.loc["broken", "distance_m"] == ""
    for seed in range(N_WALKS):
        row = rows.loc[f"walk_{seed}"]
        assert row["status"] == "ok" and row["error"] == ""
        summary = json.loads((out / f"walk_{seed}" / "summary.json").read_text())
        assert float(row["n_steps"]) == summary["n_steps"] > 30
        assert float(row["distance_m"]) == pytest.approx(summary["distance_m"], rel=1e-8)
        assert 30.0 < summary["distance_m"] < 70.0  # 34 s at 1.3 m/s
        assert float(row["duration_s"]) == pytest.approx(40.0, abs=0.05)
        assert batch.is_complete(out / f"walk_{seed}")
    assert not (out / "broken").exists()
    assert not [p for p in out.iterdir() if p.name.startswith(".")]  # no temporary folder left behind


def test_resume_skips_complete_outputs(local_out, recordings, tmp_path, capsys):
    out = tmp_path / "out"
    shutil.copytree(local_out[0], out)  # copy2: the modification times come along
    mtimes = {p: p.stat().st_mtime_ns for p in out.rglob("*") if p.is_file() and p.name != "summary.csv"}
    walks = recordings[:N_WALKS]
    assert main(["batch", *map(str, walks), "-o", str(out), "--workers", "2"]) == 0
    assert "0 ok, 3 skipped (complete), 0 failed" in capsys.readouterr().out
    assert {p: p.stat().st_mtime_ns for p in mtimes} == mtimes
    table = pd.read_csv(out / "summary.csv", keep_default_na=False)
    assert list(table["status"]) == ["skipped"] * N_WALKS
    assert table["n_steps"].min() > 30  # the skipped rows carry the previous results

    # outputs made with other options (here with GNSS) are not complete for a --no-gnss batch: they are run again
    assert main(["batch", *map(str, walks), "-o", str(out), "--workers", "2", "--no-gnss"]) == 0
    assert "3 ok, 0 skipped (complete), 0 failed" in capsys.readouterr().out
    for seed in range(N_WALKS):
        assert json.loads((out / f"walk_{seed}" / "run.json").read_text())["options"]["use_gnss"] is False


def test_dask_local_cluster_matches_local_engine(local_out, recordings, tmp_path):
    pytest.importorskip("distributed")
    local, _, _ = local_out
    out = tmp_path / "dask"
    with pytest.raises(InputError, match="3 ok, 0 skipped \\(complete\\), 1 failed"):
        batch.run_batch(recordings, out, engine="dask", workers=2)
    assert (out / "summary.csv").read_bytes() == (local / "summary.csv").read_bytes()
    for seed in range(N_WALKS):
        name = f"walk_{seed}"
        ours, theirs = _comparable(out / name), _comparable(local / name)
        assert sorted(ours) == sorted(theirs)
        for rel in ours:
            assert ours[rel] == theirs[rel], f"{name}/{rel} differs between the Dask and the local engine"


def test_deleted_folder_fails_its_row_rest_complete(recordings, tmp_path, monkeypatch):
    """A recording folder that disappears after the batch started (here: after its id was read) fails its row."""
    gone = tmp_path / "gone"
    shutil.copytree(recordings[0], gone)
    (gone / "meta.toml").write_text((gone / "meta.toml").read_text().replace('"walk_0"', '"gone"'))
    original = batch._recording_id

    def read_then_delete(rec: Path) -> str:
        rid = original(rec)
        if rec == gone:
            shutil.rmtree(gone)
        return rid

    monkeypatch.setattr(batch, "_recording_id", read_then_delete)
    with pytest.raises(InputError, match="1 ok, 0 skipped \\(complete\\), 1 failed"):
        batch.run_batch([gone, recordings[1]], tmp_path / "out", workers=2)
    rows = pd.read_csv(tmp_path / "out" / "summary.csv", keep_default_na=False).set_index("recording_id")
    assert rows.loc["gone", "status"] == "failed" and "gone" in rows.loc["gone", "error"]
    assert rows.loc["walk_1", "status"] == "ok"


@pytest.mark.skipif(multiprocessing.get_start_method() != "fork", reason="the crash is patched in by fork")
def test_dead_worker_fails_its_row_only(recordings, tmp_path, monkeypatch):
    """A worker process killed while running one recording (a native crash, the OOM killer) fails that row only."""
    from pdr.pipelines import run as run_module

    real = run_module.run_recording

    def crash_on_walk_1(rec, out, **kwargs):
        if Path(rec).name == "walk_1":
            os._exit(9)
        return real(rec, out, **kwargs)

    monkeypatch.setattr(run_module, "run_recording", crash_on_walk_1)
    with pytest.raises(InputError, match="2 ok, 0 skipped \\(complete\\), 1 failed"):
        batch.run_batch(recordings[:N_WALKS], tmp_path / "out", workers=2)
    rows = pd.read_csv(tmp_path / "out" / "summary.csv", keep_default_na=False).set_index("recording_id")
    assert rows.loc["walk_1", "status"] == "failed"
    assert "worker process died" in rows.loc["walk_1", "error"] and "exit code 9" in rows.loc["walk_1", "error"]
    assert list(rows.loc[["walk_0", "walk_2"], "status"]) == ["ok", "ok"]


def _silent_listener() -> tuple[socket.socket, int]:
    """A TCP server that accepts connections and never says a word (dask's own timeout does not cover it)."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(8)
    accepted = []

    def accept() -> None:
        while True:
            try:
                accepted.append(server.accept()[0])
            except OSError:
                return

    threading.Thread(target=accept, daemon=True).start()
    return server, server.getsockname()[1]


def _closed_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.parametrize("kind", ["refused", "silent", "malformed"])
def test_bad_scheduler_errors_within_10_s(kind, recordings, tmp_path, capsys):
    pytest.importorskip("distributed")
    server = None
    if kind == "silent":
        server, port = _silent_listener()
        address = f"tcp://127.0.0.1:{port}"
    elif kind == "refused":
        address = f"tcp://127.0.0.1:{_closed_port()}"
    else:
        address = "no-port-here"
    try:
        t0 = time.perf_counter()
        code = main(["batch", str(recordings[0]), "-o", str(tmp_path / "out"), "--engine", "dask", "--scheduler", address])
        elapsed = time.perf_counter() - t0
    finally:
        if server is not None:
            server.close()
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 1 and elapsed < 10.0
    assert len(err) == 1 and err[0].startswith("error: --scheduler")
    assert "expected" in err[0] and address in err[0]
    assert not (tmp_path / "out").exists()  # nothing was run


def test_progress_bar_on_a_terminal_only():
    class Tty:
        def __init__(self, tty: bool):
            self.tty, self.text = tty, ""

        def isatty(self) -> bool:
            return self.tty

        def write(self, s: str) -> None:
            self.text += s

        def flush(self) -> None:
            pass

    terminal, pipe = Tty(True), Tty(False)
    for stream in (terminal, pipe):
        progress = batch._Progress(2, stream)
        progress.tick({"status": "ok"})
        progress.tick({"status": "failed"})
    assert pipe.text == ""
    assert "\r" in terminal.text and "2/2" in terminal.text and "1 failed" in terminal.text
    assert terminal.text.endswith("\n")


def test_bad_arguments(recordings, tmp_path, capsys):
    walk = str(recordings[0])
    assert main(["batch", walk, walk, "-o", str(tmp_path / "o")]) == 1
    assert "expected each recording once" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:  # a usage error
        main(["batch", walk, "-o", str(tmp_path / "o"), "--workers", "0"])
    assert exc.value.code == 2 and "--workers: expected a whole number >= 1, found '0'" in capsys.readouterr().err
    assert main(["batch", walk, "-o", str(tmp_path / "o"), "--scheduler", "tcp://127.0.0.1:1"]) == 1
    assert "--scheduler: expected it with --engine dask only" in capsys.readouterr().err
    assert main(["batch", walk, "-o", str(tmp_path / "o"), "--config", str(tmp_path / "missing.toml")]) == 1
    assert "expected a file" in capsys.readouterr().err


def test_recordings_sharing_an_id_get_unique_folders(tmp_path):
    """Eight seeds of one scenario keep the scenario's id; two phones export the same name: each its own folder."""
    raw = _short_walk(0)
    recs = [save_recording(simulate(raw, seed), tmp_path / "recs" / f"seed{seed}") for seed in range(2)]
    recs.append(save_recording(simulate(raw, 2), tmp_path / "other" / "seed0"))  # same id and same folder name
    line = batch.run_batch(recs, tmp_path / "out", workers=1)
    assert "3 ok" in line
    table = pd.read_csv(tmp_path / "out" / "summary.csv")
    assert sorted(table["output_folder"]) == ["seed0", "seed0_2", "seed1"]
    assert set(table["recording_id"]) == {"walk_0"}
    for folder in table["output_folder"]:
        assert (tmp_path / "out" / folder / "summary.json").is_file()
