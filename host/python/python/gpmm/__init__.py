"""gpmm: Gaussian-process morphable face models from one scan, fitted to photos by MCMC.

The Python face of the gpmm Rust library: every function here runs the same code as the
``gpmm`` program (same settings, same seed, the same numbers), with the GIL released during
long work. Every error is a :class:`GpmmError` with the program's message: a missing file is
also a ``FileNotFoundError`` (``.filename`` names it), a bad argument or bad data also a
``ValueError``.

>>> import gpmm
>>> images = gpmm.data_dir() / "images"
>>> model = gpmm.load("face.gpmm")
>>> fit = model.fit(gpmm.load_image(images / "astronaut.png"), gpmm.read_pts(images / "astronaut.pts"), seed=0)
>>> fit["yaw_deg"], fit["shape"][:5], fit["overlay"].shape

See docs/python.md for the tour, :mod:`gpmm.batch` for fitting folders on a Dask cluster and
:func:`learn` for learning a model from unlabelled images (on a Dask cluster with ``client=``).
"""

from ._errors import GpmmError, GpmmFileNotFoundError, GpmmOSError, GpmmValueError
from ._gpmm import (
    LIGHT_PRESETS,
    Model,
    __version__,
    build,
    data_dir,
    detect,
    import_h5,
    inspect,
    kernels,
    load,
    load_image,
    model_from_bytes,
    read_pts,
)
from ._json import jsonable
from ._learn import learn


def export_h5(model: Model, path) -> None:
    """Writes ``model`` as a statismo ``.h5`` file (the same as ``model.export_h5(path)``)."""
    model.export_h5(path)


__all__ = [
    "LIGHT_PRESETS",
    "GpmmError",
    "GpmmFileNotFoundError",
    "GpmmOSError",
    "GpmmValueError",
    "Model",
    "__version__",
    "build",
    "data_dir",
    "detect",
    "export_h5",
    "import_h5",
    "inspect",
    "jsonable",
    "kernels",
    "learn",
    "load",
    "load_image",
    "model_from_bytes",
    "read_pts",
]
