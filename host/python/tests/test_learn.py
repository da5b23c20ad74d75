"""gpmm.learn: the learning loop of `gpmm learn` from Python, its fits on this process's threads or
on a local Dask cluster of two workers, with the same models byte for byte and the same records;
an unreadable image is recorded, not fatal; a failed task is recorded for its image; bad inputs
are errors naming the file."""

import json
import os
import sys

import cloudpickle

import numpy as np
import pytest
from distributed import Client, LocalCluster

import gpmm
import gpmm._learn

# Short fits (those of `gpmm learn --quick`), mirror images, one iteration.
LEARN = {"iterations": 1, "mirror": True, "landmark_steps": 1500, "image_steps": 40, "seed": 5}
# What differs between two runs of the same fits: timings and the output folder.
VARYING = ("seconds", "model")


@pytest.fixture(scope="module")
def inputs(tmp_path_factory, run_cli, data_dir, template):
    """A tiny model, its quick init file, and a folder of four renders of two identities (yaw 0 and
    30) with a broken "image" among them; built as the program's own learn test builds them."""
    d = tmp_path_factory.mktemp("learn")
    ply, lm = template
    images = d / "images"
    run_cli("synth", "--ict", data_dir / "ict", "--template-dir", ply.parent, "--count", "2", "--yaws", "0,30",
            "--seed", "9", "-o", images)
    (images / "broken.png").write_bytes(b"not a png")
    model = d / "tiny.gpmm"
    run_cli("build", "--template", ply, "--landmarks", lm, "--vertices", "600", "--rank-shape", "10",
            "--rank-color", "10", "--nystrom-points", "300", "-o", model)
    init = d / "quick.init"
    # Plain scenes: a quick training's initializer does not learn to read past looks and occluders
    # (with them it put one render's points on a single spot), and these tests need every render
    # read; they exercise the loop, not the finder.
    run_cli("train-init", model, "--quick", "--plain-looks", "--no-occluders", "-o", init)
    return model, images, init


@pytest.fixture(scope="module")
def client():
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        with Client(cluster) as c:
            yield c


def without(d, keys=VARYING):
    return {k: v for k, v in d.items() if k not in keys}


def same_iteration(a, b):
    assert without(a, VARYING + ("records",)) == without(b, VARYING + ("records",))
    assert len(a["records"]) == len(b["records"])
    for ra, rb in zip(a["records"], b["records"]):
        assert without(ra) == without(rb), ra["image"]


def test_a_local_cluster_learns_the_models_of_the_local_run(tmp_path, inputs, client, run_cli):
    model, images, init = inputs
    heard = []
    local = gpmm.learn(model, images, tmp_path / "local", init=init, progress=heard.append, **LEARN)
    # This process's threads report every view (in the order they finish), then the iteration.
    assert sorted(e["done"] for e in heard if e["event"] == "fitting") == list(range(1, 11))
    assert heard[-1]["event"] == "finished" and heard[-1]["model"] == local["model"]
    # The program's run with the same settings (its --quick fits) writes the same model.
    run_cli("learn", model, images, "--init", init, "--quick", "--mirror", "--seed", LEARN["seed"], "-o", tmp_path / "cli")
    assert (tmp_path / "cli" / "model_1.gpmm").read_bytes() == (tmp_path / "local" / "model_1.gpmm").read_bytes()
    same_iteration(json.loads((tmp_path / "cli" / "iteration_1" / "records.json").read_text()), local["iterations"][0])
    events = []
    remote = gpmm.learn(model, images, tmp_path / "dask", init=init, client=client, progress=events.append, **LEARN)
    assert local["model"] == str(tmp_path / "local" / "model_1.gpmm")
    assert remote["model"] == remote["kept"] == str(tmp_path / "dask" / "model_1.gpmm")
    assert (tmp_path / "local" / "model_1.gpmm").read_bytes() == (tmp_path / "dask" / "model_1.gpmm").read_bytes()
    for out in ("local", "dask"):
        assert (tmp_path / out / "iteration_1" / "samples.png").is_file()
        assert (tmp_path / out / "iteration_1" / "reconstructions.png").is_file()
    on_disk = [json.loads((tmp_path / out / "iteration_1" / "records.json").read_text()) for out in ("local", "dask")]
    same_iteration(*on_disk)
    # What gpmm.learn returns is what it wrote.
    assert local["iterations"] == [on_disk[0]] and remote["iterations"] == [on_disk[1]]
    it = on_disk[1]
    # Four renders and the broken file, each then its mirror image, in file-name order.
    assert it["images"] == 10 and [r["mirrored"] for r in it["records"]] == [False, True] * 5
    broken = [r for r in it["records"] if r["image"].endswith("broken.png")]
    assert len(broken) == 2 and all(not r["accepted"] and "broken.png" in r["reason"] for r in broken), broken
    assert it["accepted"] >= 2 and it["failed"] == 2, without(it, ("records",))
    # The cluster's progress: every view, then the finished iteration.
    fitting = [e for e in events if e["event"] == "fitting"]
    assert [e["done"] for e in fitting] == list(range(1, 11)) and all(e["total"] == 10 for e in fitting)
    assert events[-1]["event"] == "finished" and events[-1]["accepted"] == it["accepted"]
    # The learned model is a model like any other.
    learned = gpmm.load(remote["model"])
    assert learned.vertices == gpmm.load(model).vertices and learned.metadata["learning"]["iteration"] == 1
    # A rerun reuses the complete iteration.
    again = gpmm.learn(model, images, tmp_path / "dask", init=init, client=client, **LEARN)
    assert again["iterations"] == remote["iterations"]


def test_shape_from_shading_on_a_local_cluster_learns_the_local_model(tmp_path, inputs, client):
    """Shape from shading's bases, prepared once per worker and model, give the local run's fits."""
    model, images, init = inputs
    runs = [gpmm.learn(model, images, tmp_path / out, init=init, shape_from_shading=True, client=c, **LEARN)
            for out, c in (("local", None), ("dask", client))]
    assert (tmp_path / "local" / "model_1.gpmm").read_bytes() == (tmp_path / "dask" / "model_1.gpmm").read_bytes()
    same_iteration(runs[0]["iterations"][0], runs[1]["iterations"][0])
    assert all(r["albedo_change"] is not None for r in runs[1]["iterations"][0]["records"] if r["accepted"])
    assert runs[1]["iterations"][0]["max_albedo_change"] is not None
    # Each worker prepared the bases once for its model (none before: no other test shades).
    prepared = client.run(gpmm._gpmm.learn_shading_preparations)
    assert sorted(prepared.values()) == [1, 1], prepared


def test_a_development_set_keeps_the_programs_best(tmp_path, inputs, client, run_cli, data_dir, template):
    """With dev=, the cluster's run measures each model on the set as the program does, and
    output/model.gpmm is the same best model."""
    model, images, init = inputs
    dev = tmp_path / "dev"
    run_cli("synth", "--ict", data_dir / "ict", "--template-dir", template[0].parent, "--count", "2", "--yaws", "0,30",
            "--seed", "10", "-o", dev)
    settings = dict(LEARN, mirror=False)
    out = gpmm.learn(model, images, tmp_path / "py", init=init, dev=dev, data=data_dir, client=client, **settings)
    run_cli("learn", model, images, "--init", init, "--quick", "--seed", LEARN["seed"], "--dev", dev, "--data", data_dir,
            "-o", tmp_path / "cli")
    development = out["iterations"][0]["development"]
    cli = json.loads((tmp_path / "cli" / "iteration_1" / "records.json").read_text())["development"]
    # The same figures (the learned model's file is named after each run's folder).
    for c in (development, cli):
        c["learned"].pop("model")
    assert without(development, ("best_model",)) == without(cli, ("best_model",)), (development, cli)
    assert development["learned"]["fits"] >= 3, development
    assert 0.0 <= development["learned"]["rank1"] <= 1.0 and development["learned"]["probes"] >= 1, development
    assert out["best"] == str(tmp_path / "py" / "model.gpmm")
    assert (tmp_path / "py" / "model.gpmm").read_bytes() == (tmp_path / "cli" / "model.gpmm").read_bytes()
    assert (tmp_path / "py" / "model.gpmm").read_bytes() == open(out["kept"], "rb").read()


def _fail_mirror_of(name):
    """Makes this worker's fit of the mirror image of `name` fail as a crashed task would."""
    real = gpmm._gpmm

    class Shim:
        def __getattr__(self, attr):
            return getattr(real, attr)

        @staticmethod
        def learn_wake(model, init, image, mirrored, settings_json):
            if mirrored and image.endswith(name):
                raise RuntimeError("worker lost its disk")
            return real.learn_wake(model, init, image, mirrored, settings_json)

    gpmm._learn._gpmm = Shim()


def _restore():
    gpmm._learn._gpmm = gpmm._gpmm


def test_a_failed_task_is_recorded_for_its_image(tmp_path, inputs, client):
    model, images, init = inputs
    first = sorted(p.name for p in images.iterdir() if p.suffix == ".png" and p.name != "broken.png")[0]
    # The shim travels to the workers by value (this test module is not importable there).
    cloudpickle.register_pickle_by_value(sys.modules[__name__])
    client.run(_fail_mirror_of, first)
    try:
        out = gpmm.learn(model, images, tmp_path / "out", init=init, client=client, **LEARN)
    finally:
        client.run(_restore)
    records = out["iterations"][0]["records"]
    failed = [r for r in records if r["image"].endswith(first) and r["mirrored"]]
    assert len(failed) == 1, (first, [r["image"] for r in records])
    assert not failed[0]["accepted"] and "RuntimeError: worker lost its disk" in failed[0]["reason"], failed
    assert out["iterations"][0]["failed"] == 3


def test_bad_inputs_are_errors_naming_them(tmp_path, inputs):
    model, images, init = inputs
    with pytest.raises(FileNotFoundError) as e:
        gpmm.learn(tmp_path / "no-such.gpmm", images, tmp_path / "a", init=init, **LEARN)
    assert e.value.filename == str(tmp_path / "no-such.gpmm")
    with pytest.raises(FileNotFoundError, match="no such image or directory") as e:
        gpmm.learn(model, [images / "nope.png"], tmp_path / "b", init=init, **LEARN)
    assert e.value.filename == str(images / "nope.png")
    with pytest.raises(FileNotFoundError) as e:
        gpmm.learn(model, images, tmp_path / "c", init=tmp_path / "no.init", **LEARN)
    assert e.value.filename == str(tmp_path / "no.init")
    with pytest.raises(gpmm.GpmmValueError, match="init"):
        gpmm.learn(model, images, tmp_path / "d", **LEARN)
    with pytest.raises(gpmm.GpmmValueError, match="min_iou"):
        gpmm.learn(model, images, tmp_path / "e", init=init, min_iou=2.0, **LEARN)
    with pytest.raises(gpmm.GpmmValueError, match="dev_max_identity_drop"):
        gpmm.learn(model, images, tmp_path / "g", init=init, dev_max_identity_drop=-1.0, **LEARN)
    with pytest.raises(gpmm.GpmmValueError, match="learn_landmarks needs landmarks_dir"):
        gpmm.learn(model, images, tmp_path / "h", init=init, learn_landmarks=True, **LEARN)
    with pytest.raises(TypeError, match="no_such_setting"):
        gpmm.learn(model, images, tmp_path / "f", init=init, no_such_setting=1, **LEARN)


def test_a_worker_keeps_each_model_file_once(tmp_path, inputs):
    model, _, _ = inputs
    a = gpmm._learn.worker_model(str(model))
    assert gpmm._learn.worker_model(str(model)) is a
    copy = tmp_path / "copy.gpmm"
    copy.write_bytes(model.read_bytes())
    b = gpmm._learn.worker_model(str(copy))
    assert b is not a and b == a
    # A file rewritten in place is loaded again.
    copy.write_bytes(gpmm.load(model).to_bytes())
    st = os.stat(copy)
    os.utime(copy, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000))
    assert gpmm._learn.worker_model(str(copy)) is not b
    np.testing.assert_array_equal(gpmm._learn.worker_model(str(copy)).shape_mean, a.shape_mean)
