"""Type stubs of gpmm's native module (gpmm._gpmm)."""

from os import PathLike
from pathlib import Path
from typing import Any, Callable, Mapping, Optional, Sequence, Tuple, Union, final

import numpy as np
import numpy.typing as npt

_Path = Union[str, PathLike[str]]
_Light = Union[str, Sequence[Sequence[float]]]

__all__ = [
    "LIGHT_PRESETS",
    "Model",
    "__version__",
    "build",
    "data_dir",
    "detect",
    "import_h5",
    "inspect",
    "kernels",
    "learn_run",
    "learn_shading_preparations",
    "learn_wake",
    "load",
    "load_image",
    "model_from_bytes",
    "read_pts",
]
__version__: str
LIGHT_PRESETS: list[str]

@final
class Model:
    """A morphable model: shape (mm) and albedo (linear RGB), bases, triangles, landmarks, metadata.

    Immutable. Pickles through its model-file bytes, so it travels to worker processes.
    """

    @staticmethod
    def load(path: _Path) -> Model:
        """Loads a model file (.gpmm)."""
    @staticmethod
    def from_bytes(data: bytes) -> Model:
        """A model from the bytes of a model file."""
    @staticmethod
    def from_arrays(
        shape_mean: npt.ArrayLike,
        triangles: npt.ArrayLike,
        *,
        shape_basis: Optional[npt.ArrayLike] = None,
        shape_eigenvalues: Optional[npt.ArrayLike] = None,
        shape_directions: Optional[npt.ArrayLike] = None,
        shape_fields: Optional[npt.ArrayLike] = None,
        color_mean: Optional[npt.ArrayLike] = None,
        color_basis: Optional[npt.ArrayLike] = None,
        color_eigenvalues: Optional[npt.ArrayLike] = None,
        color_directions: Optional[npt.ArrayLike] = None,
        color_fields: Optional[npt.ArrayLike] = None,
        landmarks: Optional[npt.ArrayLike] = None,
        metadata: Optional[Mapping[str, Any]] = None,
    ) -> Model:
        """A model from numpy arrays (mean, dense or factored bases, eigenvalues, triangles, colours,
        landmarks, metadata); a wrong array is named in the error (docs/python.md)."""
    def save(self, path: _Path) -> None:
        """Writes the model file (safetensors, docs/model-format.md)."""
    def to_bytes(self) -> bytes:
        """The model file's bytes."""
    def __reduce__(self) -> Tuple[Any, Tuple[bytes]]: ...
    def __eq__(self, other: object, /) -> bool: ...
    @property
    def vertices(self) -> int:
        """Number of vertices N."""
    @property
    def rank_shape(self) -> int:
        """Number of shape components."""
    @property
    def rank_color(self) -> int:
        """Number of colour components."""
    @property
    def layout(self) -> Tuple[str, str]:
        """Basis layouts of shape and colour: 'factored' or 'dense'."""
    @property
    def shape_mean(self) -> npt.NDArray[np.float32]:
        """Mean positions, N x 3 (mm)."""
    @property
    def color_mean(self) -> npt.NDArray[np.float32]:
        """Mean albedo, N x 3 (linear RGB in [0, 1])."""
    @property
    def shape_eigenvalues(self) -> npt.NDArray[np.float64]:
        """Shape eigenvalues (mm^2), K."""
    @property
    def color_eigenvalues(self) -> npt.NDArray[np.float64]:
        """Colour eigenvalues, K."""
    @property
    def shape_basis(self) -> npt.NDArray[np.float32]:
        """Shape basis K x N x 3, each component scaled by sqrt(eigenvalue)."""
    @property
    def color_basis(self) -> npt.NDArray[np.float32]:
        """Colour basis K x N x 3, scaled like shape_basis."""
    @property
    def triangles(self) -> npt.NDArray[np.uint32]:
        """Triangles T x 3 (counter-clockwise seen from outside)."""
    @property
    def landmarks(self) -> npt.NDArray[np.uint32]:
        """Landmark vertex ids (iBUG-68 order for scheme ibug68)."""
    @property
    def metadata(self) -> dict[str, Any]:
        """The model's metadata (docs/model-format.md)."""
    def info(self) -> dict[str, Any]:
        """The key figures `gpmm info` prints."""
    def instance(
        self, shape: Optional[npt.ArrayLike] = None, color: Optional[npt.ArrayLike] = None
    ) -> Tuple[npt.NDArray[np.float32], npt.NDArray[np.float32]]:
        """Positions and colours (clamped to [0, 1]) for the given coefficients (missing ones zero)."""
    def sample(
        self, n: int = 1, seed: int = 0
    ) -> list[Tuple[npt.NDArray[np.float32], npt.NDArray[np.float32]]]:
        """n random instances, drawn as `gpmm sample --seed` draws them."""
    def render(
        self,
        shape: Optional[npt.ArrayLike] = None,
        color: Optional[npt.ArrayLike] = None,
        yaw: float = 0.0,
        pitch: float = 0.0,
        roll: float = 0.0,
        light: Optional[_Light] = None,
        width: int = 256,
        height: int = 256,
        background: str = "0,0,0",
        fov: float = 20.0,
    ) -> npt.NDArray[np.uint8]:
        """Renders as `gpmm render` does: an H x W x 4 uint8 image."""
    def fit(
        self,
        image: npt.ArrayLike,
        landmarks: Optional[npt.ArrayLike] = None,
        *,
        seed: Optional[int] = None,
        size: Optional[int] = None,
        landmark_steps: Optional[int] = None,
        image_steps: Optional[int] = None,
        shape_rank: Optional[int] = None,
        color_rank: Optional[int] = None,
        landmark_sigma: Optional[float] = None,
        contour_sigma: Optional[float] = None,
        set: Optional[Sequence[str]] = None,
        landmark_calibration: Optional[Union[str, PathLike[str]]] = None,
        init: Optional[Union[str, PathLike[str]]] = None,
        face: Optional[int] = None,
    ) -> dict[str, Any]:
        """Fits the model to a photo (H x W x 3 uint8 RGB, or RGBA: alpha dropped) as `gpmm fit` does;
        fit.json's fields plus 'overlay', 'render', 'working_image' and 'mesh': the fitted face in
        camera space ('vertices' N x 3 float32 mm, 'triangles' T x 3 uint32, 'colors' N x 3 float32,
        'vertex_sd_mm' N float32: each vertex's standard deviation along its normal, docs/intervals.md).
        Without landmarks the face is found by `init` (default: the shipped start; the largest face,
        or `face`), and 'detected' holds it (box, score, landmarks)."""
    def quantize(
        self,
        profile: str = "m4f",
        vertices: Optional[int] = None,
        rank_shape: Optional[int] = None,
        rank_color: Optional[int] = None,
        bits: Optional[int] = None,
    ) -> bytes:
        """Quantizes for a device profile (m4f or m7) as `gpmm quantize` does: the model blob."""
    def export_h5(self, path: _Path) -> None:
        """Writes a statismo .h5 file (as `gpmm export-h5`)."""

def load(path: _Path) -> Model:
    """Loads a model file (.gpmm)."""

def model_from_bytes(data: bytes) -> Model:
    """A model from the bytes of a model file (what pickling uses)."""

def kernels() -> list[str]:
    """The nine kernel names."""

def build(
    template: _Path,
    landmarks: _Path,
    kernel: str = "symmetric-full",
    rank_shape: Optional[int] = None,
    rank_color: Optional[int] = None,
    captured_shape: Optional[float] = None,
    captured_color: Optional[float] = None,
    vertices: Optional[int] = None,
    scale: Optional[float] = None,
    no_crop: bool = False,
    texture: Optional[_Path] = None,
    config: Optional[_Path] = None,
    default_color: Optional[Tuple[float, float, float]] = None,
    nystrom_points: int = 2000,
    seed: Optional[int] = None,
) -> Model:
    """Builds a model from a template scan as `gpmm build` does."""

def import_h5(
    path: _Path, scale: Optional[float] = None, landmarks: Optional[_Path] = None
) -> Tuple[Model, dict[str, Any]]:
    """Imports a statismo / scalismo .h5 model (as `gpmm import-h5`): the model and a report."""

def inspect(blob: bytes, strict: bool = True) -> dict[str, Any]:
    """Validates a model blob with the device's parser: header and metadata."""

def load_image(path: _Path) -> npt.NDArray[np.uint8]:
    """Loads a photo as H x W x 3 uint8, as `gpmm fit` reads it."""

def read_pts(path: _Path, one_based: bool = False) -> npt.NDArray[np.float32]:
    """Reads an iBUG .pts file as L x 2 float32."""

def detect(
    image: npt.ArrayLike,
    init: Optional[_Path] = None,
    min_score: Optional[float] = None,
    smallest_face: float = 32.0,
    refine: int = 3,
    face_check: bool = True,
) -> list[dict[str, Any]]:
    """Every face the init file (default: the shipped start) finds in an image (H x W x 3 uint8),
    best first, as `gpmm detect` lists them: 'box' (cx, cy, size, score), 'yaw_deg', 'pitch_deg',
    'roll_deg', 'landmarks' (L x 2). min_score: default 0.9 for a file trained on real photos, else 0.05."""

def data_dir() -> Path:
    """The data directory: $GPMM_DATA if set, else ../shared/data (FileNotFoundError if absent)."""

def learn_wake(
    model: Model, init: Optional[bytes], image: _Path, mirrored: bool, settings_json: str
) -> Tuple[str, Optional[npt.NDArray[np.float64]], Optional[npt.NDArray[np.float64]]]:
    """Fits one view of a learning iteration: its record (JSON) and, if accepted, its reconstruction."""

def learn_shading_preparations() -> int:
    """How many times this process prepared shape from shading's bases for learn_wake."""

def learn_run(
    model: _Path,
    images: Sequence[_Path],
    output: _Path,
    *,
    init: Optional[_Path] = None,
    landmarks_dir: Optional[_Path] = None,
    learn_landmarks: bool = False,
    iterations: int = 5,
    mirror: bool = False,
    min_iou: Optional[float] = None,
    init_landmark_sigma: Optional[float] = None,
    shape_from_shading: bool = False,
    keep_variance: Optional[float] = None,
    dev: Optional[_Path] = None,
    dev_landmarks_dir: Optional[_Path] = None,
    dev_identities: Optional[int] = None,
    dev_max_identity_drop: Optional[float] = None,
    data: Optional[_Path] = None,
    jobs: Optional[int] = None,
    wake_all: Optional[Callable[[int, str, Optional[bytes], str, list[Tuple[str, bool]]], Sequence[Any]]] = None,
    progress: Optional[Callable[[dict[str, Any]], None]] = None,
    seed: Optional[int] = None,
    size: Optional[int] = None,
    landmark_steps: Optional[int] = None,
    image_steps: Optional[int] = None,
    shape_rank: Optional[int] = None,
    color_rank: Optional[int] = None,
    landmark_sigma: Optional[float] = None,
    contour_sigma: Optional[float] = None,
    set: Optional[Sequence[str]] = None,
) -> dict[str, Any]:
    """Runs gpmm learn's loop; its wake phase on this process's threads or through `wake_all`."""
