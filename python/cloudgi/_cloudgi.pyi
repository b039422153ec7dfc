"""Native half of cloudgi (PyO3); use the functions of the `cloudgi` package instead."""

from typing import Any, Callable, List, Optional, Sequence, Tuple, Union

__version__: str

class CloudgiError(Exception):
    """Base of every cloudgi error."""

class SceneError(CloudgiError):
    """The scene (a file, TOML text, a dict or an argument) is invalid."""

class FormatError(CloudgiError):
    """A data file or array (grid, image) is malformed or holds bad values."""

class FileError(CloudgiError):
    """A file could not be read or written."""

class SolverError(CloudgiError):
    """A numerical stage failed (e.g. the diffusion solver did not converge)."""

class CancelledError(CloudgiError):
    """The render was cancelled."""

def render(
    kind: str,
    payload: str,
    overrides: str,
    keywords: Sequence[str],
    npy: Optional[bytes] = None,
    voxel_size: Union[float, Sequence[float], None] = None,
    origin: Optional[Sequence[float]] = None,
    progress: Optional[Callable[[str, int, int], Any]] = None,
) -> Tuple[int, int, List[Tuple[str, bytearray]]]: ...
def write_exr(path: str, width: int, height: int, layers: Sequence[Tuple[str, bytes]]) -> None: ...
def check_output(path: str, source: str, field: str) -> None: ...
def load_grid(
    path: str, grid: str
) -> Tuple[Tuple[int, int, int], bytearray, Tuple[float, float, float], Tuple[float, float, float]]: ...
def scene_toml(kind: str, payload: str, overrides: str, keywords: Sequence[str]) -> str: ...
def check_density_fits(shape: Sequence[int], itemsize: int) -> None: ...
def check_image_fits(path: str, width: int, height: int, layers: int, itemsize: int) -> None: ...
