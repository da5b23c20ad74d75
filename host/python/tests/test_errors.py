"""Pythonic errors: missing files are FileNotFoundError with .filename, bad arguments ValueError
naming the parameter, every error a gpmm.GpmmError whose message says its cause once."""

import pickle

import numpy as np
import pytest

import gpmm
from conftest import FIT_FLAGS


@pytest.fixture(scope="module")
def model(small_model_path):
    return gpmm.load(small_model_path)


@pytest.fixture(scope="module")
def photo(astronaut):
    img, pts = astronaut
    return gpmm.load_image(img), gpmm.read_pts(pts)


def missing_file_calls(model, photo, template, tmp_path):
    img, pts = photo
    ply, lm = template
    nope = tmp_path / "nope"
    return {
        "model": (lambda p: gpmm.load(p), nope.with_suffix(".gpmm")),
        "image": (lambda p: gpmm.load_image(p), nope.with_suffix(".png")),
        "landmark file": (lambda p: gpmm.read_pts(p), nope.with_suffix(".pts")),
        "template": (lambda p: gpmm.build(p, lm), nope.with_suffix(".ply")),
        "template landmarks": (lambda p: gpmm.build(ply, p), nope.with_suffix(".json")),
        "h5 model": (lambda p: gpmm.import_h5(p), nope.with_suffix(".h5")),
        "landmark calibration": (lambda p: model.fit(img, pts, landmark_calibration=p), nope.with_suffix(".cal.json")),
    }


@pytest.mark.parametrize(
    "what",
    ["model", "image", "landmark file", "template", "template landmarks", "h5 model", "landmark calibration"],
)
def test_a_missing_file_is_a_file_not_found_error_naming_it(what, model, photo, template, tmp_path):
    call, path = missing_file_calls(model, photo, template, tmp_path)[what]
    with pytest.raises(FileNotFoundError) as e:
        call(path)
    err = e.value
    assert isinstance(err, gpmm.GpmmError) and isinstance(err, OSError)
    assert err.filename == str(path) and err.errno == 2
    message = str(err)
    assert message.count(str(path)) == 1, message
    assert message.count("No such file or directory") == 1, f"the cause is said once: {message}"
    assert type(err).__module__ == "gpmm" and type(err).__name__ == "GpmmFileNotFoundError"
    again = pickle.loads(pickle.dumps(err))
    assert str(again) == message and again.filename == err.filename


def test_an_unreadable_file_is_an_os_error(tmp_path):
    with pytest.raises(OSError) as e:
        gpmm.load(tmp_path)  # a directory
    assert not isinstance(e.value, FileNotFoundError)
    assert isinstance(e.value, gpmm.GpmmOSError) and e.value.filename == str(tmp_path)


def test_a_missing_output_folder_is_a_file_not_found_error(model, tmp_path):
    target = tmp_path / "no-such-folder" / "m.gpmm"
    with pytest.raises(FileNotFoundError) as e:
        model.save(target)
    assert e.value.filename == str(target)


def test_bad_file_content_is_a_value_error_naming_the_file(tmp_path):
    bad = tmp_path / "bad.gpmm"
    bad.write_bytes(b"not a model")
    with pytest.raises(gpmm.GpmmValueError, match="bad.gpmm: not a gpmm model file"):
        gpmm.load(bad)
    with pytest.raises(ValueError):
        gpmm.load(bad)


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda m, i, p: m.fit(i, p, seed=-1), "seed must be a non-negative integer, got -1"),
        (lambda m, i, p: m.fit(i, p, seed=2**70), "seed = 1180591620717411303424 is too large"),
        (lambda m, i, p: m.fit(i, p, image_steps=-5), "image_steps must be a non-negative integer, got -5"),
        (lambda m, i, p: m.fit(i, p, set="landmarks.student_t=4"), 'set must be a list of "key=value" strings, not a str'),
        (lambda m, i, p: m.fit(i, p, set=["nonsense"]), "set: nonsense: expected PATH=VALUE"),
        (lambda m, i, p: m.fit(i, p, shape_rank=10000), "shape_rank = 10000 is more than the model's 20 components"),
        (lambda m, i, p: m.fit(i, p, color_rank=21), "color_rank = 21 is more than the model's 20 components"),
        (lambda m, i, p: m.fit(i.astype(np.float32), p), "image has dtype float32"),
        (lambda m, i, p: m.fit(i[..., 0], p), r"image has shape \(512, 512\)"),
        (lambda m, i, p: m.fit(i, p[:, :1]), r"landmarks have shape \(68, 1\)"),
        (lambda m, i, p: m.instance(shape=[float("nan")]), "shape\\[0\\] is NaN: coefficients must be finite"),
        (lambda m, i, p: m.instance(shape=[0.0], color=[1.0, float("inf")]), "color\\[1\\] is inf"),
        (lambda m, i, p: m.instance(shape=[0.0] * 21), "shape has 21 coefficients; the model has 20"),
        (lambda m, i, p: m.render(color=[float("nan")]), "color\\[0\\] is NaN"),
        (lambda m, i, p: m.render(width=-1), "width must be a non-negative integer"),
        (lambda m, i, p: m.sample(-1), "n must be a non-negative integer"),
        (lambda m, i, p: m.quantize("m4f", rank_shape=99), "rank_shape = 99 is more than the model's 20 components"),
        (lambda m, i, p: m.quantize("m9"), "profile: unknown profile 'm9'"),
    ],
)
def test_a_bad_argument_is_a_value_error_naming_the_parameter(model, photo, call, message):
    img, pts = photo
    with pytest.raises(ValueError, match=message) as e:
        call(model, img, pts)
    assert isinstance(e.value, gpmm.GpmmValueError)


def test_a_non_int_is_a_type_error_naming_the_parameter(model, photo):
    img, pts = photo
    with pytest.raises(TypeError, match="seed must be an int, got str"):
        model.fit(img, pts, seed="1")


def test_the_error_classes_show_as_gpmm_classes():
    for cls in (gpmm.GpmmError, gpmm.GpmmValueError, gpmm.GpmmFileNotFoundError, gpmm.GpmmOSError):
        assert cls.__module__ == "gpmm" and issubclass(cls, gpmm.GpmmError)
    assert issubclass(gpmm.GpmmFileNotFoundError, FileNotFoundError)
    assert issubclass(gpmm.GpmmValueError, ValueError)
    assert not issubclass(gpmm.GpmmFileNotFoundError, ValueError)


def test_rgba_is_fitted_as_its_rgb(model, photo):
    img, pts = photo
    alpha = np.full(img.shape[:2] + (1,), 9, np.uint8)
    rgba = np.concatenate([img, alpha], axis=2)
    a = model.fit(rgba, pts, **FIT_FLAGS)
    b = model.fit(img, pts, **FIT_FLAGS)
    np.testing.assert_array_equal(a["shape"], b["shape"])
    assert a["log_likelihood"] == b["log_likelihood"]


def test_data_dir_honours_gpmm_data(monkeypatch, data_dir, tmp_path):
    monkeypatch.setenv("GPMM_DATA", str(data_dir))
    assert gpmm.data_dir() == data_dir
    monkeypatch.setenv("GPMM_DATA", str(tmp_path / "absent"))
    with pytest.raises(FileNotFoundError, match="set GPMM_DATA") as e:
        gpmm.data_dir()
    assert e.value.filename == str(tmp_path / "absent")
