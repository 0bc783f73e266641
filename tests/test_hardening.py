"""Hardening: hostile archives, --force, temporary name + rename everywhere, data-only parsing.

What ``tests/test_importers.py`` already covers (``../``, absolute paths, a symbolic link, the compression ratio, the
total-size limit, an existing recording without ``--force``) is not repeated here; this file adds the cases the
audit found untested.
"""

from __future__ import annotations

import ast
import json
import struct
import zipfile
from pathlib import Path

import pytest

from pdr.cli.main import main
from pdr.errors import InputError
from pdr.io import atomic
from pdr.io.importers import _common
from pdr.io.recording import Recording, load_recording, save_recording

ROOT = Path(__file__).resolve().parents[1]
HAND = Path(__file__).resolve().parent / "importers"


def _cli(argv, capsys):
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def _one_error(rc, err) -> str:
    lines = [line for line in err.splitlines() if line.startswith("error:")]
    assert rc == 1 and len(lines) == 1 and "Traceback" not in err and "internal failure" not in err, err
    return lines[0]


def _export_zip(path: Path, extra: dict[str, bytes] | None = None, *, src: Path = HAND / "sensorlogger_android") -> Path:
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        for p in sorted(src.iterdir()):
            zf.write(p, p.name)
        for name, data in (extra or {}).items():
            zf.writestr(zipfile.ZipInfo(name), data)
    return path


def _hidden(folder: Path) -> list[Path]:
    return [p for p in folder.rglob(".*")] if folder.exists() else []


# ---------------------------------------------------------------------------------------------------------------
# Archives
# ---------------------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name, message", [
    ("..\\evil.csv", "escapes"),  # a Windows separator
    ("data/../../evil.csv", "escapes"),  # an escape further down the path
    ("C:/evil.csv", "absolute"),  # a drive letter
    ("\\\\server\\share\\evil.csv", "absolute"),  # a UNC path
])
@pytest.mark.parametrize("fmt", ["sensorlogger", "phyphox"])
def test_zip_member_paths_that_escape_are_refused(tmp_path, capsys, fmt, name, message):
    src = HAND / ("sensorlogger_android" if fmt == "sensorlogger" else "phyphox_multi")
    archive = _export_zip(tmp_path / "export.zip", {name: b"x"}, src=src)
    rc, _, err = _cli(["import", fmt, archive, tmp_path / "out"], capsys)
    assert message in _one_error(rc, err)
    assert not (tmp_path / "out").exists() and not list(tmp_path.parent.glob("evil.csv"))


def test_zip_member_lying_about_its_size_is_stopped_while_extracting(tmp_path, capsys):
    """The headers say 10 bytes; the data inflate to 20,000: refused (by our byte count or zipfile's own checks)."""
    archive = tmp_path / "export.zip"
    _export_zip(archive, {"Notes.csv": b"a" * 20_000})
    data = bytearray(archive.read_bytes())
    for sig, off in ((b"PK\x03\x04", 22), (b"PK\x01\x02", 24)):  # uncompressed size: local header, central directory
        pos = 0
        while (pos := data.find(sig, pos)) >= 0:
            name_len = struct.unpack_from("<H", data, pos + (26 if sig == b"PK\x03\x04" else 28))[0]
            name_at = pos + (30 if sig == b"PK\x03\x04" else 46)
            if data[name_at:name_at + name_len] == b"Notes.csv":
                struct.pack_into("<I", data, pos + off, 10)
            pos += 4
    archive.write_bytes(bytes(data))
    rc, _, err = _cli(["import", "sensorlogger", archive, tmp_path / "out"], capsys)
    assert "declared" in _one_error(rc, err) or "damaged member 'Notes.csv'" in err
    assert not (tmp_path / "out").exists()


def test_zip_encrypted_member_and_member_count_limit(tmp_path, capsys, monkeypatch):
    archive = _export_zip(tmp_path / "export.zip", {"secret.csv": b"x"})
    data = bytearray(archive.read_bytes())
    pos = data.find(b"PK\x01\x02")
    while pos >= 0:  # set the "encrypted" flag on the secret member in the central directory
        name_len = struct.unpack_from("<H", data, pos + 28)[0]
        if data[pos + 46:pos + 46 + name_len] == b"secret.csv":
            struct.pack_into("<H", data, pos + 8, struct.unpack_from("<H", data, pos + 8)[0] | 0x1)
        pos = data.find(b"PK\x01\x02", pos + 4)
    archive.write_bytes(bytes(data))
    rc, _, err = _cli(["import", "sensorlogger", archive, tmp_path / "out"], capsys)
    assert "encrypted" in _one_error(rc, err)
    monkeypatch.setattr(_common, "MAX_ZIP_MEMBERS", 3)
    rc, _, err = _cli(["import", "sensorlogger", _export_zip(tmp_path / "many.zip"), tmp_path / "out"], capsys)
    assert "at most 3 members" in _one_error(rc, err)
    assert not (tmp_path / "out").exists()


# ---------------------------------------------------------------------------------------------------------------
# --force and nothing half-written
# ---------------------------------------------------------------------------------------------------------------


def test_simulate_and_run_refuse_to_overwrite_without_force(tmp_path, capsys):
    scenario = ROOT / "configs" / "sim" / "walk_short.toml"
    rec = tmp_path / "rec"
    assert _cli(["simulate", scenario, "-o", rec, "--seed", "1"], capsys)[0] == 0
    before = {p.name: p.read_bytes() for p in rec.iterdir() if p.is_file()}
    rc, _, err = _cli(["simulate", scenario, "-o", rec, "--seed", "2"], capsys)
    assert "--force" in _one_error(rc, err)
    assert {p.name: p.read_bytes() for p in rec.iterdir() if p.is_file()} == before
    assert _cli(["simulate", scenario, "-o", rec, "--seed", "2", "--force"], capsys)[0] == 0
    assert (rec / "imu.csv").read_bytes() != before["imu.csv"]

    mine = tmp_path / "my_folder"
    mine.mkdir()
    (mine / "notes.txt").write_text("do not lose me")
    rc, _, err = _cli(["run", rec, "-o", mine], capsys)
    assert "--force" in _one_error(rc, err)
    assert [p.name for p in mine.iterdir()] == ["notes.txt"]
    assert _cli(["run", rec, "-o", mine, "--force"], capsys)[0] == 0
    assert (mine / "summary.json").is_file() and (mine / "notes.txt").read_text() == "do not lose me"
    assert not _hidden(tmp_path)


def test_a_run_that_fails_while_writing_leaves_the_previous_output(tmp_path, capsys, monkeypatch):
    rec = tmp_path / "rec"
    assert _cli(["simulate", ROOT / "configs" / "sim" / "walk_short.toml", "-o", rec, "--seed", "1"], capsys)[0] == 0
    out = tmp_path / "out"
    assert _cli(["run", rec, "-o", out], capsys)[0] == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    import pdr.pipelines.run as run_module

    def broken(path, obj, **kw):
        if Path(path).name == "summary.json":  # the last file written
            raise OSError("disk full")
        return write_json(path, obj, **kw)

    write_json = run_module.write_json
    monkeypatch.setattr(run_module, "write_json", broken)
    rc, _, err = _cli(["run", rec, "-o", out, "--force"], capsys)
    err = "".join(line for line in err.splitlines(keepends=True) if not line.startswith("warning:"))
    assert rc == 1 and err.startswith("error:") and "disk full" in err and len(err.splitlines()) == 1
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before  # the old output, whole
    assert not _hidden(tmp_path)


def test_save_recording_failing_midway_writes_nothing(tmp_path, monkeypatch):
    rec = load_recording(save_recording(Recording(meta={"recording": {"id": "r"}}, imu=_imu()), tmp_path / "ok"))
    calls = []

    def broken(dest, df, **kw):
        calls.append(Path(dest).name)
        if len(calls) == 2:
            raise OSError("disk full")
        return original(dest, df, **kw)

    original = atomic.write_csv
    import pdr.io.recording as recording_module

    monkeypatch.setattr(recording_module, "write_csv", broken)
    rec.reference = {"steps": rec.imu[["t_s"]].iloc[:3]}
    with pytest.raises(InputError, match="disk full"):  # one plain line naming the destination
        save_recording(rec, tmp_path / "new")
    assert not (tmp_path / "new").exists() and not _hidden(tmp_path)


def _imu():
    from tests.conftest import make_imu

    return make_imu()


# ---------------------------------------------------------------------------------------------------------------
# Configuration and model files are data only
# ---------------------------------------------------------------------------------------------------------------

UNSAFE_CALLS = {"eval", "exec", "compile", "__import__"}
UNSAFE_MODULES = {"pickle", "cPickle", "dill", "marshal", "shelve", "yaml", "joblib", "cloudpickle"}


def test_no_code_execution_from_files_anywhere_in_pdr():
    problems = []
    for path in sorted((ROOT / "pdr").rglob("*.py")):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                problems += [f"{path.name} imports {a.name}" for a in node.names if a.name.split(".")[0] in UNSAFE_MODULES]
            elif isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] in UNSAFE_MODULES:
                problems.append(f"{path.name} imports {node.module}")
            elif isinstance(node, ast.Call):
                name = node.func.id if isinstance(node.func, ast.Name) else getattr(node.func, "attr", "")
                if isinstance(node.func, ast.Name) and name in UNSAFE_CALLS:  # (re.compile is fine)
                    problems.append(f"{path.name}:{node.lineno} calls {name}")
                if name in ("load", "read_pickle") and any(k.arg == "allow_pickle" for k in node.keywords):
                    problems.append(f"{path.name}:{node.lineno} loads with allow_pickle")
                if name == "read_pickle":
                    problems.append(f"{path.name}:{node.lineno} reads a pickle")
    assert not problems, problems


def test_model_and_config_files_cannot_name_code(tmp_path, capsys):
    rec = tmp_path / "rec"
    assert _cli(["simulate", ROOT / "configs" / "sim" / "walk_short.toml", "-o", rec, "--seed", "1"], capsys)[0] == 0
    model = tmp_path / "model.json"
    model.write_text(json.dumps({"model": "os.system", "params": {"command": "touch pwned"}}))
    rc, _, err = _cli(["run", rec, "-o", tmp_path / "out", "--model", model], capsys)
    _one_error(rc, err)
    config = tmp_path / "run.toml"
    config.write_text('[fusion]\nmethod = "__import__(\'os\').system(\'touch pwned\')"\n')
    rc, _, err = _cli(["run", rec, "-o", tmp_path / "out", "--config", config], capsys)
    _one_error(rc, err)
    config.write_text('[steps]\nmethod = "!!python/object:os.system"\n')
    rc, _, err = _cli(["run", rec, "-o", tmp_path / "out", "--config", config], capsys)
    _one_error(rc, err)
    assert not (tmp_path / "out").exists() and not list(Path.cwd().glob("pwned")) and not list(tmp_path.rglob("pwned"))
