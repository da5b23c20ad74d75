"""Fixtures of the gpmm package's tests: the data directory, the gpmm program and a small model.

The data directory ($GPMM_DATA, else ../shared/data beside the checkout) and the program
($GPMM_BIN, else target/release/gpmm of the checkout) must exist: a missing one fails the
tests, it never skips them.
"""

import json
import os
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[3]

# Short fits keep the suite quick; the CLI and the package get the same flags.
FIT_FLAGS = {"landmark_steps": 1000, "image_steps": 60, "seed": 3}


def cli_flags(settings):
    out = []
    for k, v in settings.items():
        out += [f"--{k.replace('_', '-')}", str(v)]
    return out


@pytest.fixture(scope="session")
def data_dir() -> Path:
    d = Path(os.environ.get("GPMM_DATA", ROOT.parent / "shared" / "data"))
    assert d.is_dir(), f"data directory {d} is missing (set GPMM_DATA)"
    return d


@pytest.fixture(scope="session")
def gpmm_bin() -> Path:
    b = Path(os.environ.get("GPMM_BIN", ROOT / "target" / "release" / "gpmm"))
    assert b.is_file(), f"the gpmm program {b} is missing (cargo build --release -p gpmm, or set GPMM_BIN)"
    return b


@pytest.fixture(scope="session")
def run_cli(gpmm_bin, data_dir):
    def run(*args, check=True):
        env = dict(os.environ, GPMM_DATA=str(data_dir))
        p = subprocess.run([str(gpmm_bin), *map(str, args)], capture_output=True, text=True, env=env)
        if check and p.returncode != 0:
            raise AssertionError(f"gpmm {' '.join(map(str, args))} failed:\n{p.stderr}")
        return p

    return run


@pytest.fixture(scope="session")
def template(data_dir):
    t = data_dir / "template" / "lee-perry-smith"
    return t / "lee-perry-smith.ply", t / "landmarks_ibug68.json"


BUILD = {"vertices": 1000, "rank_shape": 20, "rank_color": 20, "nystrom_points": 400}


@pytest.fixture(scope="session")
def small_model_path(tmp_path_factory, run_cli, template) -> Path:
    """A small symmetric-full model built by the gpmm program (1000 vertices, ranks 20/20)."""
    out = tmp_path_factory.mktemp("model") / "small.gpmm"
    ply, lm = template
    run_cli("build", "--template", ply, "--landmarks", lm, *cli_flags(BUILD), "-o", out)
    return out


@pytest.fixture(scope="session")
def demo_model_path(tmp_path_factory, run_cli, template) -> Path:
    """The demo's model (`gpmm demo` builds it with these options: symmetric-full, ranks 200/200,
    the whole cropped template), built by the gpmm program: about 10 s."""
    out = tmp_path_factory.mktemp("demo") / "model.gpmm"
    ply, lm = template
    run_cli("build", "--template", ply, "--landmarks", lm, "--kernel", "symmetric-full",
            "--rank-shape", "200", "--rank-color", "200", "-o", out)
    return out


@pytest.fixture(scope="session")
def astronaut(data_dir):
    img = data_dir / "images" / "astronaut.png"
    pts = data_dir / "images" / "astronaut.pts"
    assert img.is_file() and pts.is_file(), "astronaut.png / .pts missing from the data directory"
    return img, pts


@pytest.fixture(scope="session")
def cli_fit(tmp_path_factory, run_cli, small_model_path, astronaut):
    """fit.json of `gpmm fit` on the astronaut with FIT_FLAGS."""
    out = tmp_path_factory.mktemp("clifit")
    img, pts = astronaut
    run_cli("fit", small_model_path, img, "--landmarks", pts, *cli_flags(FIT_FLAGS), "--no-timing", "-o", out)
    return json.loads((out / "fit.json").read_text())


@pytest.fixture()
def photo_folder(tmp_path, data_dir):
    """Eight photos with their landmarks (the five 0-based ones, three repeated under new names)."""
    names = ["astronaut.png", "lenna.png", "obama.jpg", "obama2.jpg", "biden.jpg"]
    src = data_dir / "images"
    for i in range(8):
        name = names[i % len(names)]
        stem, ext = os.path.splitext(name)
        shutil.copy(src / name, tmp_path / f"p{i}_{stem}{ext}")
        shutil.copy(src / f"{stem}.pts", tmp_path / f"p{i}_{stem}.pts")
    return tmp_path
