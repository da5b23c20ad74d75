"""A fit from Python equals `gpmm fit` on the same photo, landmarks, settings and seed."""

import json

import numpy as np
import pytest

import gpmm
from conftest import FIT_FLAGS


@pytest.fixture(scope="module")
def py_fit(small_model_path, astronaut):
    model = gpmm.load(small_model_path)
    img, pts = astronaut
    return model.fit(gpmm.load_image(img), gpmm.read_pts(pts), **FIT_FLAGS)


def assert_same_fit(py_fit, cli_fit):
    for key in ("yaw_deg", "pitch_deg", "roll_deg", "focal_px", "log_likelihood", "pixel_rmse", "covered_pixels"):
        assert py_fit[key] == cli_fit[key], key
    for key in ("shape", "color", "light", "translation_mm", "fitted_landmarks", "photo_pose_deg"):
        np.testing.assert_array_equal(np.asarray(py_fit[key], np.float32), np.array(cli_fit[key], np.float32), err_msg=key)
    assert py_fit["acceptance"] == cli_fit["acceptance"]
    for key in ("shape_mean", "color_mean", "color_sd"):
        np.testing.assert_array_equal(np.asarray(py_fit["posterior"][key], np.float32), np.array(cli_fit["posterior"][key], np.float32), err_msg=key)


def test_demo_model_default_fit_matches_the_cli(demo_model_path, astronaut, run_cli, tmp_path):
    """The demo model, the astronaut, gpmm fit's defaults (seed 0, 5000 + 600 steps, 200 + 50 components)."""
    img, pts = astronaut
    run_cli("fit", demo_model_path, img, "--landmarks", pts, "--no-timing", "-o", tmp_path)
    cli = json.loads((tmp_path / "fit.json").read_text())
    model = gpmm.load(demo_model_path)
    fit = model.fit(gpmm.load_image(img), gpmm.read_pts(pts))
    assert fit["fitted_ranks"] == [200, 50] and fit["landmark_steps"] == 5000 and fit["image_steps"] == 600
    assert_same_fit(fit, cli)


def test_fit_matches_the_cli(py_fit, cli_fit):
    assert_same_fit(py_fit, cli_fit)
    assert py_fit["crop"] == cli_fit["crop"]


def test_fit_outputs(py_fit):
    assert py_fit["shape"].shape == (20,) and py_fit["shape"].dtype == np.float32
    assert py_fit["light"].shape == (9, 3)
    assert py_fit["fitted_landmarks"].shape == (68, 2)
    assert py_fit["working_image"].shape == (128, 128, 3)
    assert py_fit["render"].shape == (128, 128, 4)
    assert py_fit["overlay"].ndim == 3 and py_fit["overlay"].shape[2] == 4
    assert py_fit["landmark_rmse_original_px"] < 15.0, "the fit follows the landmarks"
    assert py_fit["acceptance"]["image_chain"], "the image chain ran"
    post = py_fit["posterior"]
    assert post["samples"] > 0 and post["color_mean"].shape == py_fit["color"].shape
    assert post["shape_sd"].dtype == np.float32 and (post["shape_sd"] >= 0).all()
    # The translation's intervals around the fit's, the distance's the widest.
    t, sd = py_fit["translation_mm"], post["translation_sd_mm"]
    for k in range(3):
        lo, hi = post["translation_interval_90_mm"][k]
        assert sd[k] > 0 and lo < t[k] < hi, (k, post)
    assert sd[2] > sd[0]
    # The shape's spread from the landmarks, per coefficient and per vertex along its normal.
    assert (post["shape_sd"] > 0).any() and (post["shape_sd"] <= 1 + 1e-6).all()
    mesh = py_fit["mesh"]
    sd = mesh["vertex_sd_mm"]
    assert sd.shape == (mesh["vertices"].shape[0],) and sd.dtype == np.float32
    assert (sd >= 0).all() and np.isclose(np.median(sd), post["vertex_sd_mm"]["median"], rtol=0.01)
    # The angles' intervals: around the mean, the 90 % one wider than the 50 % one, and wider
    # than the chain's own spread says (the landmarks' residuals widen them).
    assert post["landmark_residual_px"] > 0
    for k in range(3):
        mean, sd, chain = post["angles_mean_deg"][k], post["angles_sd_deg"][k], post["angles_chain_sd_deg"][k]
        (lo50, hi50), (lo90, hi90) = post["angles_interval_50_deg"][k], post["angles_interval_90_deg"][k]
        assert lo90 < lo50 < mean < hi50 < hi90, (k, post)
        assert abs((hi90 - lo90) - 2 * 1.645 * sd) < 1e-3 * max(1.0, sd)
        assert sd > chain >= 0


def test_fit_settings_and_errors(small_model_path, astronaut, tmp_path):
    model = gpmm.load(small_model_path)
    img, pts = astronaut
    image, points = gpmm.load_image(img), gpmm.read_pts(pts)
    with pytest.raises(gpmm.GpmmError, match="68"):
        model.fit(image, points[:10], landmark_steps=10, image_steps=0)
    with pytest.raises(gpmm.GpmmError, match="outside"):
        model.fit(image, points + 1000, landmark_steps=10, image_steps=0)
    with pytest.raises(gpmm.GpmmError, match="no.such"):
        model.fit(image, points, set=["no.such=1"])
    # A detector calibration (here: every point 0.2 inter-ocular distances to the right) is removed
    # from the landmarks first; a broken file is refused with its name.
    cal = tmp_path / "det.cal.json"
    cal.write_text(json.dumps({"format": "gpmm-landmark-calibration", "version": 1, "detector": "test", "degree": 0,
                               "turn_range": [-1.0, 1.0], "offsets": [[[0.2, 0.0]]] * 68,
                               "training": {"images": 0, "median_rms_px_before": 0.0, "median_rms_px_after": 0.0}}))
    plain = model.fit(image, points, landmark_steps=300, image_steps=0)
    moved = model.fit(image, points, landmark_steps=300, image_steps=0, landmark_calibration=str(cal))
    assert moved["landmark_calibration"] == str(cal) and "landmark_calibration" not in plain
    iod = float(np.linalg.norm(points[45] - points[36]))
    shift = float(np.mean(moved["fitted_landmarks"][:, 0] - plain["fitted_landmarks"][:, 0]))
    assert shift > 0.1 * iod, (shift, iod)
    broken = tmp_path / "broken.json"
    broken.write_text("{}")
    with pytest.raises(gpmm.GpmmError, match="broken.json"):
        model.fit(image, points, landmark_steps=10, image_steps=0, landmark_calibration=str(broken))
    a = model.fit(image, points, landmark_steps=200, image_steps=5, seed=1, set=["image.pixel_sigma=0.05"])
    b = model.fit(image, points, landmark_steps=200, image_steps=5, seed=2)
    assert a["shape"].tolist() != b["shape"].tolist(), "seeds and settings reach the fit"


def test_a_fit_gives_its_face_as_a_mesh_in_camera_space(small_model_path, py_fit):
    """The fit's mesh is the fitted instance moved rigidly by the fitted pose: the same colours,
    every distance between vertices kept, the centre where the translation puts it."""
    model = gpmm.load(small_model_path)
    fit = py_fit
    mesh = fit["mesh"]
    positions, colors = model.instance(fit["shape"], fit["color"])
    n = model.vertices
    assert mesh["vertices"].shape == (n, 3) and mesh["vertices"].dtype == np.float32
    tri = mesh["triangles"]
    assert tri.ndim == 2 and tri.shape[1] == 3 and len(tri) > n and tri.dtype == np.uint32 and tri.max() < n
    np.testing.assert_array_equal(mesh["colors"], colors)
    # A rigid motion: pairwise distances (a sample of pairs) are those of the model-space instance.
    rng = np.random.default_rng(0)
    a, b = rng.integers(0, n, 200), rng.integers(0, n, 200)
    moved = np.linalg.norm(mesh["vertices"][a] - mesh["vertices"][b], axis=1)
    rest = np.linalg.norm(positions[a] - positions[b], axis=1)
    np.testing.assert_allclose(moved, rest, rtol=1e-4, atol=1e-3)
    # In front of the camera, about the translation's distance away, and not the model-space instance.
    assert (mesh["vertices"][:, 2] > 0).all() or (mesh["vertices"][:, 2] < 0).all()
    assert abs(np.linalg.norm(mesh["vertices"].mean(axis=0)) - np.linalg.norm(fit["translation_mm"])) < 0.2 * np.linalg.norm(fit["translation_mm"])
    assert not np.allclose(mesh["vertices"], positions)


def test_an_occlusion_aware_fit_labels_a_painted_occluder(small_model_path, astronaut):
    """With occlusion rounds, a magenta bar painted over the eyes is left to the non-face model:
    the result's `occluded` labels cover most of it in the working image, and fit.json's
    `occluded_fraction` says how much of the face that is; without rounds neither is there."""
    model = gpmm.load(small_model_path)
    img, pts = astronaut
    image, points = np.array(gpmm.load_image(img)), gpmm.read_pts(pts)
    eyes = points[36:48]
    (x0, y0), (x1, y1) = eyes.min(axis=0), eyes.max(axis=0)
    pad = 0.15 * (x1 - x0)
    box = (int(y0 - pad), int(y1 + pad), int(x0 - pad), int(x1 + pad))
    image[box[0]:box[1], box[2]:box[3]] = [230, 40, 200]
    plain = model.fit(image, points, landmark_steps=300, image_steps=30, seed=3)
    assert "occluded" not in plain and "occluded_fraction" not in plain
    fit = model.fit(image, points, landmark_steps=300, image_steps=30, seed=3, set=["occlusion.rounds=2"])
    labels = fit["occluded"]
    side = fit["working_image"].shape[0]
    assert labels.shape == (side, side) and labels.dtype == bool
    assert 0.02 < fit["occluded_fraction"] < 0.6, fit["occluded_fraction"]
    # The bar in working pixels: the crop maps photo pixels to the working image.
    magenta = np.all(np.abs(fit["working_image"].astype(int) - [230, 40, 200]) < 40, axis=2)
    assert magenta.sum() > 50
    assert labels[magenta].mean() > 0.7, labels[magenta].mean()
    assert labels[~magenta].mean() < 0.2, labels[~magenta].mean()
    # The same labels on the photo: the painted bar itself, in the photo's pixels.
    photo = fit["occluded_photo"]
    assert photo.shape == image.shape[:2] and photo.dtype == bool
    bar = np.zeros(image.shape[:2], dtype=bool)
    bar[box[0]:box[1], box[2]:box[3]] = True
    assert photo[bar].mean() > 0.7, photo[bar].mean()
    assert photo[~bar].mean() < 0.05, photo[~bar].mean()
    assert fit["overlay"].shape[1] > plain["overlay"].shape[1], "the overlay has a fourth panel"
