"""gpmm: Gaussian-process morphable face models from one scan, fitted to photos by MCMC.

The Python face of the gpmm Rust library: every function here runs the same code as the
``gpmm`` program (same settings, same seed, the same numbers), with the GIL released during
long work. Errors are :class:`GpmmError` (a ``ValueError``) with the program's messages.

>>> import gpmm
>>> model = gpmm.load("face.gpmm")
>>> image = gpmm.load_image("photo.jpg"); points = gpmm.read_pts("photo.pts")
>>> fit = model.fit(image, points, seed=0)
>>> fit["yaw_deg"], fit["shape"][:5], fit["overlay"].shape

See docs/python.md for the tour and :mod:`gpmm.batch` for fitting folders on a Dask cluster.
"""

from ._gpmm import (
    LIGHT_PRESETS,
    GpmmError,
    Model,
    __version__,
    build,
    import_h5,
    inspect,
    kernels,
    load,
    load_image,
    model_from_bytes,
    read_pts,
)


def export_h5(model: Model, path) -> None:
    """Writes ``model`` as a statismo ``.h5`` file (the same as ``model.export_h5(path)``)."""
    model.export_h5(path)


__all__ = [
    "LIGHT_PRESETS",
    "GpmmError",
    "Model",
    "__version__",
    "build",
    "export_h5",
    "import_h5",
    "inspect",
    "kernels",
    "load",
    "load_image",
    "model_from_bytes",
    "read_pts",
]
