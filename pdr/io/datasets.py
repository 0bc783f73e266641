"""The registry of the public recordings the project reads (``datasets/registry.toml``) and where their files are.

None of these files is part of the repository. ``PDR_DATA_DIR`` names a local copy with the registry's layout
(``<dir>/<dataset>/<path>``); without it, ``../shared/datasets`` beside the repository is used when present, else
the download cache that ``pdr datasets fetch`` fills. Downloads go through pooch (Uieda et al., JOSS 2020), which checks
each file's sha256.
"""

from __future__ import annotations

import os
import shutil
import urllib.parse
import urllib.request
from dataclasses import dataclass
from pathlib import Path

from pdr.errors import InputError
from pdr.io.tomlio import read_toml

REPO_ROOT = Path(__file__).resolve().parents[2]
REGISTRY_PATH = REPO_ROOT / "datasets" / "registry.toml"
DATA_DIR_VARIABLE = "PDR_DATA_DIR"
SHARED_DATA_DIR = REPO_ROOT.parent / "shared" / "datasets"


@dataclass(frozen=True)
class DatasetFile:
    """One file of a dataset: its path inside the dataset folder, where upstream serves it, and its sha256."""

    path: str
    url: str
    sha256: str


@dataclass(frozen=True)
class Dataset:
    """A public recording: its source (repository at a pinned commit), licence, citation and ground truth."""

    name: str
    title: str
    repository: str
    commit: str
    licence: str
    citation: str
    ground_truth: str
    files: tuple[DatasetFile, ...]


def load_registry(path: Path = REGISTRY_PATH) -> dict[str, Dataset]:
    """Every dataset of the registry file, by name."""
    raw = read_toml(path, what="dataset registry")
    out = {}
    for name, entry in raw.get("datasets", {}).items():
        files = tuple(DatasetFile(f["path"], f["url"], f["sha256"]) for f in entry.get("files", []))
        out[name] = Dataset(name, entry["title"], entry["repository"], entry["commit"], entry["licence"],
                            entry["citation"], entry["ground_truth"], files)
    return out


def cache_dir() -> Path:
    """The download cache of ``pdr datasets fetch`` (pooch's per-user cache folder for ``pdr``)."""
    import pooch

    return Path(pooch.os_cache("pdr")) / "datasets"


def data_dir() -> Path:
    """The folder every consumer reads the datasets from: ``PDR_DATA_DIR``, else ``../shared/datasets`` beside the
    repository when it exists, else the download cache."""
    if os.environ.get(DATA_DIR_VARIABLE):
        return Path(os.environ[DATA_DIR_VARIABLE]).expanduser()
    if SHARED_DATA_DIR.is_dir():
        return SHARED_DATA_DIR
    return cache_dir()


def get_dataset(name: str, registry: dict[str, Dataset] | None = None) -> Dataset:
    registry = load_registry() if registry is None else registry
    if name not in registry:
        raise InputError(f"dataset {name!r}: not in the registry; expected one of: {', '.join(sorted(registry))}")
    return registry[name]


def missing_files(name: str, root: Path | None = None) -> list[str]:
    """The registered files of ``name`` that are not under ``root`` (default: ``data_dir()``)."""
    folder = (data_dir() if root is None else root) / name
    return [f.path for f in get_dataset(name).files if not (folder / f.path).is_file()]


def dataset_dir(name: str) -> Path:
    """The local folder of a registered dataset, with all its files; an InputError that says how to get them
    otherwise."""
    missing = missing_files(name)
    if missing:
        raise InputError(
            f"dataset {name}: {len(missing)} file(s) missing under {data_dir() / name} (e.g. {missing[0]}); "
            f"run `pdr datasets fetch {name}` or set {DATA_DIR_VARIABLE} to a folder that holds it")
    return data_dir() / name


def _file_downloader(url: str, output_file, _pooch) -> None:
    """pooch downloader for ``file://`` URLs (a local mirror; also how the tests exercise fetch offline)."""
    source = Path(urllib.request.url2pathname(urllib.parse.urlparse(url).path))
    with open(source, "rb") as src:
        if isinstance(output_file, (str, Path)):
            with open(output_file, "wb") as dst:
                shutil.copyfileobj(src, dst)
        else:
            shutil.copyfileobj(src, output_file)


def fetch_dataset(name: str, dest: Path | None = None, registry: dict[str, Dataset] | None = None) -> Path:
    """Download every file of ``name`` into ``dest/name`` (default: the cache), verifying each sha256; files already
    there with the right checksum are kept. Returns the dataset folder."""
    import pooch

    pooch.get_logger().setLevel("WARNING")
    dataset = get_dataset(name, registry)
    folder = (cache_dir() if dest is None else Path(dest)) / name
    for f in dataset.files:
        target = folder / f.path
        downloader = _file_downloader if f.url.startswith("file://") else None
        try:
            pooch.retrieve(f.url, known_hash=f"sha256:{f.sha256}", fname=target.name, path=target.parent,
                           downloader=downloader, progressbar=False)
        except ValueError as exc:  # pooch: checksum mismatch (the partial download is removed)
            raise InputError(f"dataset {name}: {f.url}: checksum mismatch ({str(exc).splitlines()[0]})") from None
        except Exception as exc:  # network or file errors: requests, OSError
            raise InputError(
                f"dataset {name}: could not download {f.url} ({type(exc).__name__}); without network, copy the "
                f"dataset to a folder and set {DATA_DIR_VARIABLE} to it") from None
    return folder
