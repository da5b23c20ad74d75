"""gpmm.detect lists the faces `gpmm detect` lists, with the same numbers."""

import json

import numpy as np
import pytest

import gpmm


@pytest.fixture(scope="module")
def init_file(tmp_path_factory, run_cli, small_model_path):
    """A landmark-free start trained for a few seconds (it finds the astronaut's face, roughly)."""
    out = tmp_path_factory.mktemp("init") / "quick.init"
    run_cli("train-init", small_model_path, "--quick", "-o", out)
    return out


def test_detect_lists_the_faces_the_program_lists(init_file, astronaut, run_cli):
    img, _ = astronaut
    faces = gpmm.detect(gpmm.load_image(img), init_file, face_check=False)
    listed = json.loads(run_cli("detect", img, "--init", init_file, "--no-face-check").stdout)["faces"]
    assert len(faces) == len(listed) >= 1
    for got, want in zip(faces, listed):
        assert got["box"] == want["box"]
        assert (got["yaw_deg"], got["pitch_deg"], got["roll_deg"]) == (want["yaw_deg"], want["pitch_deg"], want["roll_deg"])
        assert got["landmarks"].shape == (68, 2) and got["landmarks"].dtype == np.float32
        np.testing.assert_array_equal(got["landmarks"], np.array(want["landmarks"], np.float32))


def test_detect_refuses_what_is_not_an_image_or_an_init_file(init_file, tmp_path):
    with pytest.raises(gpmm.GpmmValueError, match="uint8"):
        gpmm.detect(np.zeros((4, 4), np.float32), init_file)
    with pytest.raises(gpmm.GpmmFileNotFoundError):
        gpmm.detect(np.zeros((8, 8, 3), np.uint8), tmp_path / "missing.init")
    bad = tmp_path / "bad.init"
    bad.write_bytes(b"GPMI" + bytes(60))
    with pytest.raises(gpmm.GpmmError, match="bad.init"):
        gpmm.detect(np.zeros((8, 8, 3), np.uint8), bad)


def test_detect_defaults_are_the_programs(run_cli):
    """The signature's defaults (written out for Python) are `gpmm detect`'s: the shipped start
    and its advised score when none is given."""
    import inspect
    import re

    defaults = {k: v.default for k, v in inspect.signature(gpmm.detect).parameters.items()}
    help_text = " ".join(run_cli("detect", "--help").stdout.split())
    for flag, key in (("--smallest-face", "smallest_face"), ("--refine", "refine")):
        shown = re.search(re.escape(flag) + r" .*?\[default: ([0-9.]+)\]", help_text)
        assert shown and float(shown.group(1)) == defaults[key], (flag, defaults[key])
    assert defaults["init"] is None and defaults["min_score"] is None
    assert "0.9" in help_text and "shipped start" in help_text


def test_without_an_init_file_the_shipped_start_finds_both_faces(run_cli):
    """gpmm.detect(image) uses the start gpmm ships, as `gpmm detect IMAGE` does: both faces of
    the shared two-person photo, the same boxes."""
    path = gpmm.data_dir() / "images" / "two_people.jpg"
    faces = gpmm.detect(gpmm.load_image(path))
    listed = json.loads(run_cli("detect", path).stdout)["faces"]
    assert len(faces) == len(listed) == 2
    for got, want in zip(faces, listed):
        assert got["box"] == want["box"] and got["box"]["score"] >= 0.9


def test_fit_without_landmarks_fits_the_face_the_start_finds(small_model_path, astronaut):
    """Model.fit(image) finds the face with the shipped start and fits it; its 'detected' face
    lies on the photo's own landmarks."""
    img, pts = astronaut
    model = gpmm.load(small_model_path)
    fit = model.fit(gpmm.load_image(img), landmark_steps=300, image_steps=20)
    truth = gpmm.read_pts(pts)
    eyes = np.linalg.norm(truth[36:42].mean(0) - truth[42:48].mean(0))
    error = np.linalg.norm(fit["detected"]["landmarks"] - truth, axis=1).mean() / eyes
    assert error < 0.15, f"the start's landmarks are {error:.3f} eye distances off"
    with pytest.raises(gpmm.GpmmValueError, match="face=5"):
        model.fit(gpmm.load_image(img), face=5, landmark_steps=300, image_steps=20)
