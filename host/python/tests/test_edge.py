"""Faces at the photo's edge: landmarks a little outside the image are fitted, far-out ones are
refused with the same message as `gpmm fit`."""

import re

import numpy as np
import pytest

import gpmm


def test_a_chin_below_the_last_row_fits_and_a_far_point_is_refused(small_model_path, astronaut, run_cli, tmp_path):
    model = gpmm.load(small_model_path)
    img, pts = astronaut
    image, points = gpmm.load_image(img), gpmm.read_pts(pts)
    # Cut the photo a pixel or two above the chin point (landmark 8): it lies outside, within the margin.
    chip = np.ascontiguousarray(image[: int(points[8][1]) - 2])
    assert points[8][1] >= chip.shape[0] + 1
    fit = model.fit(chip, points, landmark_steps=200, image_steps=4, seed=1)
    # Accepted (it was refused before); the crop may still fit in the photo by moving up.
    assert 0.0 <= fit["crop_outside_fraction"] < 1.0
    assert np.isfinite(fit["landmark_rmse_px"])
    # Far outside: the same refusal as the program's (the line differs: the file has a header).
    far = points.copy()
    far[8] = [far[8][0], 5000.0]
    with pytest.raises(gpmm.GpmmError) as e:
        model.fit(chip, far, landmark_steps=10, image_steps=0)
    chip_ppm, far_pts = tmp_path / "chip.ppm", tmp_path / "far.pts"
    chip_ppm.write_bytes(f"P6 {chip.shape[1]} {chip.shape[0]} 255\n".encode() + chip.astype(np.uint8).tobytes())
    far_pts.write_text("version: 1\nn_points: 68\n{\n" + "".join(f"{x} {y}\n" for x, y in far) + "}\n")
    cli = run_cli("fit", small_model_path, chip_ppm, "--landmarks", far_pts, "-o", tmp_path / "out", check=False)
    assert cli.returncode != 0

    def refusal(text):
        m = re.search(r"landmark 8 \(0-based; line \d+\) (at .* lies outside the \d+x\d+ image by more than the margin of [\d.]+ px)", text)
        assert m, text
        return m.group(1)

    assert refusal(str(e.value)) == refusal(cli.stderr)
    assert "belong to this image" in str(e.value)
