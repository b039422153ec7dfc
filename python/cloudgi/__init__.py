"""cloudgi: physically based cloud rendering (Max et al. 2004) from Python.

Numpy in, images out::

    import cloudgi
    images = cloudgi.render("examples/default.toml", width=160, height=120)
    images["rgb"].shape            # (120, 160, 3), float32, linear radiance
    cloudgi.write_exr("cloud.exr", images)

A scene is a path to a scene file, TOML text, or a dict in the scene file's schema
(``{"camera": {"width": 64}, "medium": {"sigma_t": 0.1}}``); every key the file allows, with the
same defaults and the same error messages as the ``cloudgi`` command line. ``density`` (a numpy
array indexed ``[z][y][x]``, like a ``.npy`` file) replaces ``medium.grid``. Frames on a Dask
cluster: :func:`cloudgi.dask.render_frames`.
"""

from __future__ import annotations

import io
import json
import math
import numbers
import os
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Union

import numpy as np

from . import _cloudgi
from ._cloudgi import (
    CancelledError,
    CloudgiError,
    FileError,
    FormatError,
    SceneError,
    SolverError,
)

__version__: str = _cloudgi.__version__

__all__ = [
    "__version__",
    "render",
    "write_exr",
    "load_vdb",
    "load_grid",
    "scene_toml",
    "METHODS",
    "CloudgiError",
    "SceneError",
    "FormatError",
    "FileError",
    "SolverError",
    "CancelledError",
]

#: The rendering methods, as ``render(method=...)`` and the scene's ``render.method`` name them.
METHODS = ("single", "diffusion", "full", "transport", "reference")

SceneLike = Union[str, bytes, "os.PathLike[str]", Mapping[str, Any]]
ProgressCallback = Callable[[str, int, int], Any]


# JSON has no NaN or infinity: a non-finite float travels as this prefix and its repr, and the
# extension turns it back into a float, so the scene parser names the key as the command line does.
_NON_FINITE = "\x00float:"


# TOML's integers are 64-bit signed; the scene parser reads what a scene file can hold.
_TOML_INT_MIN, _TOML_INT_MAX = -(2**63), 2**63 - 1


def _json(value: Any) -> str:
    """``value`` as JSON: numpy scalars and arrays as Python numbers and lists, non-finite floats
    marked with :data:`_NON_FINITE`; a ``None`` (TOML has no null) raises naming its key."""
    def mark(v: Any, key: str) -> Any:
        if isinstance(v, (np.generic, np.ndarray)):
            v = v.tolist()
        if v is None:
            raise SceneError(f"`{key}` is None: TOML has no null; leave the key out for its default")
        if isinstance(v, os.PathLike):
            v = os.fsdecode(v)
        if isinstance(v, numbers.Integral) and not isinstance(v, bool):
            v = int(v)
        elif isinstance(v, numbers.Real) and not isinstance(v, bool):
            v = float(v)
        if isinstance(v, float) and not math.isfinite(v):
            return _NON_FINITE + repr(v)
        if isinstance(v, int) and not isinstance(v, bool) and not _TOML_INT_MIN <= v <= _TOML_INT_MAX:
            raise SceneError(f"`{key}` = {v} is beyond a scene file's integers (64-bit signed, ±9.2e18)")
        if isinstance(v, Mapping):
            for k in v:
                if not isinstance(k, str):
                    raise TypeError(f"`{key}` has the key {k!r} ({type(k).__name__}); keys of a scene's tables are str")
            return {k: mark(x, f"{key}.{k}" if key else k) for k, x in v.items()}
        if isinstance(v, (list, tuple)):
            return [mark(x, f"{key}[{i}]") for i, x in enumerate(v)]
        if not isinstance(v, (str, bool, int, float)):
            raise TypeError(
                f"`{key}` is {type(v).__name__} {v!r}; a scene value is a str, number, bool, list or dict"
            )
        return v
    return json.dumps(mark(value, ""), allow_nan=False)


def _scene_input(scene: Optional[SceneLike]) -> "tuple[str, str]":
    """(kind, payload) of a scene: the built-in one, a path, TOML text or a dict (sent as JSON)."""
    if scene is None:
        return "builtin", ""
    if isinstance(scene, Mapping):
        return "dict", _json(scene)
    if isinstance(scene, (os.PathLike, bytes)):
        return "path", os.fsdecode(scene)
    if isinstance(scene, str):
        if scene == "":
            raise ValueError("scene is an empty string: give a scene file's path, TOML text or a dict (None: the built-in scene)")
        # TOML text has a newline, a `=` or a `[`; a path has none of them, names a file, or is
        # one line ending in `.toml` (`shots/a=1/scene.toml`: a missing one is named as a file).
        is_toml_path = "\n" not in scene and scene.lower().endswith(".toml")
        looks_like_toml = any(c in scene for c in "\n=[") and not is_toml_path
        if looks_like_toml and not os.path.isfile(scene):
            return "toml", scene
        return "path", scene
    raise TypeError(f"scene must be a path, TOML text or a dict, not {type(scene).__name__}")


def _overrides(method: Optional[str], width: Optional[int], height: Optional[int],
               spp: Optional[int], seed: Optional[int], aov: Optional[bool],
               extra: Optional[Mapping[str, Mapping[str, Any]]] = None) -> "tuple[str, List[str]]":
    """The keyword arguments as scene keys (JSON), and the dotted keys set by a keyword of its own
    (``render.spp`` for ``spp=``, for messages): their types checked here, their values by the
    scene file's own parser."""
    over: Dict[str, Dict[str, Any]] = {}
    keywords: List[str] = []
    if extra is not None and not isinstance(extra, Mapping):
        raise TypeError(
            f"overrides must be a dict of scene tables, e.g. {{'sun': {{'elevation_deg': 30}}}}, not {type(extra).__name__} {extra!r}"
        )
    for table, keys in (extra or {}).items():
        if not isinstance(keys, Mapping):
            raise TypeError(
                f"overrides[{table!r}] must be a dict of the table's keys, e.g. {{'width': 64}}, not {type(keys).__name__} {keys!r}"
            )
        over.setdefault(table, {}).update(keys)
    for table, key, value, kind in (
        ("render", "method", method, str),
        ("camera", "width", width, numbers.Integral),
        ("camera", "height", height, numbers.Integral),
        ("render", "spp", spp, numbers.Integral),
        ("render", "seed", seed, numbers.Integral),
        ("render", "aov", aov, (bool, np.bool_)),
    ):
        if value is None:
            continue
        if not isinstance(value, kind) or (kind is numbers.Integral and isinstance(value, bool)):
            expected = {str: "a str", numbers.Integral: "an int"}.get(kind, "a bool")
            raise TypeError(f"{key} must be {expected} (the scene's {table}.{key}), not {type(value).__name__} {value!r}")
        if key in over.get(table, {}):
            raise TypeError(
                f"{key}={value!r} and overrides[{table!r}][{key!r}]={over[table][key]!r} both set the scene's "
                f"{table}.{key}; give one of them"
            )
        over.setdefault(table, {})[key] = value
        keywords.append(f"{table}.{key}")
    return _json(over), keywords


def _npy_bytes(density: Any) -> bytes:
    """The bytes of ``density`` as a ``.npy`` file, so the grid is checked exactly as one."""
    if not isinstance(density, np.ndarray):
        raise TypeError(f"density must be a numpy.ndarray, not {type(density).__name__}")
    if isinstance(density, np.ma.MaskedArray):
        raise TypeError("density is a masked array, whose mask a grid cannot hold; give density.filled(0)")
    # Before any copy: a virtual array (np.broadcast_to) would be materialised by np.save. The
    # copies: the .npy bytes and their bytes object, a C-order copy first if it is not one.
    copies = 2 if density.flags.c_contiguous else 3
    _cloudgi.check_density_fits([int(n) for n in density.shape], density.dtype.itemsize * copies)
    buf = io.BytesIO()
    if density.dtype.hasobject:
        # np.save refuses Python objects; the header alone has the reader name the dtype.
        np.lib.format.write_array_header_1_0(buf, np.lib.format.header_data_from_array_1_0(density))
        return buf.getvalue()
    # C order, as the reader requires; a 0-d array stays 0-d (ascontiguousarray would make it 1-d
    # and the message would count the wrong dimensions).
    np.save(buf, density if density.flags.c_contiguous else np.ascontiguousarray(density), allow_pickle=False)
    return buf.getvalue()


def _images(width: int, height: int, layers: Sequence["tuple[str, bytearray]"]) -> Dict[str, np.ndarray]:
    return {name: np.frombuffer(data, dtype="<f4").reshape(height, width, 3) for name, data in layers}


def render(
    scene: Optional[SceneLike] = None,
    method: Optional[str] = None,
    density: Optional[np.ndarray] = None,
    width: Optional[int] = None,
    height: Optional[int] = None,
    *,
    spp: Optional[int] = None,
    seed: Optional[int] = None,
    aov: Optional[bool] = None,
    voxel_size: Union[float, Sequence[float], None] = None,
    origin: Optional[Sequence[float]] = None,
    overrides: Optional[Mapping[str, Mapping[str, Any]]] = None,
    progress: Optional[ProgressCallback] = None,
) -> Dict[str, np.ndarray]:
    """Render a scene; returns ``{"rgb": array, <aov>: array, ...}``, float32 ``(H, W, 3)``.

    ``scene``: a path to a scene file, TOML text, or a dict in the scene file's schema (tables
    and keys it leaves out take the defaults, and no ``ground`` table means no ground, as in a
    scene file); ``None``: the built-in default scene (the command line without a scene file;
    ``""`` raises ValueError). ``method`` (``"transport"``, ``"single"``,
    ``"diffusion"``, ``"full"``, ``"reference"``; default: the scene's ``render.method``),
    ``width``, ``height``, ``spp``, ``seed`` and ``aov`` override the scene's keys, and so does
    ``overrides``, a dict of tables in the scene file's schema (``{"sun": {"elevation_deg": 30}}``),
    applied on top of the scene after the scene itself is checked.

    ``density``: float, integer or bool array indexed ``[z][y][x]`` (as a ``.npy`` file), replacing
    ``medium.grid``; its voxels are ``voxel_size`` metres (one edge, or ``[x, y, z]`` as
    :func:`load_grid` returns it; default ``medium.voxel_size``) with the minimum corner at
    ``origin`` (default ``medium.origin``); either one without ``density`` raises ValueError, and
    a NaN, infinity or value float32 cannot hold raises :class:`SceneError` naming it. A density
    whose copies would not fit in the available memory is refused from its shape
    (:class:`SceneError`) before numpy copies it (``np.broadcast_to`` arrays included).

    ``progress(stage, done, total)`` is called from this thread while the render runs (at most
    every 50 ms, on change), e.g. to drive a tqdm bar. The GIL is released during the render;
    Ctrl-C cancels it (KeyboardInterrupt). Solver warnings, the scene's warnings and notes (a
    sun taken out of the sky map by ``sky.extract_sun``, a clipped one, a cloud out of view, ...)
    and the command line's warnings about a key given that does not apply to the method, sky,
    ground or grid (``spp`` with a deterministic method) are issued as RuntimeWarning.

    Raises TypeError or ValueError for an argument of the wrong type or shape, naming it,
    :class:`SceneError` (bad scene or scene value), :class:`FormatError` (bad grid data),
    :class:`FileError`, :class:`SolverError`, each with the command line's message.
    """
    kind, payload = _scene_input(scene)
    over, keywords = _overrides(method, width, height, spp, seed, aov, overrides)
    if density is None:
        for name, value in (("voxel_size", voxel_size), ("origin", origin)):
            if value is not None:
                raise ValueError(
                    f"{name} places the density array, and no density is given; set the scene's "
                    f"medium.{name} instead, e.g. overrides={{'medium': {{'{name}': ...}}}}"
                )
    if progress is not None and not callable(progress):
        raise TypeError(f"progress must be a callable progress(stage, done, total), not {type(progress).__name__}")
    npy = None if density is None else _npy_bytes(density)
    w, h, layers = _cloudgi.render(
        kind,
        payload,
        over,
        keywords,
        npy,
        _voxel_size(voxel_size),
        None if origin is None else _vec3("origin", origin, "[x, y, z] in metres", tiny_is_zero=True),
        progress,
    )
    return _images(w, h, layers)


_F32_MAX = float(np.finfo(np.float32).max)


def _real(name: str, v: Any, tiny_is_zero: bool) -> float:
    """``v`` as a float32-sized float; a bool, a str or anything not a real number raises
    TypeError naming ``name``; NaN, infinity or a value past float32's range (the renderer's
    precision) raises :class:`SceneError` naming it and the value (cast, 1e300 would read as
    inf). So does a nonzero value float32 rounds to 0 (1e-50), unless ``tiny_is_zero`` (a
    coordinate, where it is 0 to within the precision of every other one)."""
    if isinstance(v, np.ndarray) and v.ndim == 0:
        v = v.item()
    if isinstance(v, bool) or not isinstance(v, numbers.Real):
        raise TypeError(f"{name} must be a number, not {type(v).__name__} {v!r}")
    shown = str(v) if len(str(v)) <= 24 else f"{str(v)[:12]}... ({len(str(v))} digits)"
    out_of_range = SceneError(
        f"{name} = {shown} is out of range: the renderer holds it as float32, "
        f"from {float(np.finfo(np.float32).smallest_subnormal):.1e} to {_F32_MAX:.1e} in magnitude"
    )
    try:
        x = float(v)
    except OverflowError:  # an int past float64's range
        raise out_of_range from None
    if not math.isfinite(x):
        raise SceneError(f"{name} = {shown} is not a finite number")
    with np.errstate(over="ignore", under="ignore"):
        as_f32 = float(np.float32(x))
    if not math.isfinite(as_f32) or (as_f32 == 0.0 and x != 0.0 and not tiny_is_zero):
        raise out_of_range
    return x


def _vec3(name: str, v: Any, expected: str, tiny_is_zero: bool) -> List[float]:
    """``v`` as three floats; anything else raises naming ``name`` and ``expected``."""
    if isinstance(v, (str, bytes)) or not isinstance(v, (Sequence, np.ndarray)):
        raise TypeError(f"{name} must be {expected}, not {type(v).__name__} {v!r}")
    if len(v) != 3:
        raise ValueError(f"{name} has {len(v)} values, {list(v)!r}; it must be {expected}")
    return [_real(f"{name}[{i}]", x, tiny_is_zero) for i, x in enumerate(v)]


def _voxel_size(v: Union[float, Sequence[float], None]) -> Union[float, List[float], None]:
    """``voxel_size`` as the extension takes it: one float, or a list of three."""
    if v is None:
        return None
    if isinstance(v, numbers.Real) or (isinstance(v, np.ndarray) and v.ndim == 0):
        return _real("voxel_size", v, tiny_is_zero=False)
    return _vec3("voxel_size", v, "one edge in metres, or [x, y, z]", tiny_is_zero=False)


def write_exr(path: Union[str, bytes, "os.PathLike[str]"], images: Mapping[str, np.ndarray]) -> None:
    """Write ``images`` (``"rgb"`` and any AOVs, each ``(H, W, 3)``) as one OpenEXR file,
    atomically: RGB as the R, G, B channels and each AOV as ``NAME.R/G/B``, exactly as the
    command line writes a render. A path that is a folder, in a folder that does not exist or
    cannot be written, or whose name does not end in ``.exr``, raises :class:`FileError` before
    anything is converted or written; a NaN,
    an infinity or a value past float32's range (float64 1e300) raises :class:`FormatError`
    naming the image and pixel, and nothing is written. Images whose copies would not fit in
    the available memory are refused from their shape (:class:`SceneError`) before any copy."""
    path = _path("path", path)
    if not isinstance(images, Mapping):
        raise TypeError(f"images must be a dict {{name: (H, W, 3) array}} as render returns, not {type(images).__name__}")
    for name in images:
        if not isinstance(name, str):
            raise TypeError(f"{path}: image names must be str (the EXR's layer names), not {type(name).__name__} {name!r}")
    if "rgb" not in images:
        raise SceneError(f"{path}: images need an \"rgb\" entry (got {sorted(images)})")
    _check_exr_output(path, "cloudgi.write_exr", "path")
    shape = np.shape(images["rgb"])
    arrays = {}
    for name, img in images.items():
        arr = np.asarray(img)
        if arr.dtype.kind not in "fiub":
            raise TypeError(f"{path}: image `{name}` has dtype {arr.dtype}; an image holds real numbers (float, int or bool)")
        if arr.ndim != 3 or arr.shape[2] != 3 or arr.shape != shape:
            raise FormatError(
                f"{path}: image `{name}` has shape {arr.shape}; every image must be (H, W, 3) like rgb's {shape}"
            )
        if arr.size == 0:
            raise FormatError(f"{path}: the images have shape {shape}, no pixel; an EXR needs at least 1×1")
        if name == "":
            raise FormatError(f"{path}: an image named \"\" would be a second RGB; name it (its layer is NAME.R/G/B)")
        _check_layer_name(path, name)
        arrays[name] = arr
    if max(shape[:2]) > _EXR_MAX_SIDE:
        raise FormatError(f"{path}: the images have shape {shape}; an EXR holds at most {_EXR_MAX_SIDE} pixels a side")
    # Before any conversion: a virtual array (np.broadcast_to) would be materialised. The copies
    # here: float32 and its bytes, 4 bytes a value each.
    _cloudgi.check_image_fits(path, shape[1], shape[0], len(arrays), 8)
    layers = [(name, _f32_bytes(path, name, arr)) for name, arr in arrays.items()]
    _cloudgi.write_exr(path, shape[1], shape[0], layers)


# An EXR's data window is held in signed 32-bit integers.
_EXR_MAX_SIDE = 2**31 - 1


# An EXR channel name (NAME.R) holds at most 255 bytes of UTF-8; a longer one, or a NUL (which
# ends a name in the file), makes a file no reader opens.
_MAX_LAYER_NAME_BYTES = 255 - len(".R")


def _check_layer_name(path: str, name: str) -> None:
    """An image's name as an EXR can hold it: UTF-8, no NUL, at most 253 bytes."""
    if name == "rgb":
        return
    try:
        size = len(name.encode("utf-8"))
    except UnicodeEncodeError as e:
        raise FormatError(f"{path}: image name {name!r} is not valid Unicode ({e.reason}); an EXR's names are UTF-8") from None
    if "\0" in name:
        raise FormatError(f"{path}: image name {name!r} holds a NUL character, which ends a name in an EXR file")
    if size > _MAX_LAYER_NAME_BYTES:
        raise FormatError(
            f"{path}: image name {name[:20]!r}... is {size} bytes of UTF-8; an EXR channel name (NAME.R) holds at most "
            f"255 bytes, so a name at most {_MAX_LAYER_NAME_BYTES}"
        )


def _f32_bytes(path: str, name: str, arr: np.ndarray) -> bytes:
    """Image ``name`` as float32 bytes, as the EXR holds it; a NaN or infinity, or a value past
    float32's range (which the cast would make infinite), raises :class:`FormatError` naming it:
    the file would hold non-finite pixels that nothing downstream expects."""
    with np.errstate(over="ignore", invalid="ignore"):
        f32 = np.ascontiguousarray(arr, dtype="<f4")
    bad = ~np.isfinite(f32)
    if not bad.any():
        return f32.tobytes()
    y, x, c = (int(i) for i in np.argwhere(bad)[0])
    value = arr[y, x, c]
    where = f"pixel (row {y}, column {x}), channel {'RGB'[c]}"
    if np.isfinite(value):
        largest = np.abs(arr[np.isfinite(arr)]).max()
        raise FormatError(
            f"{path}: images[{name!r}] holds {value:g} at {where} (largest magnitude {largest:g}), past float32's "
            f"{_F32_MAX:.4g} that an EXR's float channels hold; scale the image down"
        )
    raise FormatError(
        f"{path}: images[{name!r}] holds {value} at {where} ({int(bad.sum())} non-finite values): an EXR of a render "
        "holds finite values; find where they came from (or replace them, e.g. numpy.nan_to_num)"
    )


def _check_exr_output(path: str, source: str, field: str) -> None:
    """Raise :class:`FileError` (naming ``source`` and ``field``) unless ``path`` can be written
    as an output file (``_cloudgi.check_output``) and ends in ``.exr``: an OpenEXR file under
    another image's name (``c.png``) opens nowhere as that format."""
    _cloudgi.check_output(path, source, field)
    suffix = os.path.splitext(path)[1]
    if suffix.lower() != ".exr":
        raise FileError(
            f"{source}: field `{field}`: `{path}` ends in {f'`{suffix}`' if suffix else 'no extension'}; "
            "the file is written as OpenEXR: give the name the .exr extension"
        )


def _path(name: str, path: Any) -> str:
    """A path argument as str: a str, bytes (decoded as the file system names) or os.PathLike."""
    try:
        return os.fsdecode(path)
    except TypeError:
        raise TypeError(f"{name} must be a path (str, bytes or os.PathLike), not {type(path).__name__} {path!r}") from None


def load_vdb(path: Union[str, bytes, "os.PathLike[str]"], grid: str = "density") -> np.ndarray:
    """Read grid ``grid`` of an OpenVDB file densely over its active voxels: a float32 array
    indexed ``[z][y][x]``, ready for ``render(density=...)`` (its voxel size and origin are the
    file's transform; see :func:`load_grid` for them)."""
    return load_grid(path, grid)[0]


def load_grid(path: Union[str, bytes, "os.PathLike[str]"], grid: str = "density"):
    """Read a grid file (``.vdb``, ``.npy``, ``.raw`` with its ``.json``, ``.vol``) as the scene's
    ``medium.grid`` would be read: ``(array [z][y][x] float32, voxel_size (m, x y z), origin (m))``."""
    if not isinstance(grid, str):
        raise TypeError(f"grid must be a str, the grid's name in the file, not {type(grid).__name__} {grid!r}")
    dims, data, voxel, origin = _cloudgi.load_grid(_path("path", path), grid)
    nx, ny, nz = dims
    return np.frombuffer(data, dtype="<f4").reshape(nz, ny, nx), tuple(voxel), tuple(origin)


def scene_toml(scene: Optional[SceneLike] = None, **overrides: Any) -> str:
    """The scene ``render`` would use, as scene-file TOML with every default filled in."""
    kind, payload = _scene_input(scene)
    over, keywords = _overrides(overrides.pop("method", None), overrides.pop("width", None),
                                overrides.pop("height", None), overrides.pop("spp", None),
                                overrides.pop("seed", None), overrides.pop("aov", None),
                                overrides.pop("overrides", None))
    if overrides:
        raise TypeError(f"unknown keyword arguments: {sorted(overrides)}")
    return _cloudgi.scene_toml(kind, payload, over, keywords)
