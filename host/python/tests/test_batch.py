"""The batch example: eight photos fitted on a local Dask cluster of two workers equal eight
sequential fits, with one model load per worker."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from distributed import Client, LocalCluster

import gpmm
import gpmm.batch

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "batch_fit.py"

SETTINGS = {"landmark_steps": 600, "image_steps": 20, "seed": 7}


@pytest.fixture(scope="module")
def client():
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        with Client(cluster) as c:
            yield c


def same(a, b):
    assert (a["name"], a["path"], a["image"]) == (b["name"], b["path"], b["image"])
    for k in ("yaw_deg", "pitch_deg", "roll_deg", "log_likelihood"):
        assert a[k] == b[k], (a["image"], k)
    for k in ("shape", "color", "light", "fitted_landmarks"):
        np.testing.assert_array_equal(a[k], b[k])


def test_fit_folder_on_dask_equals_sequential(client, small_model_path, photo_folder):
    sequential = gpmm.batch.fit_folder(small_model_path, photo_folder, **SETTINGS)
    assert len(sequential) == 8
    distributed = gpmm.batch.fit_folder(small_model_path, photo_folder, client=client, **SETTINGS)
    assert len(distributed) == 8
    for a, b in zip(sequential, distributed):
        same(a, b)
    loads = client.run(gpmm.batch.model_loads)
    assert sorted(loads.values()) == [1, 1], f"one model load per worker, got {loads}"
    # The same fits with the model object scattered to the workers (it pickles as bytes).
    scattered = gpmm.batch.fit_folder(gpmm.load(small_model_path), photo_folder, client=client, **SETTINGS)
    for a, b in zip(sequential, scattered):
        same(a, b)


def test_a_bad_photo_is_recorded_and_the_others_are_fitted(small_model_path, photo_folder):
    """A malformed .pts and an image that is not one each give a result that says why, a photo
    without landmarks is fitted from the face the shipped start finds; every other photo is fitted
    as in a folder without them."""
    clean = gpmm.batch.fit_folder(small_model_path, photo_folder, **SETTINGS)
    astronaut = (photo_folder / "p0_astronaut.png").read_bytes()
    (photo_folder / "a_no_points.png").write_bytes(astronaut)
    (photo_folder / "b_bad_points.png").write_bytes(astronaut)
    (photo_folder / "b_bad_points.pts").write_text("version: 1\nn_points: 68\n{\n1 2\n}\n")
    (photo_folder / "c_not_an_image.png").write_bytes(b"not a png")
    (photo_folder / "c_not_an_image.pts").write_bytes((photo_folder / "p0_astronaut.pts").read_bytes())
    try:
        results = gpmm.batch.fit_folder(small_model_path, photo_folder, **SETTINGS)
    finally:
        for name in ("a_no_points.png", "b_bad_points.png", "b_bad_points.pts", "c_not_an_image.png", "c_not_an_image.pts"):
            (photo_folder / name).unlink()
    by_name = {r["name"]: r for r in results}
    assert len(results) == len(clean) + 3
    unlabelled = by_name["a_no_points.png"]
    assert unlabelled["error"] is None and unlabelled["landmarks_file"] is None
    assert unlabelled["detected"]["landmarks"].shape == (68, 2), "the face the start found"
    assert "b_bad_points.pts" in by_name["b_bad_points.png"]["error"]
    assert "c_not_an_image.png" in by_name["c_not_an_image.png"]["error"]
    for want in clean:
        got = by_name[want["name"]]
        assert got["error"] is None and want["error"] is None
        same(got, want)
    # The errors are what json.dumps takes too.
    assert json.loads(json.dumps(gpmm.jsonable(results)))[1]["error"] == by_name["b_bad_points.png"]["error"]


def test_each_result_names_its_photo(small_model_path, photo_folder):
    """Every result carries its photo's name and path (not the "<array>" of a fit of arrays), and
    its numbers are those of fitting that photo on its own."""
    results = gpmm.batch.fit_folder(small_model_path, photo_folder, **SETTINGS)
    photos = sorted(p for p in os.listdir(photo_folder) if not p.endswith(".pts"))
    assert [r["name"] for r in results] == photos
    model = gpmm.load(small_model_path)
    for r in results[:3]:
        path = photo_folder / r["name"]
        assert r["path"] == r["image"] == str(path)
        assert r["landmarks_file"] == str(path.with_suffix(".pts"))
        alone = model.fit(gpmm.load_image(path), gpmm.read_pts(path.with_suffix(".pts")), **SETTINGS)
        assert r["yaw_deg"] == alone["yaw_deg"] and r["log_likelihood"] == alone["log_likelihood"], r["name"]
    # Photos that are not files: the names given come back.
    items = [(f"frame{i}", gpmm.load_image(photo_folder / r["name"]), gpmm.read_pts(photo_folder / (os.path.splitext(r["name"])[0] + ".pts")))
             for i, r in enumerate(results[:2])]
    from_arrays = gpmm.batch.fit_arrays(model, items, **SETTINGS)
    assert [(r["name"], r["image"], r["path"]) for r in from_arrays] == [("frame0", "frame0", None), ("frame1", "frame1", None)]
    assert from_arrays[1]["yaw_deg"] == results[1]["yaw_deg"]
    # The results are what json.dumps takes, through gpmm.jsonable.
    again = json.loads(json.dumps(gpmm.jsonable(results)))
    assert again[0]["name"] == photos[0] and again[0]["shape"] == results[0]["shape"].tolist()


def test_the_example_program_prints_one_json_line_per_photo(small_model_path, photo_folder):
    p = subprocess.run(
        [sys.executable, str(EXAMPLE), str(small_model_path), str(photo_folder), "--workers", "2",
         "--seed", "7", "--landmark-steps", "600", "--image-steps", "20"],
        capture_output=True, text=True, timeout=600,
    )
    assert p.returncode == 0, p.stderr
    lines = [json.loads(line) for line in p.stdout.splitlines() if line.strip()]
    sequential = gpmm.batch.fit_folder(small_model_path, photo_folder, **SETTINGS)
    assert [r["name"] for r in lines] == [r["name"] for r in sequential]
    for got, want in zip(lines, sequential):
        assert got["yaw_deg"] == want["yaw_deg"] and got["shape"] == want["shape"].tolist(), got["name"]
