"""Terrain-image dataset: determinism, split leakage, atomic builds, archives and verified downloads.

Downloads run against an http.server on 127.0.0.1 (no other network)."""

from __future__ import annotations

import functools
import http.server
import io
import json
import tarfile
import threading
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from hexbench.cli import app
from hexbench.perception.dataset.archive import ArchiveError, pack_build, safe_extract
from hexbench.perception.dataset.build import BuildConfig, build_terrain_images, plan_images, verify_build
from hexbench.perception.dataset.registry import (
    DownloadError,
    RegistryEntry,
    download,
    registry_entry_for,
    write_registry,
)
from hexbench.perception.views import TERRAIN_CLASSES

TINY = BuildConfig(per_class=5, seed=3)


@pytest.fixture(scope="module")
def tiny_build(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("ds") / "terrain-images"
    build_terrain_images(out, TINY)
    return out


def _sha_map(build: Path) -> dict[str, str]:
    return {f["path"]: f["sha256"] for f in json.loads((build / "manifest.json").read_text())["files"]}


def test_build_layout_and_manifest(tiny_build):
    manifest = json.loads((tiny_build / "manifest.json").read_text())
    assert manifest["classes"] == list(TERRAIN_CLASSES)
    assert len(manifest["files"]) == 3 * TINY.per_class
    for split in ("train", "test"):
        for terrain in TERRAIN_CLASSES:
            assert list((tiny_build / split / terrain).glob("*.png")), f"{split}/{terrain} is empty"
    for f in manifest["files"]:
        assert f["path"].split("/")[:2] == [f["split"], f["label"]]
    assert verify_build(tiny_build) == []
    from PIL import Image

    img = np.asarray(Image.open(tiny_build / manifest["files"][0]["path"]))
    assert img.shape == (72, 96, 3) and img.std() > 1.0  # a real picture, not a blank frame


def test_same_seed_gives_identical_bytes(tiny_build, tmp_path):
    again = tmp_path / "again"
    build_terrain_images(again, TINY)
    assert _sha_map(again) == _sha_map(tiny_build)
    assert (again / "manifest.json").read_bytes() == (tiny_build / "manifest.json").read_bytes()


def test_other_seed_gives_other_images():
    a = plan_images(BuildConfig(per_class=5, seed=3))
    b = plan_images(BuildConfig(per_class=5, seed=4))
    assert {p.view.instance.terrain_seed for p in a}.isdisjoint({p.view.instance.terrain_seed for p in b})


def test_split_is_by_terrain_instance_without_leakage():
    config = BuildConfig(per_class=200, seed=0)  # the default build's plan (no rendering)
    planned = plan_images(config)
    split_of_instance: dict[tuple, set] = {}
    for item in planned:
        split_of_instance.setdefault((item.terrain, item.view.instance.terrain_seed), set()).add(item.split)
    assert all(len(s) == 1 for s in split_of_instance.values()), "a terrain instance is in both splits"
    for terrain in TERRAIN_CLASSES:
        items = [p for p in planned if p.terrain == terrain]
        assert len(items) == 200
        assert sum(p.split == "test" for p in items) == 40  # 80/20
        seeds = {s: {p.view.instance.terrain_seed for p in items if p.split == s} for s in ("train", "test")}
        assert seeds["train"].isdisjoint(seeds["test"])
        levels = {s: {p.view.instance.level for p in items if p.split == s} for s in ("train", "test")}
        assert levels["train"].isdisjoint(levels["test"])
    held_out = {p.view.instance.terrain_seed for p in plan_images(BuildConfig(per_class=200, seed=1))}
    assert held_out.isdisjoint({p.view.instance.terrain_seed for p in planned})


def test_build_refuses_existing_folder_and_leaves_no_partial_files(tiny_build, tmp_path):
    with pytest.raises(FileExistsError, match="--force"):
        build_terrain_images(tiny_build, TINY)
    out = tmp_path / "bad"
    result = CliRunner().invoke(app, ["dataset", "build", "terrain-images", "--per-class", "1", "--out", str(out)])
    assert result.exit_code == 2 and "--per-class must be at least 2" in result.output
    assert not out.exists() and list(tmp_path.iterdir()) == []
    result = CliRunner().invoke(app, ["dataset", "build", "no-such-set"])
    assert result.exit_code == 2 and "valid datasets: terrain-images" in result.output


def test_failed_build_removes_its_temp_folder(tmp_path, monkeypatch):
    import hexbench.perception.dataset.build as build_mod

    calls = {"n": 0}

    def broken(sim, view):
        calls["n"] += 1
        if calls["n"] > 2:
            raise RuntimeError("renderer died")
        return np.zeros((72, 96, 3), np.uint8)

    monkeypatch.setattr(build_mod, "render_view", broken)
    with pytest.raises(RuntimeError):
        build_terrain_images(tmp_path / "x", TINY)
    assert list(tmp_path.iterdir()) == []


# ------------------------------------------------------------------------------ archives


@pytest.mark.parametrize("manifest, words", [
    ("[" * 100_000, "not valid JSON (nested too deeply)"),
    ("[1, 2]", "not a terrain-images manifest"),
    ('{"files": [{"path": "../../etc/passwd", "sha256": "0"}]}', "is not a path inside the dataset folder"),
    (None, "is not a terrain-images build"),
])
def test_a_corrupt_or_hostile_manifest_is_one_line(tmp_path, manifest, words):
    folder = tmp_path / "dataset"
    folder.mkdir()
    if manifest is not None:
        (folder / "manifest.json").write_text(manifest)
    for command in (["dataset", "verify", str(folder)], ["dataset", "preview", str(folder), "--out", str(tmp_path / "p.png")]):
        res = CliRunner().invoke(app, command)
        lines = [ln for ln in res.output.splitlines() if ln.strip()]
        assert res.exit_code != 0 and len(lines) == 1 and words in lines[0], (command, res.output)
    assert not (tmp_path / "p.png").exists()


def test_pack_is_deterministic(tiny_build, tmp_path):
    a = pack_build(tiny_build, tmp_path / "a.tar.gz", "terrain-images-1.0.0")
    b = pack_build(tiny_build, tmp_path / "b.tar.gz", "terrain-images-1.0.0")
    assert a.read_bytes() == b.read_bytes()
    out = safe_extract(a, tmp_path / "x")
    assert _sha_map(out) == _sha_map(tiny_build) and verify_build(out) == []


def _tar_with(member: tarfile.TarInfo, data: bytes = b"x") -> bytes:
    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w:gz") as tar:
        if member.isfile():
            member.size = len(data)
            tar.addfile(member, io.BytesIO(data))
        else:
            tar.addfile(member)
    return buf.getvalue()


def _unsafe_archives() -> dict[str, bytes]:
    absolute = tarfile.TarInfo("/tmp/hexbench-evil.txt")
    dotdot = tarfile.TarInfo("terrain-images/../../evil.txt")
    symlink = tarfile.TarInfo("terrain-images/link")
    symlink.type, symlink.linkname = tarfile.SYMTYPE, "/etc/passwd"
    hardlink = tarfile.TarInfo("terrain-images/hard")
    hardlink.type, hardlink.linkname = tarfile.LNKTYPE, "terrain-images/manifest.json"
    return {"absolute path": _tar_with(absolute), "leaves the destination": _tar_with(dotdot),
            "link": _tar_with(symlink), "link ": _tar_with(hardlink)}


@pytest.mark.parametrize("problem", ["absolute path", "leaves the destination", "link", "link "])
def test_safe_extract_refuses_unsafe_members(problem, tmp_path):
    archive = tmp_path / "evil.tar.gz"
    archive.write_bytes(_unsafe_archives()[problem])
    with pytest.raises(ArchiveError, match=problem.strip()):
        safe_extract(archive, tmp_path / "out" / "x")
    assert not (tmp_path / "out" / "x").exists()
    assert not (tmp_path / "evil.txt").exists() and not Path("/tmp/hexbench-evil.txt").exists()


def test_safe_extract_refuses_truncated_archive(tiny_build, tmp_path):
    good = pack_build(tiny_build, tmp_path / "good.tar.gz", "terrain-images-1.0.0").read_bytes()
    cut = tmp_path / "cut.tar.gz"
    cut.write_bytes(good[: len(good) // 2])
    with pytest.raises(ArchiveError, match="damaged archive"):
        safe_extract(cut, tmp_path / "out")
    assert not (tmp_path / "out").exists()


# ------------------------------------------------------------------------------ downloads


@pytest.fixture()
def server(tmp_path, monkeypatch):
    """Serve tmp_path/www on 127.0.0.1 (an ephemeral port); yields (www folder, base URL)."""
    monkeypatch.setenv("NO_PROXY", "127.0.0.1,localhost")
    monkeypatch.setenv("no_proxy", "127.0.0.1,localhost")
    www = tmp_path / "www"
    www.mkdir()

    class Quiet(http.server.SimpleHTTPRequestHandler):
        def log_message(self, *args):
            pass

    httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(Quiet, directory=str(www)))
    thread = threading.Thread(target=httpd.serve_forever, daemon=True)
    thread.start()
    yield www, f"http://127.0.0.1:{httpd.server_address[1]}"
    httpd.shutdown()
    httpd.server_close()


def _publish(tiny_build: Path, www: Path, base_url: str, tmp_path: Path, mangle=None) -> Path:
    """Pack the tiny build, serve it (optionally mangled), and write a registry for the good archive."""
    archive = pack_build(tiny_build, tmp_path / "dist" / "terrain-images-1.0.0.tar.gz", "terrain-images-1.0.0")
    entry = registry_entry_for(archive, "terrain-images", "1.0.0", (f"{base_url}/{archive.name}",))
    data = archive.read_bytes()
    (www / archive.name).write_bytes(mangle(data) if mangle else data)
    registry = tmp_path / "registry.toml"
    write_registry({"terrain-images": entry}, registry)
    return registry


def test_download_verifies_extracts_and_caches(tiny_build, server, tmp_path):
    www, url = server
    registry = _publish(tiny_build, www, url, tmp_path)
    cache = tmp_path / "cache"
    folder = download("terrain-images", registry_path=registry, cache_dir=cache)
    assert folder == cache / "terrain-images-1.0.0"
    assert _sha_map(folder) == _sha_map(tiny_build) and verify_build(folder) == []
    (www / "terrain-images-1.0.0.tar.gz").unlink()  # the second call must not need the network
    assert download("terrain-images", registry_path=registry, cache_dir=cache) == folder


def test_download_cli_honours_data_dir_env(tiny_build, server, tmp_path, monkeypatch):
    www, url = server
    registry = _publish(tiny_build, www, url, tmp_path)
    monkeypatch.setenv("HEXBENCH_DATA_DIR", str(tmp_path / "envcache"))
    result = CliRunner().invoke(app, ["dataset", "download", "terrain-images", "--registry", str(registry)])
    assert result.exit_code == 0, result.output
    assert (tmp_path / "envcache" / "terrain-images-1.0.0" / "manifest.json").is_file()


@pytest.mark.parametrize("mangle", [
    pytest.param(lambda d: d[:100] + bytes([d[100] ^ 0xFF]) + d[101:], id="tampered"),
    pytest.param(lambda d: d[: len(d) // 2], id="truncated"),
])
def test_download_refuses_bad_archive(tiny_build, server, tmp_path, mangle):
    www, url = server
    registry = _publish(tiny_build, www, url, tmp_path, mangle)
    cache = tmp_path / "cache"
    with pytest.raises(DownloadError, match="failed sha256 verification"):
        download("terrain-images", registry_path=registry, cache_dir=cache)
    assert not any(p.is_file() for p in cache.rglob("*")), "a bad download left files behind"
    result = CliRunner().invoke(app, ["dataset", "download", "terrain-images", "--registry", str(registry),
                                      "--data-dir", str(cache)])
    assert result.exit_code == 2
    last = result.output.strip().splitlines()[-1]  # (earlier lines: the download progress bar)
    assert last.startswith("error: archive from http://127.0.0.1") and "failed sha256 verification" in last


def test_download_refuses_unsafe_archive_even_with_matching_hash(server, tmp_path):
    www, url = server
    (www / "evil.tar.gz").write_bytes(_unsafe_archives()["leaves the destination"])
    entry = registry_entry_for(www / "evil.tar.gz", "terrain-images", "1.0.0", (f"{url}/evil.tar.gz",))
    write_registry({"terrain-images": entry}, tmp_path / "registry.toml")
    with pytest.raises(DownloadError, match="unsafe archive"):
        download("terrain-images", registry_path=tmp_path / "registry.toml", cache_dir=tmp_path / "cache")
    assert not (tmp_path / "evil.txt").exists() and not (tmp_path / "cache" / "terrain-images-1.0.0").exists()


def test_download_errors_are_one_clear_line(tmp_path, server):
    _, url = server
    entry = RegistryEntry("terrain-images", "1.0.0", "t.tar.gz", "0" * 64, 10, (f"{url}/missing.tar.gz",))
    write_registry({"terrain-images": entry}, tmp_path / "registry.toml")
    with pytest.raises(DownloadError, match="could not download 'terrain-images' from any mirror"):
        download("terrain-images", registry_path=tmp_path / "registry.toml", cache_dir=tmp_path / "c")
    with pytest.raises(DownloadError, match="registered: terrain-images"):
        download("other", registry_path=tmp_path / "registry.toml", cache_dir=tmp_path / "c")


def test_placeholder_mirror_is_named_as_such(tmp_path):
    entry = RegistryEntry("terrain-images", "1.0.0", "t.tar.gz", "0" * 64, 10, ("https://mirror.hexbench.invalid/t.tar.gz",))
    write_registry({"terrain-images": entry}, tmp_path / "registry.toml")
    with pytest.raises(DownloadError, match="placeholder .no public mirror yet.*HEXBENCH_DATASET_URL"):
        download("terrain-images", registry_path=tmp_path / "registry.toml", cache_dir=tmp_path / "c")


def test_publish_cli_prints_the_entry_of_a_deterministic_archive(tiny_build, tmp_path):
    args = ["dataset", "publish", "terrain-images", "--build", str(tiny_build), "--url", "http://127.0.0.1:1/x.tar.gz"]
    first = CliRunner().invoke(app, args + ["--out", str(tmp_path / "a")])
    second = CliRunner().invoke(app, args + ["--out", str(tmp_path / "b")])
    assert first.exit_code == 0, first.output
    archive = tmp_path / "a" / "terrain-images-1.0.0.tar.gz"
    import hashlib

    import tomllib

    entry = tomllib.loads(first.output.split("\n", 1)[1])["terrain-images"]
    assert entry["sha256"] == hashlib.sha256(archive.read_bytes()).hexdigest()
    assert entry["size_bytes"] == archive.stat().st_size and entry["urls"] == ["http://127.0.0.1:1/x.tar.gz"]
    assert (tmp_path / "b" / archive.name).read_bytes() == archive.read_bytes()
    assert first.output.split("\n", 1)[1] == second.output.split("\n", 1)[1]


def test_shipped_registry_is_well_formed():
    from hexbench.perception.dataset.registry import load_registry

    entry = load_registry()["terrain-images"]
    assert len(entry.sha256) == 64 and entry.size_bytes > 0 and entry.urls
    assert entry.archive == f"terrain-images-{entry.version}.tar.gz"


# ------------------------------------------------------------------------------ version 2: walk views

from hexbench.perception.dataset.walks import WALK_KINDS, WalkConfig, plan_walks  # noqa: E402

TINY_WALKS = WalkConfig(walks_per_terrain=2, mixed_walks=2, image_every_steps=60, max_steps_single=150,
                        max_steps_mixed=150)
TINY_V2 = BuildConfig(per_class=5, seed=3, version=2, walks=TINY_WALKS)


@pytest.fixture(scope="module")
def tiny_v2_build(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("ds2") / "terrain-images"
    build_terrain_images(out, TINY_V2)
    return out


def test_version_2_adds_walk_views_labelled_and_counted(tiny_v2_build, tiny_build):
    manifest = json.loads((tiny_v2_build / "manifest.json").read_text())
    assert manifest["version"] == "2.1.0" and verify_build(tiny_v2_build) == []
    walk_rows = [f for f in manifest["files"] if f["view_kind"] == "walk"]
    approach = [f for f in manifest["files"] if f["view_kind"] == "approach"]
    # the approach views are version 1's images, byte for byte
    assert {f["path"]: f["sha256"] for f in approach} == _sha_map(tiny_build)
    # 150 steps from a phase in [0, 60): 2 or 3 images per walk, 2 walks per kind
    assert {f["walk_kind"] for f in walk_rows} == set(WALK_KINDS) and 16 <= len(walk_rows) <= 24
    for f in walk_rows:
        assert f["path"].split("/")[:2] == [f["split"], f["label"]]
        if f["walk_kind"] == "mixed":
            from hexbench.world.terrain import mixed_segment_at

            assert f["label"] == mixed_segment_at(f["base_x_m"] + f["lookahead_m"])
        else:
            assert f["label"] == f["walk_kind"] and f["label_rule"] == "walk terrain"
    by_kind = manifest["counts_by_view_kind"]
    for split, per_label in manifest["counts"].items():
        for label, n in per_label.items():
            assert sum(kinds[label] for kinds in by_kind[split].values()) == n
    assert sum(by_kind["test"]["walk-mixed"].values()) > 0 or sum(by_kind["train"]["walk-mixed"].values()) > 0


def _stalling_stairs_walk(**rules) -> list:
    """Walk 1 of a two-walk stairs plan with its level raised to 10 cm, a riser the open-loop CPG
    cannot climb: it stalls in front of the first step."""
    from dataclasses import replace

    from hexbench.perception.dataset.walks import walk_images

    config = WalkConfig(walks_per_terrain=2, mixed_walks=0, image_every_steps=60, max_steps_single=1500, **rules)
    walk = replace([w for w in plan_walks(0, config) if w.kind == "stairs"][1], level=10.0)
    return list(walk_images(walk, config))


def test_a_stalled_walk_gives_no_near_identical_frames():
    every_frame = _stalling_stairs_walk(min_image_spacing_m=0.0, min_image_turn_deg=0.0)
    kept = _stalling_stairs_walk()
    assert max(i.base_x_m for i in every_frame) < 0.2  # it did stall in front of the first riser (x = 0.3 m)
    assert 0 < len(kept) <= len(every_frame) // 3
    for i, a in enumerate(kept):
        for b in kept[i + 1:]:
            turn = abs((b.heading_deg - a.heading_deg + 180) % 360 - 180)
            assert np.hypot(b.base_x_m - a.base_x_m, b.base_y_m - a.base_y_m) >= 0.03 or turn >= 5.0


def test_a_walk_stops_photographing_once_its_look_ahead_is_past_the_last_obstacle():
    from dataclasses import replace

    from hexbench.perception.dataset.walks import walk_images
    from hexbench.world.terrain import make_terrain

    config = WalkConfig(walks_per_terrain=1, mixed_walks=0, image_every_steps=60, max_steps_single=4000)
    walk = replace(next(w for w in plan_walks(0, config) if w.kind == "stairs"), level=2.0)
    end_x_m = make_terrain("stairs", 2.0).obstacle_end_x_m
    kept = list(walk_images(walk, config))
    every = list(walk_images(walk, replace(config, stop_past_obstacle=False)))
    assert max(i.base_x_m for i in every) + config.lookahead_m > end_x_m  # the walk itself went past it
    assert kept and all(i.base_x_m + config.lookahead_m <= end_x_m for i in kept)
    assert [i.step for i in kept] == [i.step for i in every][: len(kept)]


def test_version_2_is_reproducible(tiny_v2_build, tmp_path):
    again = tmp_path / "again"
    build_terrain_images(again, TINY_V2)
    assert (again / "manifest.json").read_bytes() == (tiny_v2_build / "manifest.json").read_bytes()


def test_walk_split_is_by_walk_without_leakage():
    walks = plan_walks(0, WalkConfig())
    for kind in WALK_KINDS:
        mine = [w for w in walks if w.kind == kind]
        test = [w for w in mine if w.split == "test"]
        assert len(test) == round(0.2 * len(mine))
        assert {w.episode_seed for w in test}.isdisjoint({w.episode_seed for w in mine if w.split == "train"})
    assert {w.episode_seed for w in plan_walks(1, WalkConfig())}.isdisjoint({w.episode_seed for w in walks})


def test_walk_seeds_are_not_protocol_episode_seeds():
    from hexbench.suite.tasks import load_suite

    suite = load_suite("v1")
    protocol = {s for t in suite.all_tasks for s in t.seeds()}
    assert protocol.isdisjoint({w.episode_seed for w in plan_walks(0, WalkConfig())})


def test_unknown_version_is_refused_with_the_valid_ones(tmp_path):
    result = CliRunner().invoke(app, ["dataset", "build", "terrain-images", "--version", "3",
                                      "--out", str(tmp_path / "x")])
    assert result.exit_code == 2 and "valid versions: 1, 2" in result.output
    assert list(tmp_path.iterdir()) == []


def test_registry_keeps_every_major_version_downloadable(tiny_build, tiny_v2_build, server, tmp_path):
    www, url = server
    entries = {}
    for build, version in ((tiny_build, "1.0.0"), (tiny_v2_build, "2.1.0")):
        archive = pack_build(build, tmp_path / "dist" / f"terrain-images-{version}.tar.gz", f"terrain-images-{version}")
        (www / archive.name).write_bytes(archive.read_bytes())
        entry = registry_entry_for(archive, "terrain-images", version, (f"{url}/{archive.name}",))
        entries[entry.key] = entry
    assert sorted(entries) == ["terrain-images", "terrain-images@2"]
    registry = tmp_path / "registry.toml"
    write_registry(entries, registry)
    cache = tmp_path / "cache"
    assert download("terrain-images", registry_path=registry, cache_dir=cache) == cache / "terrain-images-2.1.0"
    assert download("terrain-images", version=1, registry_path=registry, cache_dir=cache) == cache / "terrain-images-1.0.0"
    with pytest.raises(DownloadError, match="no registered version 3; registered versions: 1, 2"):
        download("terrain-images", version=3, registry_path=registry, cache_dir=cache)
