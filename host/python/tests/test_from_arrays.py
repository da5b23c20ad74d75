"""gpmm.Model.from_arrays: a model from numpy arrays round-trips through files, quantization
and fitting; a wrong array is named in the error."""

import numpy as np
import pytest

import gpmm
from conftest import FIT_FLAGS


@pytest.fixture(scope="module")
def model(small_model_path):
    return gpmm.load(small_model_path)


def arrays_of(m):
    return dict(
        shape_mean=m.shape_mean,
        triangles=m.triangles,
        shape_basis=m.shape_basis,
        shape_eigenvalues=m.shape_eigenvalues,
        color_mean=m.color_mean,
        color_basis=m.color_basis,
        color_eigenvalues=m.color_eigenvalues,
        landmarks=m.landmarks,
    )


def test_a_models_arrays_make_the_same_model(model, astronaut, tmp_path):
    made = gpmm.Model.from_arrays(**arrays_of(model), metadata={"kernel": "pca-of-mine", "units": "mm"})
    assert made.metadata["kernel"] == "pca-of-mine" and made.metadata["landmark_scheme"] == "ibug68"
    for name in ("shape_mean", "shape_basis", "color_mean", "color_basis", "triangles", "landmarks"):
        np.testing.assert_array_equal(getattr(made, name), getattr(model, name), err_msg=name)
    np.testing.assert_allclose(made.shape_eigenvalues, model.shape_eigenvalues, rtol=1e-12)
    # save / load
    path = tmp_path / "made.gpmm"
    made.save(path)
    assert gpmm.load(path) == made
    # quantize
    info = gpmm.inspect(made.quantize("m4f", vertices=500, rank_shape=10, rank_color=10))
    assert info["error"] is None
    # fit: the same numbers as the model the arrays came from (dense and factored bases are the same basis)
    img, pts = astronaut
    photo, points = gpmm.load_image(img), gpmm.read_pts(pts)
    a = made.fit(photo, points, **FIT_FLAGS)
    b = model.fit(photo, points, **FIT_FLAGS)
    np.testing.assert_allclose(a["shape"], b["shape"], rtol=0, atol=1e-3)
    assert abs(a["yaw_deg"] - b["yaw_deg"]) < 0.5


def test_a_pca_from_numpy(model):
    """A user's own PCA: orthonormal components and variances, shape only."""
    rng = np.random.default_rng(0)
    n = model.vertices
    q, _ = np.linalg.qr(rng.standard_normal((n * 3, 4)))
    components = q.T.reshape(4, n, 3)
    variances = np.array([9.0, 4.0, 1.0, 0.25])
    made = gpmm.Model.from_arrays(
        model.shape_mean,
        model.triangles,
        shape_basis=components * np.sqrt(variances)[:, None, None],
        shape_eigenvalues=variances,
        landmarks=model.landmarks,
    )
    assert (made.rank_shape, made.rank_color) == (4, 0)
    np.testing.assert_allclose(made.color_mean, 0.5)
    pos, _ = made.instance(shape=[1.0])
    np.testing.assert_allclose(pos, model.shape_mean + 3.0 * components[0], atol=1e-4)


def test_a_factored_basis(model):
    n = model.vertices
    fields = np.stack([np.linspace(0, 1, n), np.linspace(1, 0, n) * 0.5]).astype(np.float32)
    directions = np.array([[1, 0, 0], [0, 0, 1]], np.float32)
    made = gpmm.Model.from_arrays(model.shape_mean, model.triangles, shape_fields=fields, shape_directions=directions)
    assert made.layout[0] == "factored"
    np.testing.assert_allclose(made.shape_eigenvalues, (fields.astype(np.float64) ** 2).sum(axis=1), rtol=1e-6)
    np.testing.assert_allclose(made.shape_basis[0, :, 0], fields[0])


@pytest.mark.parametrize(
    "change, message",
    [
        ({"shape_mean": np.zeros((10, 2))}, r"shape_mean has shape \(10, 2\); expected \(N, 3\)"),
        ({"triangles": "T"}, "triangles must hold integer vertex ids"),
        ({"triangles": np.array([[0, 1, 99999]])}, "triangles refers to vertex 99999"),
        ({"triangles": np.array([[0.0, 1.0, 2.0]])}, "triangles must hold integer vertex ids, got dtype float64"),
        ({"landmarks": np.array([-1])}, "landmarks refers to vertex -1"),
        ({"shape_basis": np.zeros((3, 5, 3))}, r"shape_basis has shape \(3, 5, 3\); expected \(K, N, 3\)"),
        ({"color_basis": "x"}, "color_basis must be an array of numbers"),
        ({"color_mean": np.full((1, 3), np.nan)}, r"color_mean has shape \(1, 3\)"),
        ({"shape_eigenvalues": np.ones(20)}, r"shape_eigenvalues\[0\] = 1 but component 0 of shape_basis has squared norm"),
        ({"shape_eigenvalues": np.ones(3)}, r"shape_eigenvalues has shape \(3,\); expected \(K,\) with K = 20"),
        ({"shape_fields": np.zeros((2, 5))}, "give either shape_basis or shape_directions \\+ shape_fields, not both"),
        ({"metadata": {"kernal": "x"}}, "metadata has an unknown entry 'kernal'"),
    ],
)
def test_a_wrong_array_is_named(model, change, message):
    args = arrays_of(model)
    args.update(change)
    with pytest.raises(ValueError, match=message):
        gpmm.Model.from_arrays(**args)


def test_non_finite_values_and_order_are_refused(model):
    args = arrays_of(model)
    mean = model.color_mean.copy()
    mean[3, 1] = np.inf
    with pytest.raises(ValueError, match="color_mean has a non-finite value at flat index 10"):
        gpmm.Model.from_arrays(**{**args, "color_mean": mean})
    with pytest.raises(ValueError, match="descending order of eigenvalue"):
        gpmm.Model.from_arrays(model.shape_mean, model.triangles, shape_basis=model.shape_basis[::-1])
    with pytest.raises(ValueError, match=r"shape_directions\[1\] = .* is not a unit vector"):
        gpmm.Model.from_arrays(model.shape_mean, model.triangles, shape_fields=np.ones((2, model.vertices)),
                               shape_directions=np.array([[1, 0, 0], [0, 2, 0]]))
