"""The exceptions gpmm raises; every one is a :class:`GpmmError`, and its message is the one
the ``gpmm`` program prints for the same failure (each cause said once).

- :class:`GpmmFileNotFoundError` (also a ``FileNotFoundError``): a model, image, landmark,
  template or other input file that does not exist; ``filename`` names it.
- :class:`GpmmOSError` (also an ``OSError``): a file that exists but cannot be read or
  written (permissions, a directory, a missing output folder); ``filename`` names it.
- :class:`GpmmValueError` (also a ``ValueError``): a bad argument (the message names the
  parameter) or bad data in a file (the message names the file).
"""

import os
from typing import Optional, Tuple, Type


class GpmmError(Exception):
    """Base of every error gpmm raises; the message is the one the gpmm program prints."""


class GpmmValueError(GpmmError, ValueError):
    """A bad argument (the message names the parameter) or bad data in a file (it names the file)."""


class _FileError(GpmmError, OSError):
    """An OS error with the gpmm program's message (``str``) and ``errno`` / ``filename``."""

    def __init__(self, message: str, errno: Optional[int] = None, filename: Optional[str] = None) -> None:
        super().__init__(errno, os.strerror(errno) if errno is not None else message, filename)
        self.message = message

    def __str__(self) -> str:
        return self.message

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.message!r})"

    def __reduce__(self) -> Tuple[Type["_FileError"], Tuple[str, Optional[int], Optional[str]]]:
        return (type(self), (self.message, self.errno, self.filename))


class GpmmFileNotFoundError(_FileError, FileNotFoundError):
    """A file that does not exist (``filename`` names it)."""


class GpmmOSError(_FileError):
    """A file that exists but cannot be read or written (``filename`` names it)."""


# Shown as gpmm.GpmmError etc. (where users catch them), not gpmm._errors.GpmmError.
for _cls in (GpmmError, GpmmValueError, _FileError, GpmmFileNotFoundError, GpmmOSError):
    _cls.__module__ = "gpmm"
