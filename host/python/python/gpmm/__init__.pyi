from ._errors import (
    GpmmError as GpmmError,
    GpmmFileNotFoundError as GpmmFileNotFoundError,
    GpmmOSError as GpmmOSError,
    GpmmValueError as GpmmValueError,
)
from ._gpmm import (
    LIGHT_PRESETS as LIGHT_PRESETS,
    Model as Model,
    __version__ as __version__,
    build as build,
    data_dir as data_dir,
    detect as detect,
    import_h5 as import_h5,
    inspect as inspect,
    kernels as kernels,
    load as load,
    load_image as load_image,
    model_from_bytes as model_from_bytes,
    read_pts as read_pts,
)
from ._json import jsonable as jsonable
from ._learn import learn as learn
from os import PathLike
from typing import Union

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

def export_h5(model: Model, path: Union[str, PathLike[str]]) -> None: ...
