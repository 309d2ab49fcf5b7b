"""`hexbench dataset download`: fetch a published dataset archive with pooch, verify, extract safely.

The registry is `datasets/registry.toml`, one table per dataset:

  [terrain-images]
  version = "1.0.0"
  archive = "terrain-images-1.0.0.tar.gz"
  sha256 = "<hex digest of the archive>"
  size_bytes = 1234567
  urls = ["https://...", "https://..."]   # mirrors, tried in order

  ["terrain-images@2"]                    # another major version of the same dataset
  version = "2.0.0"
  ...

A table's key is the dataset name for major version 1 and `<name>@<major>` for the others, so
every version stays downloadable (`hexbench dataset download terrain-images --version 1`);
without --version the highest registered major version is fetched.

Cache: `$HEXBENCH_DATA_DIR` if set, else pooch's per-user cache (`pooch.os_cache("hexbench")`).
The archive lands there as `<archive>` and is extracted to `<name>-<version>/`; every extracted
file is then checked against the dataset's own manifest. `$HEXBENCH_DATASET_URL` (or `--url`)
replaces the registry's mirrors, e.g. to serve the archive from a local server.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import urlparse

from hexbench.artifacts.files import sha256_file, write_text_atomic
from hexbench.artifacts.provenance import REPO_ROOT
from hexbench.errors import HexbenchError

REGISTRY_PATH = REPO_ROOT / "datasets" / "registry.toml"
DATA_DIR_ENV = "HEXBENCH_DATA_DIR"
URL_ENV = "HEXBENCH_DATASET_URL"
COMPLETE_MARKER = ".hexbench-complete"  # holds the archive sha256 once extraction and checks passed


class DownloadError(HexbenchError):
    """A dataset could not be fetched or failed verification (message: one line)."""


@dataclass(frozen=True)
class RegistryEntry:
    name: str
    version: str
    archive: str
    sha256: str
    size_bytes: int
    urls: tuple[str, ...]

    @property
    def major(self) -> int:
        return int(self.version.split(".", 1)[0])

    @property
    def key(self) -> str:
        """The registry table of this entry: the name (major version 1) or `name@major`."""
        return registry_key(self.name, self.major)

    def toml(self) -> str:
        urls = ", ".join(f'"{u}"' for u in self.urls)
        header = self.key if self.major == 1 else f'"{self.key}"'
        return (f"[{header}]\nversion = \"{self.version}\"\narchive = \"{self.archive}\"\n"
                f"sha256 = \"{self.sha256}\"\nsize_bytes = {self.size_bytes}\nurls = [{urls}]\n")


def registry_key(name: str, major: int) -> str:
    return name if major == 1 else f"{name}@{major}"


def load_registry(path: Path | None = None) -> dict[str, RegistryEntry]:
    """Entries by table key (`name` or `name@major`)."""
    import tomllib

    path = Path(path) if path is not None else REGISTRY_PATH
    if not path.is_file():
        raise DownloadError(f"dataset registry {path} not found")
    try:
        tables = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as err:
        raise DownloadError(f"dataset registry {path} is not valid TOML: {err}") from None
    entries = {}
    for key, t in tables.items():
        name = key.split("@", 1)[0]
        try:
            entry = RegistryEntry(name, str(t["version"]), str(t["archive"]), str(t["sha256"]).lower(),
                                  int(t["size_bytes"]), tuple(t["urls"]))
            expected_key = entry.key  # ValueError for a version that does not start with an integer
        except (KeyError, TypeError, ValueError) as err:
            raise DownloadError(f"dataset registry {path}: entry [{key}] lacks or mangles {err}") from None
        if key != expected_key:
            raise DownloadError(f"dataset registry {path}: entry [{key}] holds version {entry.version}; "
                                f"its table must be [{expected_key}]")
        entries[key] = entry
    return entries


def data_dir() -> Path:
    import pooch

    env = os.environ.get(DATA_DIR_ENV)
    return Path(env).expanduser() if env else Path(pooch.os_cache("hexbench"))


def download(name: str, *, version: int | None = None, registry_path: Path | None = None,
             cache_dir: Path | None = None, url: str | None = None, progressbar: bool = False) -> Path:
    """Fetch, verify and extract dataset `name` (major `version`, default the highest registered);
    return the folder holding its files."""
    import pooch

    from hexbench.perception.dataset.archive import ArchiveError, safe_extract
    from hexbench.perception.dataset.build import verify_build

    registry = load_registry(registry_path)
    versions = {e.major: e for e in registry.values() if e.name == name}
    if not versions:
        names = sorted({e.name for e in registry.values()})
        raise DownloadError(f"unknown dataset {name!r}; registered: {', '.join(names) or '(none)'}")
    if version is not None and version not in versions:
        raise DownloadError(f"dataset {name!r} has no registered version {version}; registered versions: "
                            f"{', '.join(str(v) for v in sorted(versions))} (build it with "
                            f"`hexbench dataset build {name} --version {version}`)")
    entry = versions[max(versions) if version is None else version]
    cache = Path(cache_dir) if cache_dir is not None else data_dir()
    cache.mkdir(parents=True, exist_ok=True)
    target = cache / f"{entry.name}-{entry.version}"
    marker = target / COMPLETE_MARKER
    if marker.is_file() and marker.read_text().strip() == entry.sha256:
        return target

    override = url or os.environ.get(URL_ENV)
    urls = (override,) if override else entry.urls
    if not urls:
        raise DownloadError(f"dataset {name!r} has no mirror URL; pass --url or set {URL_ENV}")
    failures = []
    archive = None
    for u in urls:
        if urlparse(u).hostname and urlparse(u).hostname.endswith(".invalid"):
            failures.append(f"{u} is a placeholder (no public mirror yet)")
            continue
        try:
            archive = Path(pooch.retrieve(u, known_hash=f"sha256:{entry.sha256}", fname=entry.archive, path=cache,
                                          progressbar=progressbar))
            break
        except ValueError as err:
            if "does not match" in str(err):
                raise DownloadError(f"archive from {u} failed sha256 verification (expected {entry.sha256}): "
                                    "tampered or truncated; nothing was kept") from None
            failures.append(f"{u}: {err}")
        except Exception as err:  # network errors from requests / urllib
            failures.append(f"{u}: {type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''}")
    if archive is None:
        raise DownloadError(f"could not download {name!r} from any mirror ({'; '.join(failures)}); "
                            f"pass --url or set {URL_ENV}, or build it with `hexbench dataset build {name}`")
    size = archive.stat().st_size
    if size != entry.size_bytes:
        raise DownloadError(f"archive {archive.name} is {size} bytes but the registry says {entry.size_bytes}")
    try:
        safe_extract(archive, target)
    except ArchiveError as err:
        raise DownloadError(str(err)) from None
    problems = verify_build(target)
    if problems:
        raise DownloadError(f"extracted {name!r} does not match its manifest: {problems[0]} "
                            f"({len(problems)} problem(s))")
    marker.write_text(entry.sha256 + "\n")
    return target


def registry_entry_for(archive: Path, name: str, version: str, urls: tuple[str, ...]) -> RegistryEntry:

    archive = Path(archive)
    return RegistryEntry(name, version, archive.name, sha256_file(archive), archive.stat().st_size, urls)


def write_registry(entries: dict[str, RegistryEntry], path: Path | None = None, header: str = "") -> None:
    path = Path(path) if path is not None else REGISTRY_PATH
    text = header + "\n".join(entries[k].toml() for k in sorted(entries))
    write_text_atomic(path, text)
