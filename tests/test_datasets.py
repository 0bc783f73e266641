"""The dataset registry (``datasets/registry.toml``), ``pdr datasets list|fetch``, and the rule that no third-party
recording is committed to the repository."""

from __future__ import annotations

import hashlib
import subprocess
from pathlib import Path

import pytest

from conftest import ROOT
from pdr.cli.main import main
from pdr.io import datasets
from pdr.io.datasets import Dataset, DatasetFile, load_registry

KEPT_IN_REPO = {"ground_textures_cc0"}  # CC0 photos from the scikit-image wheel: the project may keep them


def _git_blob(path: Path) -> str:
    data = path.read_bytes()
    return hashlib.sha1(b"blob %d\0" % len(data) + data).hexdigest()


def test_no_tracked_file_equals_a_shared_recording():
    """Compare git blob hashes of every tracked file with those of ../shared/datasets (skipped where it is absent)."""
    if not datasets.SHARED_DATA_DIR.is_dir():
        pytest.skip(f"{datasets.SHARED_DATA_DIR} absent: nothing to compare the tracked files with")
    shared = {}
    for p in datasets.SHARED_DATA_DIR.rglob("*"):
        if p.is_file() and p.relative_to(datasets.SHARED_DATA_DIR).parts[0] not in KEPT_IN_REPO:
            shared[_git_blob(p)] = p
    listing = subprocess.run(["git", "ls-files", "-s"], cwd=ROOT, capture_output=True, text=True, check=True).stdout
    copies = [f"{line.split(chr(9))[1]} = {shared[line.split()[1]]}" for line in listing.splitlines()
              if line.split()[1] in shared]
    assert not copies, "third-party recordings committed:\n" + "\n".join(copies)


def test_registry_entries_are_complete_and_match_the_shared_copy():
    registry = load_registry()
    assert {"oxford_step_counter", "mobgap_lowerback_tvs_lab", "humolire_phone_landmarks", "gaitmap_foot_imu_mocap",
            "xio_foot_imu_loop_walk", "openshoe_foot_imu_figure8"} <= set(registry)
    for ds in registry.values():
        assert len(ds.commit) == 40 and ds.licence and ds.citation and ds.ground_truth and ds.files
        for f in ds.files:
            assert f.url.startswith(f"https://raw.githubusercontent.com/{ds.repository.split('github.com/')[1]}/{ds.commit}/")
            assert len(f.sha256) == 64
            local = datasets.SHARED_DATA_DIR / ds.name / f.path
            if local.is_file():
                assert hashlib.sha256(local.read_bytes()).hexdigest() == f.sha256, local


def _local_registry(tmp_path: Path, content: bytes, sha256: str | None = None) -> dict[str, Dataset]:
    mirror = tmp_path / "mirror"
    mirror.mkdir()
    (mirror / "walk.csv").write_bytes(content)
    digest = sha256 or hashlib.sha256(content).hexdigest()
    f = DatasetFile("sub/walk.csv", (mirror / "walk.csv").as_uri(), digest)
    return {"demo_walk": Dataset("demo_walk", "a walk", "https://github.com/o/r", "0" * 40, "MIT", "cite", "none", (f,))}


def test_fetch_from_file_url_verifies_the_checksum(tmp_path):
    registry = _local_registry(tmp_path, b"t_s,acc\n0,1\n")
    folder = datasets.fetch_dataset("demo_walk", tmp_path / "cache", registry)
    assert (folder / "sub" / "walk.csv").read_bytes() == b"t_s,acc\n0,1\n"
    datasets.fetch_dataset("demo_walk", tmp_path / "cache", registry)  # present and verified: kept


def test_fetch_checksum_mismatch_is_one_error_and_leaves_no_file(tmp_path):
    registry = _local_registry(tmp_path, b"t_s,acc\n0,1\n", sha256="a" * 64)
    with pytest.raises(datasets.InputError, match="checksum mismatch"):
        datasets.fetch_dataset("demo_walk", tmp_path / "cache", registry)
    assert not (tmp_path / "cache" / "demo_walk" / "sub" / "walk.csv").exists()


def test_fetch_without_network_names_the_url_and_the_variable(tmp_path, monkeypatch, capsys):
    ds = load_registry()["xio_foot_imu_loop_walk"]
    unreachable = tuple(DatasetFile(f.path, "https://unreachable.invalid/" + f.path, f.sha256) for f in ds.files)
    monkeypatch.setattr(datasets, "load_registry", lambda path=None: {ds.name: Dataset(**{**ds.__dict__, "files": unreachable})})
    assert main(["datasets", "fetch", ds.name, "--dir", str(tmp_path)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "https://unreachable.invalid/" in err[0] and "PDR_DATA_DIR" in err[0]


def test_unknown_dataset_is_one_error(capsys):
    assert main(["datasets", "fetch", "no_such_walk"]) == 1
    assert "not in the registry" in capsys.readouterr().err


def test_list_shows_every_entry_and_its_state(monkeypatch, tmp_path, capsys):
    monkeypatch.setenv("PDR_DATA_DIR", str(tmp_path))
    assert datasets.data_dir() == tmp_path
    assert main(["datasets", "list"]) == 0
    out = capsys.readouterr().out
    assert str(tmp_path) in out.splitlines()[0]
    for name in load_registry():
        assert f"{name}:" in out
    assert "[present]" not in out and "missing" in out
    with pytest.raises(datasets.InputError, match="pdr datasets fetch humolire_phone_landmarks"):
        datasets.dataset_dir("humolire_phone_landmarks")


def test_path_prints_the_local_folder_or_says_how_to_get_it(monkeypatch, tmp_path, capsys):
    (tmp_path / "xio_foot_imu_loop_walk").mkdir()
    for f in load_registry()["xio_foot_imu_loop_walk"].files:
        (tmp_path / "xio_foot_imu_loop_walk" / f.path).write_text("x")
    monkeypatch.setenv("PDR_DATA_DIR", str(tmp_path))
    assert main(["datasets", "path", "xio_foot_imu_loop_walk"]) == 0
    assert capsys.readouterr().out.strip() == str(tmp_path / "xio_foot_imu_loop_walk")
    assert main(["datasets", "path", "gaitmap_foot_imu_mocap"]) == 1
    assert "pdr datasets fetch gaitmap_foot_imu_mocap" in capsys.readouterr().err
