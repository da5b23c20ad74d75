"""Fit results (and anything holding numpy values) as what ``json.dumps`` takes."""

import os
from typing import Any

import numpy as np


def jsonable(value: Any) -> Any:
    """A copy of ``value`` that ``json.dumps`` takes: numpy arrays become (nested) lists, numpy
    scalars Python numbers, paths strings, tuples lists; dicts and lists are converted
    throughout. For a fit result or a list of batch results::

        json.dumps(gpmm.jsonable(fit))

    Images (a fit's ``overlay``, ``render``, ``working_image``) become long lists too: leave
    them out first if they are not wanted.
    """
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    return value
