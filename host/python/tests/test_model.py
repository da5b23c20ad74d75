"""Models as numpy arrays, files, bytes and pickles; building, sampling, rendering, blobs."""

import pickle

import numpy as np
import pytest

import gpmm
from conftest import BUILD


@pytest.fixture(scope="module")
def model(small_model_path):
    return gpmm.load(small_model_path)


def test_arrays_have_documented_shapes(model):
    n = model.vertices
    assert n <= 1000 and model.rank_shape == 20 and model.rank_color == 20
    assert model.shape_mean.shape == (n, 3) and model.shape_mean.dtype == np.float32
    assert model.color_mean.shape == (n, 3)
    assert model.shape_basis.shape == (20, n, 3) and model.shape_basis.dtype == np.float32
    assert model.shape_eigenvalues.dtype == np.float64 and model.shape_eigenvalues.shape == (20,)
    assert model.triangles.shape[1] == 3 and model.triangles.dtype == np.uint32
    assert int(model.triangles.max()) < n
    assert model.landmarks.shape == (68,)
    assert model.layout == ("factored", "factored")
    assert model.metadata["kernel"] == "symmetric-full"
    assert model.info()["rank_shape"] == 20


def test_basis_reproduces_instances(model):
    a = np.linspace(-1, 1, 20).astype(np.float32)
    b = np.linspace(1, -1, 20).astype(np.float32)
    pos, col = model.instance(a, b)
    want = model.shape_mean + np.tensordot(a, model.shape_basis, axes=1)
    np.testing.assert_allclose(pos, want, rtol=0, atol=1e-3)
    np.testing.assert_allclose(col, np.clip(model.color_mean + np.tensordot(b, model.color_basis, axes=1), 0, 1), atol=1e-5)
    # Eigenvalues are the squared norms of the scaled basis vectors.
    norms = (model.shape_basis.astype(np.float64) ** 2).sum(axis=(1, 2))
    np.testing.assert_allclose(norms, model.shape_eigenvalues, rtol=1e-4)


def test_file_bytes_and_pickle_round_trip(model, tmp_path):
    path = tmp_path / "copy.gpmm"
    model.save(path)
    again = gpmm.load(path)
    assert again == model
    assert gpmm.model_from_bytes(model.to_bytes()) == model
    clone = pickle.loads(pickle.dumps(model))
    assert clone == model
    np.testing.assert_array_equal(clone.shape_basis, model.shape_basis)
    assert path.read_bytes() == model.to_bytes()


def test_build_matches_the_cli(model, template):
    ply, lm = template
    built = gpmm.build(ply, lm, kernel="symmetric-full", **BUILD)
    assert built.rank_shape == model.rank_shape
    # The same code and options: equal up to the last bits of the f64 eigen-solve, whose sums
    # depend on how many threads share them.
    np.testing.assert_allclose(built.shape_basis, model.shape_basis, rtol=0, atol=1e-6)
    np.testing.assert_allclose(built.color_basis, model.color_basis, rtol=0, atol=1e-6)
    np.testing.assert_allclose(built.color_eigenvalues, model.color_eigenvalues, rtol=1e-12)
    np.testing.assert_allclose(built.shape_eigenvalues, model.shape_eigenvalues, rtol=1e-12)
    assert built.metadata["template"] == model.metadata["template"]
    assert built.metadata["hyperparameters"] == model.metadata["hyperparameters"]
    assert sorted(gpmm.kernels()) == sorted(
        f"{a}-{b}" for a in ("standard", "symmetric", "correlated") for b in ("full", "rgb", "xyz")
    )


@pytest.mark.parametrize("kernel", ["standard-rgb", "correlated-xyz"])
def test_build_any_kernel(template, kernel):
    ply, lm = template
    m = gpmm.build(ply, lm, kernel=kernel, vertices=300, rank_shape=5, rank_color=5, nystrom_points=100)
    assert m.metadata["kernel"] == kernel and m.rank_shape == 5


def test_sample_and_render(model):
    s1 = model.sample(3, seed=5)
    s2 = model.sample(3, seed=5)
    assert len(s1) == 3
    for (p1, c1), (p2, c2) in zip(s1, s2):
        np.testing.assert_array_equal(p1, p2)
        np.testing.assert_array_equal(c1, c2)
    assert not np.array_equal(s1[0][0], s1[1][0])
    img = model.render(yaw=20, width=96, height=80, light="left")
    assert img.shape == (80, 96, 4) and img.dtype == np.uint8
    assert (img[..., :3].sum(axis=2) > 0).mean() > 0.2, "the face covers part of the image"
    img2 = model.render(yaw=20, width=96, height=80, light=[[0.5] * 3] + [[0.0] * 3] * 8)
    assert not np.array_equal(img, img2)


def test_render_matches_the_cli(model, small_model_path, run_cli, tmp_path):
    out = tmp_path / "r.png"
    run_cli("render", small_model_path, "--yaw", "15", "--size", "64x48", "-o", out)
    want = gpmm.load_image(out)
    got = model.render(yaw=15, width=64, height=48)
    np.testing.assert_array_equal(got[..., :3], want)


def test_quantize_and_inspect(model):
    blob = model.quantize("m4f", vertices=500, rank_shape=10, rank_color=10)
    info = gpmm.inspect(blob)
    assert info["error"] is None
    assert info["crc_ok"] is True
    bad = bytearray(blob)
    bad[len(bad) // 2] ^= 0xFF
    with pytest.raises(gpmm.GpmmError, match="not a valid model blob"):
        gpmm.inspect(bytes(bad))
    assert gpmm.inspect(bytes(bad), strict=False)["error"]


def test_errors_carry_the_cli_message(model, run_cli, tmp_path):
    missing = tmp_path / "nope.gpmm"
    p = run_cli("info", missing, check=False)
    assert p.returncode == 1
    cli_message = p.stderr.strip().removeprefix("error: ")
    with pytest.raises(gpmm.GpmmError) as e:
        gpmm.load(missing)
    assert str(e.value) == cli_message
    assert str(e.value).count("os error 2") == 1, "the cause is said once"
    assert isinstance(e.value, FileNotFoundError) and e.value.filename == str(missing)
    with pytest.raises(gpmm.GpmmError, match="unknown light 'dusk'"):
        model.render(light="dusk")
    with pytest.raises(gpmm.GpmmError, match="uint8"):
        model.fit(np.zeros((10, 10, 3), np.float32), np.zeros((68, 2)))
