"""tests/realistic/population_mean.py on a small model: the mean becomes ICT's registered neutral
face, the landmarks and the prior change only when asked, every command reads the result, and a
file that is not a model is refused by name."""

import json
import subprocess
import sys

import numpy as np

from conftest import ROOT

SCRIPT = ROOT / "tests" / "realistic" / "population_mean.py"
sys.path.insert(0, str(ROOT / "tests" / "realistic"))
from landmark_definitions import model_tensor  # noqa: E402


def script(data_dir, *args, check=True):
    p = subprocess.run([sys.executable, str(SCRIPT), "--ict", str(data_dir / "ict"), *map(str, args)], capture_output=True, text=True)
    if check and p.returncode != 0:
        raise AssertionError(f"population_mean.py {' '.join(map(str, args))} failed:\n{p.stderr}")
    return p


def test_the_population_mean_replaces_the_mean_and_nothing_else_unless_asked(tmp_path, small_model_path, gpmm_bin, data_dir, run_cli):
    plain, marked = tmp_path / "world.gpmm", tmp_path / "world-lm.gpmm"
    script(data_dir, "make", small_model_path, "-o", plain, "--gpmm", gpmm_bin)
    script(data_dir, "make", small_model_path, "-o", marked, "--ict-landmarks", "--prior-scale", "0.5", "--gpmm", gpmm_bin)

    before = model_tensor(small_model_path, "shape.mean")
    after = model_tensor(plain, "shape.mean")
    moved = np.linalg.norm(after - before, axis=1)
    # Another face in the same frame: every vertex may move, but by face-sized amounts, not by a frame's.
    assert np.median(moved) > 0.5 and np.median(moved) < 15.0, np.median(moved)
    assert abs(after.mean(0) - before.mean(0)).max() < 1.0
    for name in ("shape.fields", "shape.eigenvalues", "landmarks", "color.mean"):
        assert np.array_equal(model_tensor(plain, name), model_tensor(small_model_path, name)), name

    assert np.array_equal(model_tensor(marked, "shape.mean"), after)
    assert np.allclose(model_tensor(marked, "shape.fields"), 0.5 * model_tensor(small_model_path, "shape.fields"))
    assert np.allclose(model_tensor(marked, "shape.eigenvalues"), 0.25 * model_tensor(small_model_path, "shape.eigenvalues"))
    lm = model_tensor(marked, "landmarks")
    assert not np.array_equal(lm, model_tensor(small_model_path, "landmarks")) and lm.max() < len(after)

    info = json.loads(run_cli("info", marked).stdout)
    assert info["vertices"] == len(after), info


def test_offsets_draws_and_measures_against_the_reference(tmp_path, small_model_path, gpmm_bin, data_dir):
    world = tmp_path / "world.gpmm"
    script(data_dir, "make", small_model_path, "-o", world, "--gpmm", gpmm_bin)
    png = tmp_path / "offsets.png"
    out = script(data_dir, "offsets", small_model_path, world, "--reference", world, "-o", png).stdout.splitlines()
    assert png.stat().st_size > 1000
    template, itself = (float(line.split("median ")[1].split(" mm")[0]) for line in out)
    assert template > 0.3 and itself == 0.0, out


def test_a_file_that_is_not_a_model_is_refused_by_name(tmp_path, gpmm_bin, data_dir):
    bad = tmp_path / "notes.gpmm"
    bad.write_bytes(b"\x04\x00\x00\x00\x00\x00\x00\x00{}  ")
    p = script(data_dir, "make", bad, "-o", tmp_path / "out.gpmm", "--gpmm", gpmm_bin, check=False)
    assert p.returncode != 0 and str(bad) in p.stderr and "tensor" in p.stderr, p.stderr
    assert not (tmp_path / "out.gpmm").exists()
