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
    """The signature's defaults (written out for Python) are `gpmm detect`'s."""
    import inspect
    import re

    defaults = {k: v.default for k, v in inspect.signature(gpmm.detect).parameters.items()}
    help_text = " ".join(run_cli("detect", "--help").stdout.split())
    for flag, key in (("--min-score", "min_score"), ("--smallest-face", "smallest_face"), ("--refine", "refine")):
        shown = re.search(re.escape(flag) + r" .*?\[default: ([0-9.]+)\]", help_text)
        assert shown and float(shown.group(1)) == defaults[key], (flag, defaults[key])
