"""Fitting a folder of photos on a Dask cluster (``distributed``), one model load per worker.

>>> from distributed import Client, LocalCluster
>>> import gpmm.batch
>>> with LocalCluster(n_workers=2, threads_per_worker=1) as cluster, Client(cluster) as client:
...     results = gpmm.batch.fit_folder("face.gpmm", "photos/", client=client, image_steps=300)

Every image ``NAME.png`` / ``.jpg`` / ``.jpeg`` / ``.ppm`` is fitted with the landmark file
``NAME.pts`` beside it, or, without one, from the face the start gpmm ships finds (the largest;
as ``gpmm fit PHOTO``; its result's ``detected`` holds the face). Each fit is the same deterministic fit as ``gpmm fit`` with the same
settings and seed, so the results equal sequential fits (``client=None``). Each result names its
photo: ``name`` (the file name), ``path`` and ``image`` (its path), ``landmarks_file``, and
``error``: ``None``, or, for a photo that could not be fitted (no face found in it, an
unreadable image, a malformed ``.pts``, landmarks the fit refuses), the message saying why; one
bad photo loses nothing of the others. :func:`gpmm.jsonable` makes the results what
``json.dumps`` takes.

The model reaches the workers in one of two ways: a *path* (every worker loads it once, from a
file system all workers see) or a :class:`gpmm.Model` (scattered once to every worker; it
pickles through its model-file bytes). Photos are read by the workers from their paths, so on
a real cluster the folder must be on a shared file system (or pass arrays yourself to
:func:`fit_arrays`).
"""

from __future__ import annotations

import os
import threading
from pathlib import Path
from typing import Any, Iterable, Optional, Union

from . import GpmmError, Model, load, load_image, read_pts

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".ppm")

_cache_lock = threading.Lock()
_cache: dict[str, Model] = {}
_loads = 0


def worker_model(path: str) -> Model:
    """The model at ``path``, loaded at most once per process (a Dask worker's cache)."""
    global _loads
    with _cache_lock:
        model = _cache.get(path)
        if model is None:
            model = load(path)
            _cache[path] = model
            _loads += 1
        return model


def model_loads() -> int:
    """How many times this process loaded a model file through :func:`worker_model`."""
    return _loads


def find_photos(folder: Union[str, os.PathLike]) -> list[tuple[str, Optional[str]]]:
    """The (image, landmarks) path pairs of a folder, sorted by name; the landmarks are ``None``
    for an image without a ``.pts`` beside it (its result says so). A folder without images is
    an error."""
    pairs: list[tuple[str, Optional[str]]] = []
    for p in sorted(Path(folder).iterdir()):
        if p.suffix.lower() in IMAGE_SUFFIXES:
            pts = p.with_suffix(".pts")
            pairs.append((str(p), str(pts) if pts.is_file() else None))
    if not pairs:
        raise FileNotFoundError(f"{folder}: no images ({', '.join(IMAGE_SUFFIXES)}) in it")
    return pairs


# A fit's large fields: kept in a batch's results only when asked for.
LARGE = ("overlay", "render", "working_image", "mesh")


def _summary(name: str, path: Optional[str], landmarks: Optional[str], fit: dict[str, Any],
             keep_images: bool) -> dict[str, Any]:
    """A fit's fields (its images and mesh only with ``keep_images``) named after the photo: the fit of an
    array calls its image and landmarks ``<array>``, which the photo's own names replace."""
    out = {k: v for k, v in fit.items() if keep_images or k not in LARGE}
    out["name"] = name
    out["path"] = path
    out["image"] = path if path is not None else name
    out["landmarks_file"] = landmarks
    out["error"] = None
    return out


def fit_file(model: Union[str, Model], image: str, landmarks: Optional[str], pts_one_based: bool = False,
             keep_images: bool = False, **settings: Any) -> dict[str, Any]:
    """Fits one photo (on whichever process runs it); ``model`` is a path (cached per process) or a
    Model; ``landmarks`` ``None``: the shipped start finds the face. A photo that cannot be fitted
    (no face found, a bad image or ``.pts``, refused data) gives a result with its ``error``
    instead of raising, so a batch goes on."""
    name = os.path.basename(image)
    m = worker_model(model) if isinstance(model, str) else model
    try:
        points = None if landmarks is None else read_pts(landmarks, pts_one_based)
        fit = m.fit(load_image(image), points, **settings)
    except GpmmError as e:
        return _failed(name, image, landmarks, f"{image}: {e}" if landmarks is None else str(e))
    return _summary(name, image, landmarks, fit, keep_images)


def _failed(name: str, path: str, landmarks: Optional[str], error: str) -> dict[str, Any]:
    """The result of a photo that could not be fitted: its names and why."""
    return {"name": name, "path": path, "image": path, "landmarks_file": landmarks, "error": error}


def fit_folder(model_path: Union[str, os.PathLike, Model], folder: Union[str, os.PathLike],
               client: Optional[Any] = None, *, pts_one_based: bool = False, keep_images: bool = False,
               **settings: Any) -> list[dict[str, Any]]:
    """Fits every photo of ``folder`` (see :func:`find_photos`) with ``Model.fit``'s settings.

    ``client``: a ``distributed.Client`` (a ``LocalCluster`` here, a scheduler address in
    production); ``None`` fits sequentially in this process. Results come back in file-name
    order: fit.json's fields (pose, coefficients, light, fitted landmarks, log-likelihood,
    acceptance, ...) with ``name`` (the photo's file name), ``path`` and ``image`` (its path),
    ``landmarks_file`` and ``error`` (``None``); the images (``overlay`` ...) and the ``mesh`` only
    with ``keep_images=True``. A photo that could not be fitted has only its names and ``error``.
    """
    pairs = find_photos(folder)
    model: Union[str, Model] = model_path if isinstance(model_path, Model) else os.fspath(model_path)
    if client is None:
        return [fit_file(model, i, p, pts_one_based, keep_images, **settings) for i, p in pairs]
    if isinstance(model, Model):
        model = client.scatter(model, broadcast=True)
    futures = [
        client.submit(fit_file, model, i, p, pts_one_based, keep_images, pure=False, **settings)
        for i, p in pairs
    ]
    return client.gather(futures)


def fit_arrays(model: Model, items: Iterable[tuple[str, Any, Any]], client: Optional[Any] = None,
               **settings: Any) -> list[dict[str, Any]]:
    """Fits (name, image array, landmarks array) items: for photos that are not files the workers
    see. Each result has ``name`` and ``image`` set to the item's name (``path`` is ``None``)."""
    items = list(items)
    if client is None:
        return [_fit_array(model, n, img, pts, **settings) for n, img, pts in items]
    shared = client.scatter(model, broadcast=True)
    futures = [client.submit(_fit_array, shared, n, img, pts, pure=False, **settings) for n, img, pts in items]
    return client.gather(futures)


def _fit_array(model: Model, name: str, image: Any, landmarks: Any, **settings: Any) -> dict[str, Any]:
    return _summary(name, None, None, model.fit(image, landmarks, **settings), False)
