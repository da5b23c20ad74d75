"""The batch example: eight photos fitted on a local Dask cluster of two workers equal eight
sequential fits, with one model load per worker."""

import numpy as np
import pytest
from distributed import Client, LocalCluster

import gpmm.batch

SETTINGS = {"landmark_steps": 600, "image_steps": 20, "seed": 7}


@pytest.fixture(scope="module")
def client():
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        with Client(cluster) as c:
            yield c


def same(a, b):
    assert a["image"] == b["image"]
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


def test_a_photo_without_landmarks_is_an_error(tmp_path, small_model_path, photo_folder):
    (photo_folder / "extra.png").write_bytes((photo_folder / "p0_astronaut.png").read_bytes())
    with pytest.raises(FileNotFoundError, match="extra.pts"):
        gpmm.batch.fit_folder(small_model_path, photo_folder, **SETTINGS)
