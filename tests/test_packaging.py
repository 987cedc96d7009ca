"""The package carries its scene files, configs and baked skies, and finds them from any folder.

``test_wheel_installs_and_runs_from_another_folder`` is the CI step of issue 27: it builds the
wheel from the tracked files (plus baked skies), installs it into a fresh virtual environment
that does not see the checkout, and runs a tiny quickstart, a path-traced ``make-dataset`` of one
image and ``compare`` from another folder.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import site
import subprocess
import sys
import tomllib
import venv
import zipfile
from pathlib import Path

import pytest

from mitsuba_platonic.files import resources
from mitsuba_platonic.config import ConfigError, config_file, load_config

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "mitsuba_platonic"


def test_package_data_are_the_top_level_folders():
    """In a checkout the package data are the repository's own folders (one source)."""
    assert resources.scenes_folder().resolve() == (ROOT / "scenes").resolve()
    assert resources.configs_folder().resolve() == (ROOT / "configs").resolve()
    assert resources.from_checkout()
    assert resources.sky_cache().resolve() == (ROOT / "scenes" / "envmaps").resolve()
    assert "quickstart" in resources.config_names()


def test_no_module_finds_data_relative_to_its_own_file():
    """Data are read through mitsuba_platonic.files.resources, never as ``../scenes`` next to a module."""
    offenders = [f"{p.relative_to(ROOT)}:{i}" for p in PACKAGE.rglob("*.py")
                 for i, line in enumerate(p.read_text().splitlines(), 1)
                 if re.search(r"Path\(__file__\)|os\.path\.dirname\(__file__\)", line)]
    assert not offenders, offenders


def test_package_data_patterns_cover_every_data_file():
    """Every file in scenes/ and configs/ that git tracks matches pyproject's package-data."""
    patterns = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]
    data = PACKAGE / "_data"
    globbed = {p.resolve() for pattern in patterns["mitsuba_platonic._data"] for p in data.glob(pattern)}
    tracked = [p for folder in ("scenes", "configs") for p in (ROOT / folder).rglob("*")
               if p.is_file() and p.suffix != ".exr"]
    assert tracked and all(p.resolve() in globbed for p in tracked), sorted(set(tracked) - globbed)


def test_configs_are_found_by_name_from_any_folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    for name in ("paper", "paper.yaml", "configs/paper.yaml"):
        assert config_file(name) == resources.configs_folder() / "paper.yaml"
    assert load_config("quickstart").model.resolution == 32
    (tmp_path / "paper.yaml").write_text("model:\n  resolution: 16\n")      # a file here comes first
    assert load_config("paper.yaml").model.resolution == 16
    with pytest.raises(ConfigError, match=r"'nope.yaml' does not exist \(packaged configs, .*paper"):
        config_file("nope.yaml")
    with pytest.raises(ConfigError, match="does not exist"):
        config_file("elsewhere/paper.yaml")                                  # a path is never replaced


def test_a_folder_named_like_a_packaged_config_does_not_hide_it(tmp_path, monkeypatch):
    """A run folder ``paper/`` (``run.out_dir=paper``) beside the command: ``--config paper`` is
    still the packaged config; a folder with no packaged config of its name is refused by name."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "paper").mkdir()
    (tmp_path / "mine").mkdir()
    assert config_file("paper") == resources.configs_folder() / "paper.yaml"
    with pytest.raises(ConfigError, match="'mine' is not a file"):
        config_file("mine")


def test_skies_missing_from_an_installed_package_bake_into_the_user_cache(tmp_path, monkeypatch):
    """An installed package (no checkout) may be read-only: skies it lacks go to the user's cache."""
    monkeypatch.setattr(resources, "from_checkout", lambda: False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert resources.sky_cache() == tmp_path / "mitsuba-platonic" / "envmaps"


# --------------------------------------------------------------------------- the wheel, installed


def _tracked_copy(dest: Path) -> Path:
    """The files git tracks (links kept as links) copied to ``dest``: a clean clone's tree."""
    listed = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
    for name in filter(None, listed.decode().split("\0")):
        src, dst = ROOT / name, dest / name
        dst.parent.mkdir(parents=True, exist_ok=True)
        if src.is_symlink():
            dst.symlink_to(os.readlink(src))
        elif src.is_file():
            shutil.copy2(src, dst)
    return dest


def _run(argv, cwd: Path, env=None, timeout: int = 300) -> str:
    done = subprocess.run([str(a) for a in argv], cwd=cwd, env=env, capture_output=True, text=True,
                          stdin=subprocess.DEVNULL, timeout=timeout)
    assert done.returncode == 0, f"{' '.join(map(str, argv))} → {done.returncode}\n{done.stdout}\n{done.stderr}"
    return done.stdout


def _build_wheel(tmp: Path) -> Path:
    """Bake the skies into a clean tree and build its wheel, as a release would."""
    src = _tracked_copy(tmp / "src")
    _run([sys.executable, "-m", "mitsuba_platonic.render.mitsuba.sky", "--out", src / "scenes" / "envmaps", "--width", "64"],
         cwd=tmp)
    _run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation", "-w", tmp / "dist", src],
         cwd=tmp)
    (wheel,) = (tmp / "dist").glob("mitsuba_platonic-*.whl")
    return wheel


def _fresh_env(tmp: Path, wheel: Path) -> Path:
    """A new virtual environment with the wheel installed. Its dependencies are this
    environment's, seen as plain folders (a .pth line), so neither this environment's ``.pth``
    files (the editable install's import hook) nor the checkout are on its path."""
    env = tmp / "env"
    venv.create(env, with_pip=True)
    python = env / "bin" / "python"
    _run([python, "-m", "pip", "install", "-q", "--no-deps", "--no-index", wheel], cwd=tmp)
    target = Path(_run([python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"], cwd=tmp).strip())
    deps = [p for p in site.getsitepackages() if Path(p).is_dir()]
    (target / "_dependencies.pth").write_text("\n".join(deps) + "\n")
    return env


@pytest.mark.slow
def test_wheel_installs_and_runs_from_another_folder(tmp_path):
    wheel = _build_wheel(tmp_path)
    names = zipfile.ZipFile(wheel).namelist()
    for name in ("scenes/raymarch_ea.xml", "scenes/physical.xml", "scenes/emitters/envmap.xml",
                 "scenes/envmaps/sunsky_elev35_turb3.exr", "configs/quickstart.yaml", "configs/paper.yaml"):
        assert f"mitsuba_platonic/_data/{name}" in names, name

    env = _fresh_env(tmp_path, wheel)
    work, cache = tmp_path / "elsewhere", tmp_path / "cache"
    work.mkdir()
    environ = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    environ.update(HOME=str(tmp_path / "home"), XDG_CACHE_HOME=str(cache))
    platonic = env / "bin" / "platonic"

    where = _run([env / "bin" / "python", "-c", "import mitsuba_platonic; print(mitsuba_platonic.__file__)"],
                 cwd=work, env=environ)
    assert Path(where.strip()).is_relative_to(env) and not Path(where.strip()).is_relative_to(ROOT), where

    # every packaged config resolves in the wheel as in the checkout: the parents its `extends:` names are there
    resolve = ("import json; from mitsuba_platonic.config import load_config; from mitsuba_platonic.files.resources "
               "import config_names; print(json.dumps({n: load_config(n, ['data.path=P']).to_dict() for n in config_names()}))")
    installed = json.loads(_run([env / "bin" / "python", "-c", resolve], cwd=work, env=environ))
    assert installed == {n: load_config(n, ["data.path=P"]).to_dict() for n in resources.config_names()}

    out = _run([platonic, "quickstart", "--out", "q", "--set", "run.steps=2", "--set", "model.resolution=16",
                "--set", "data.n_shapes=10", "--set", "data.views_per_shape=1", "--set", "train.batch_size=2"],
               cwd=work, env=environ)
    assert "2 steps" in out and (work / "q" / "report.md").is_file(), out

    out = _run([platonic, "make-dataset", "--class", "mushroom", "--shapes", "1", "--views", "1", "--resolution", "16",
                "--formation", "physical", "--spp", "1", "--max-depth", "2", "--lighting", "envmap", "--out", "d"],
               cwd=work, env=environ)
    assert "1 images in d" in out and (work / "d" / "images" / "00000_00.png").is_file(), out
    assert not (cache / "mitsuba-platonic").exists(), "the wheel carries the baked skies: none is baked on first use"

    out = _run([platonic, "compare", "--resolution", "16", "--views", "1", "--repeats", "1", "--out", "c"],
               cwd=work, env=environ)
    assert "closed form vs Mitsuba" in out and (work / "c" / "compare.json").is_file(), out
