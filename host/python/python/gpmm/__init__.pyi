from ._gpmm import (
    LIGHT_PRESETS as LIGHT_PRESETS,
    GpmmError as GpmmError,
    Model as Model,
    __version__ as __version__,
    build as build,
    import_h5 as import_h5,
    inspect as inspect,
    kernels as kernels,
    load as load,
    load_image as load_image,
    model_from_bytes as model_from_bytes,
    read_pts as read_pts,
)
from os import PathLike
from typing import Union

def export_h5(model: Model, path: Union[str, PathLike]) -> None: ...
