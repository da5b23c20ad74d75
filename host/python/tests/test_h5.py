"""Statismo / scalismo `.h5` files: export read by h5py, round trips, a file written by h5py
that imports, renders and fits, and malformed files refused with the dataset named."""

import json

import h5py
import numpy as np
import pytest

import gpmm


@pytest.fixture(scope="module")
def model(small_model_path):
    return gpmm.load(small_model_path)


def test_export_has_the_statismo_datasets(model, small_model_path, run_cli, tmp_path):
    path = tmp_path / "m.h5"
    model.export_h5(path)
    n, t = model.vertices, len(model.triangles)
    with h5py.File(path, "r") as f:
        for part, k in (("shape", model.rank_shape), ("color", model.rank_color)):
            assert f[f"{part}/model/mean"].shape == (3 * n,)
            assert f[f"{part}/model/mean"].dtype == np.float32
            assert f[f"{part}/model/pcaBasis"].shape == (3 * n, k)
            assert f[f"{part}/model/pcaVariance"].shape == (k,)
            assert f[f"{part}/model/noiseVariance"].shape == ()
            assert int(f[f"{part}/version/majorVersion"][()]) == 0
            assert int(f[f"{part}/version/minorVersion"][()]) == 9
            assert f[f"{part}/representer/points"].shape == (3, n)
            assert f[f"{part}/representer/cells"].shape == (3, t)
            assert np.issubdtype(f[f"{part}/representer/cells"].dtype, np.integer)
        np.testing.assert_array_equal(f["shape/model/mean"][:], model.shape_mean.reshape(-1))
        np.testing.assert_array_equal(f["shape/representer/cells"][:].T, model.triangles)
        basis = f["shape/model/pcaBasis"][:].astype(np.float64)
        gram = basis.T @ basis
        np.testing.assert_allclose(gram, np.eye(model.rank_shape), atol=2e-3, err_msg="orthonormal columns")
        raw = f["metadata/landmarks/json"][()]
        landmarks = json.loads(raw.decode() if isinstance(raw, bytes) else raw)
        assert len(landmarks) == 68 and landmarks[0]["id"] == "ibug68.0"
        np.testing.assert_allclose(landmarks[30]["coordinates"], model.shape_mean[model.landmarks[30]], atol=1e-4)
    cli_path = tmp_path / "cli.h5"
    run_cli("export-h5", small_model_path, "-o", cli_path)
    assert cli_path.read_bytes() == path.read_bytes(), "the CLI and the package write the same file"


def test_round_trip_is_exact_to_float32(model, tmp_path):
    path = tmp_path / "rt.h5"
    gpmm.export_h5(model, path)
    back, report = gpmm.import_h5(path)
    assert report["landmarks"] == 68 and report["scale_mm_per_unit"] == 1.0
    assert back.layout == ("dense", "dense")
    np.testing.assert_array_equal(back.shape_mean, model.shape_mean)
    np.testing.assert_array_equal(back.color_mean, model.color_mean)
    np.testing.assert_array_equal(back.triangles, model.triangles)
    np.testing.assert_array_equal(back.landmarks, model.landmarks)
    np.testing.assert_array_equal(back.shape_eigenvalues, model.shape_eigenvalues.astype(np.float32))
    for a, b in ((model.shape_basis, back.shape_basis), (model.color_basis, back.color_basis)):
        np.testing.assert_array_equal(b, a)
    assert back.metadata == model.metadata


def write_statismo(path, model, *, nan=False, float_cells=False, drop=None, landmarks=True):
    """A statismo 0.9 file written by h5py as other tools write one (gzip, int32 cells)."""
    with h5py.File(path, "w") as f:
        for part, mean, basis, ev in (
            ("shape", model.shape_mean, model.shape_basis, model.shape_eigenvalues),
            ("color", model.color_mean, model.color_basis, model.color_eigenvalues),
        ):
            k = len(ev)
            unscaled = (basis.reshape(k, -1).T / np.sqrt(ev)[None, :]).astype(np.float32)
            m = mean.reshape(-1).copy()
            if nan and part == "shape":
                m[7] = np.nan
            data = {
                "model/mean": m,
                "model/pcaBasis": unscaled,
                "model/pcaVariance": ev.astype(np.float32),
                "model/noiseVariance": np.float32(0),
                "version/majorVersion": np.int32(0),
                "version/minorVersion": np.int32(9),
                "representer/points": model.shape_mean.T.astype(np.float32),
                "representer/cells": model.triangles.T.astype(np.float32 if float_cells else np.int32),
            }
            for name, value in data.items():
                if drop == f"{part}/{name}":
                    continue
                kw = {"compression": "gzip"} if np.ndim(value) > 1 else {}
                f.create_dataset(f"{part}/{name}", data=value, **kw)
            f[f"{part}/representer"].attrs["datasetType"] = "POLYGON_MESH"
        f.create_dataset("expression/model/mean", data=np.zeros(3, np.float32))
        if landmarks:
            lms = [{"id": f"ibug68.{i}", "coordinates": model.shape_mean[v].tolist()} for i, v in enumerate(model.landmarks)]
            f.create_dataset("metadata/landmarks/json", data=json.dumps(lms))


def test_an_h5py_statismo_file_loads_renders_and_fits(model, astronaut, run_cli, tmp_path):
    path = tmp_path / "other.h5"
    write_statismo(path, model)
    imported, report = gpmm.import_h5(path)
    assert report["units"].startswith("detected: millimetres")
    assert any("expression" in n for n in report["notes"])
    assert report["landmark_source"].startswith("metadata/landmarks/json")
    np.testing.assert_array_equal(imported.landmarks, model.landmarks)
    np.testing.assert_allclose(imported.shape_basis, model.shape_basis, atol=1e-4)
    img = imported.render(width=64, height=64)
    assert (img[..., :3].sum(axis=2) > 0).mean() > 0.2
    image, points = gpmm.load_image(astronaut[0]), gpmm.read_pts(astronaut[1])
    fit = imported.fit(image, points, landmark_steps=500, image_steps=20, seed=1)
    assert np.isfinite(fit["log_likelihood"]) and fit["landmark_rmse_original_px"] < 20
    # The CLI imports the same file into the same model.
    out = tmp_path / "cli.gpmm"
    run_cli("import-h5", path, "-o", out)
    assert gpmm.load(out) == imported
    # Quantizing the dense model keeps it dense and within the m4f budget.
    info = gpmm.inspect(imported.quantize("m4f"))
    assert info["error"] is None


def test_landmarks_absent_or_given(model, tmp_path):
    path = tmp_path / "nolm.h5"
    write_statismo(path, model, landmarks=False)
    m, report = gpmm.import_h5(path)
    assert report["landmarks"] == 0 and any("no landmarks" in n for n in report["notes"])
    with pytest.raises(gpmm.GpmmError, match="0 landmarks"):
        m.fit(np.zeros((64, 64, 3), np.uint8), np.zeros((0, 2)), landmark_steps=10, image_steps=0)
    lm = tmp_path / "lm.json"
    lm.write_text(json.dumps({"scheme": "ibug68", "vertex_ids": model.landmarks.tolist()}))
    m, _ = gpmm.import_h5(path, landmarks=lm)
    np.testing.assert_array_equal(m.landmarks, model.landmarks)


@pytest.mark.parametrize(
    "kw, dataset, words",
    [
        ({"nan": True}, "/shape/model/mean", "non-finite"),
        ({"float_cells": True}, "/shape/representer/cells", "integers"),
        ({"drop": "color/model/pcaBasis"}, "/color/model/pcaBasis", "missing"),
    ],
)
def test_malformed_files_are_refused(model, run_cli, tmp_path, kw, dataset, words):
    path = tmp_path / "bad.h5"
    write_statismo(path, model, **kw)
    with pytest.raises(gpmm.GpmmError) as e:
        gpmm.import_h5(path)
    assert dataset in str(e.value) and words in str(e.value)
    p = run_cli("import-h5", path, "-o", tmp_path / "x.gpmm", check=False)
    assert p.returncode == 1 and p.stderr.strip() == f"error: {e.value}"
