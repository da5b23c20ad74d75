"""tests/realistic/landmark_definitions.py on a small `gpmm synth` set: the model's landmarks land on
ICT's surface, the points it writes are the points it reports, and a set whose truth is not ICT's
projection is refused."""

import json
import subprocess
import sys

import pytest

from conftest import ROOT

SCRIPT = ROOT / "tests" / "realistic" / "landmark_definitions.py"


@pytest.fixture(scope="module")
def synth_set(tmp_path_factory, run_cli, data_dir):
    out = tmp_path_factory.mktemp("synth") / "set"
    t = data_dir / "template" / "lee-perry-smith"
    run_cli("synth", "--ict", data_dir / "ict", "--template-dir", t, "--count", "2", "--yaws", "0,30", "--seed", "5", "-o", out)
    return out


def script(data_dir, *args, check=True):
    p = subprocess.run([sys.executable, str(SCRIPT), "--ict", str(data_dir / "ict"), *map(str, args)], capture_output=True, text=True)
    if check and p.returncode != 0:
        raise AssertionError(f"landmark_definitions.py {' '.join(map(str, args))} failed:\n{p.stderr}")
    return p


def overall(report):
    """The 'all' row of a report: floor, then (vs truth, vs model points) per points directory."""
    row = next(line for line in report.splitlines() if line.split()[:1] == ["all"])
    return [float(v) for v in row.split()[2:]]


def test_transfer_report_and_write_agree(tmp_path, synth_set, small_model_path, gpmm_bin, data_dir):
    defs = tmp_path / "defs.json"
    albedo = tmp_path / "albedo.npy"
    p = script(data_dir, "transfer", small_model_path, "-o", defs, "--gpmm", gpmm_bin, "--albedo", albedo)
    assert "wrote" in p.stderr and albedo.is_file()
    d = json.loads(defs.read_text())
    assert len(d["ict_triangles"]) == 68 and all(abs(sum(w) - 1) < 1e-9 and min(w) >= -1e-12 for w in d["barycentric"])

    points = tmp_path / "points"
    script(data_dir, "write", synth_set, defs, points)
    assert len(list(points.glob("*.pts"))) == 4
    # The exact ICT points (the set's own .pts) and the written model points, each against both.
    floor, exact_truth, exact_model, model_truth, model_model = overall(script(data_dir, "report", synth_set, defs, synth_set, points).stdout)
    assert exact_truth == 0.0 and model_model == 0.0
    assert model_truth == floor and exact_model == floor
    # Two conventions of the same 68 points: apart, but by a fraction of the eye distance.
    assert 0.01 < floor < 0.2, floor


def test_a_set_that_is_not_icts_projection_is_refused(tmp_path, synth_set, small_model_path, gpmm_bin, data_dir):
    defs = tmp_path / "defs.json"
    script(data_dir, "transfer", small_model_path, "-o", defs, "--gpmm", gpmm_bin)
    moved = tmp_path / "moved"
    moved.mkdir()
    truth = json.loads((synth_set / "truth.json").read_text())
    truth["images"][0]["translation_mm"][0] += 5.0
    (moved / "truth.json").write_text(json.dumps(truth))
    p = script(data_dir, "report", moved, defs, check=False)
    assert p.returncode != 0 and "do not project onto the set's truth" in p.stderr, p.stderr
