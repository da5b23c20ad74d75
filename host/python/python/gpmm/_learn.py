"""Learning a model from unlabelled images (``gpmm learn``) from Python, its fits on this
machine's threads or on a Dask cluster.

The loop itself runs in the native module (the code ``gpmm learn`` runs); with a ``client``, each
iteration hands its views (every image, then its mirror image with ``mirror``) to the cluster,
one task per view. A worker loads each iteration's model from its file once (the files are
written to ``output``, so on a real cluster that folder, the images and the start model must be
on a file system all workers see); the init file's bytes are scattered once.
"""

from __future__ import annotations

import os
import threading
from typing import Any, Callable, Optional, Sequence, Union

from . import _gpmm
from ._gpmm import Model

PathLike = Union[str, "os.PathLike[str]"]

_models_lock = threading.Lock()
# The models this process loaded for learning fits, by (path, modification time, size): a file
# rewritten by a new run is loaded again. The last few only (one per iteration).
_models: dict[tuple[str, int, int], Model] = {}
_MODELS_KEPT = 2


def worker_model(path: str) -> Model:
    """The model file at ``path``, loaded once per process while it is unchanged (a Dask worker's cache)."""
    st = os.stat(path)
    key = (path, st.st_mtime_ns, st.st_size)
    with _models_lock:
        model = _models.get(key)
        if model is None:
            model = _gpmm.load(path)
            while len(_models) >= _MODELS_KEPT:
                del _models[next(iter(_models))]
            _models[key] = model
        return model


def wake_view(model_path: str, init: Optional[bytes], image: str, mirrored: bool,
              settings_json: str) -> tuple[str, Any, Any]:
    """One view's fit on whichever process runs it: :func:`gpmm._gpmm.learn_wake` with the model
    at ``model_path`` (cached per process)."""
    return _gpmm.learn_wake(worker_model(model_path), init, image, mirrored, settings_json)


class _ClusterWake:
    """The wake phase on a Dask client: one task per view, the init file's bytes scattered once
    (again only when a retrained one differs)."""

    def __init__(self, client: Any, progress: Optional[Callable[[dict[str, Any]], None]]) -> None:
        self.client = client
        self.progress = progress
        self.init: Optional[tuple[bytes, Any]] = None

    def __call__(self, iteration: int, model_path: str, init: Optional[bytes], settings_json: str,
                 views: list[tuple[str, bool]]) -> list[Any]:
        from distributed import as_completed

        shared = None
        if init is not None:
            if self.init is None or self.init[0] != init:
                self.init = (init, self.client.scatter(init, broadcast=True))
            shared = self.init[1]
        futures = [
            self.client.submit(wake_view, model_path, shared, image, mirrored, settings_json, pure=False)
            for image, mirrored in views
        ]
        for done, _ in enumerate(as_completed(futures), 1):
            if self.progress is not None:
                self.progress({"event": "fitting", "iteration": iteration, "done": done, "total": len(futures)})
        results: list[Any] = []
        for (image, _), future in zip(views, futures):
            if future.status == "finished":
                results.append(future.result())
            elif future.status == "error":
                # The task failed (its worker died, or it raised): the view is recorded as not fitted.
                error = future.exception()
                results.append(f"the cluster's task failed: {type(error).__name__}: {error}")
            else:
                raise RuntimeError(f"{image}: the cluster's task was {future.status}; the cluster failed")
        return results


def learn(model: PathLike, images: Union[PathLike, Sequence[PathLike]], output: PathLike, *,
          init: Optional[PathLike] = None, landmarks_dir: Optional[PathLike] = None,
          learn_landmarks: bool = False, iterations: int = 5,
          mirror: bool = False, keep_variance: Optional[float] = None, min_iou: Optional[float] = None,
          init_landmark_sigma: Optional[float] = None, shape_from_shading: bool = False,
          dev: Optional[PathLike] = None, dev_identities: Optional[int] = None,
          dev_max_identity_drop: Optional[float] = None, dev_landmarks_dir: Optional[PathLike] = None, data: Optional[PathLike] = None,
          jobs: Optional[int] = None, client: Optional[Any] = None,
          progress: Optional[Callable[[dict[str, Any]], None]] = None, **settings: Any) -> dict[str, Any]:
    """Learns a model from unlabelled images as ``gpmm learn`` does, with the same outputs in
    ``output`` (``model_N.gpmm``, ``iteration_N/records.json`` and pictures; a rerun continues
    after the last complete iteration).

    ``images``: image files or folders of them. ``init``: the init file (``gpmm train-init``)
    whose finder and initializer start every fit, or ``landmarks_dir`` with ``STEM.pts`` files;
    ``learn_landmarks``: each model takes the landmark vertices where those points lie.
    ``keep_variance``: the share of the previous model's covariance kept beside the fits' (the
    program's default when ``None``). ``dev_max_identity_drop``: the development check's allowed
    fall of rank-1 identification, in percentage points, for a model whose fits come closer (the
    program's default, 5, when ``None``). ``settings``: the fit settings ``Model.fit`` takes
    (``seed``, ``landmark_steps``, ``image_steps``, ``set`` ...), from ``gpmm learn``'s defaults (an
    image chain of 10000 steps that fits the shape as well, where ``Model.fit``'s has 600 and
    leaves the shape to the landmarks). ``client``: a ``distributed.Client`` whose workers fit the
    views (the same models as without it); ``None`` fits on ``jobs`` threads here (default all
    cores). ``progress``: called with a dict per event (``event`` is "fitting", "checking",
    "finished" or "reused").

    Returns ``kept`` (the model to use: the best on ``dev``, else the last), ``best`` (with
    ``dev``: ``output/model.gpmm``, its copy, as the program leaves it), ``model`` (the last one
    written) and ``iterations`` (each iteration's records.json as a dict: counts and a record
    per view saying whether it was accepted and why not).
    """
    paths = [images] if isinstance(images, (str, os.PathLike)) else list(images)
    wake_all = None if client is None else _ClusterWake(client, progress)
    fspath = (lambda p: None if p is None else os.fspath(p))
    return _gpmm.learn_run(
        os.fspath(model), [os.fspath(p) for p in paths], os.fspath(output), init=fspath(init),
        landmarks_dir=fspath(landmarks_dir), learn_landmarks=learn_landmarks, iterations=iterations, mirror=mirror,
        min_iou=min_iou, init_landmark_sigma=init_landmark_sigma, shape_from_shading=shape_from_shading,
        keep_variance=keep_variance, dev=fspath(dev), dev_landmarks_dir=fspath(dev_landmarks_dir),
        dev_identities=dev_identities, dev_max_identity_drop=dev_max_identity_drop, data=fspath(data), jobs=jobs,
        wake_all=wake_all, progress=progress, **settings)
