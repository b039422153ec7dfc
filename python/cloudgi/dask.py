"""Frames on a Dask cluster: one task per frame, each written atomically, failed frames retried.

::

    from dask.distributed import Client, LocalCluster
    import cloudgi.dask

    client = Client(LocalCluster(n_workers=2))
    frames = [{"sun": {"elevation_deg": e}} for e in (10, 20, 30, 40)]
    paths = cloudgi.dask.render_frames("scene.toml", frames, client, "out/cloud_{frame:04d}.exr")

A frame is a dict of scene keys applied on top of ``scene`` (``{}``: the scene as it is), a
scene of its own (a path or TOML text), or a ``(scene, overrides)`` pair.
"""

from __future__ import annotations

import inspect
import numbers
import os
import re
import warnings
from typing import Any, Dict, Iterable, List, Mapping, Optional, Tuple, Type, Union

import numpy as np

import cloudgi

Frame = Union[Mapping[str, Any], str, "os.PathLike[str]", Tuple[Any, Mapping[str, Any]]]


def frame_path(out_pattern: str, frame: int) -> str:
    """The output of frame number ``frame``: ``{frame}`` in the pattern formatted
    (``cloud_{frame:04d}.exr``), or else its run of ``#`` replaced by the zero-padded number
    (``cloud_####.exr``). A pattern whose braces name anything but ``frame`` raises ValueError."""
    out_pattern = os.fsdecode(out_pattern)
    if "{" in out_pattern:
        try:
            return out_pattern.format(frame=frame)
        except (KeyError, IndexError, ValueError, AttributeError) as e:
            raise ValueError(
                f"out_pattern `{out_pattern}` cannot be formatted ({type(e).__name__}: {e}); its only field is "
                "{frame}, e.g. cloud_{frame:04d}.exr (double a literal brace: {{)"
            ) from None
    runs = list(re.finditer(r"#+", out_pattern))
    if not runs:
        raise ValueError(f"out_pattern `{out_pattern}` has no `{{frame}}` or `#` for the frame number")
    r = runs[-1]
    return out_pattern[: r.start()] + str(frame).zfill(len(r.group())) + out_pattern[r.end():]


def _split(scene: Any, frame: Frame) -> Tuple[Any, Optional[Mapping[str, Any]]]:
    """(scene, overrides) of one frame."""
    if isinstance(frame, tuple):
        if len(frame) != 2:
            raise ValueError(f"a frame given as a tuple is (scene, overrides), not {len(frame)} items: {frame!r}")
        own, overrides = frame
        return own, overrides
    if isinstance(frame, Mapping):
        return scene, frame
    return frame, None


def render_frame(scene: Any, overrides: Optional[Mapping[str, Any]], path: str, options: Mapping[str, Any]) -> str:
    """Render one frame and write it to ``path`` atomically (a temporary file in the same folder,
    renamed when complete, so a killed worker never leaves a partial frame). The task each frame
    of :func:`render_frames` runs."""
    images = cloudgi.render(scene, overrides=overrides, **options)
    cloudgi.write_exr(path, images)
    return path


def _frame_task(
    scene: Any, overrides: Optional[Mapping[str, Any]], path: str, options: Mapping[str, Any]
) -> Tuple[str, List[Tuple[Type[Warning], str]]]:
    """:func:`render_frame` on a worker, with the warnings it issued (category, message): a
    warning raised on a worker stays in its log, so they travel back with the path."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        done = render_frame(scene, overrides, path, options)
    return done, [(w.category, str(w.message)) for w in caught]


def _frame_ranges(frames: List[int]) -> str:
    """``frame 3``, ``frames 0-3`` or ``frames 0-1, 5``: ascending frame numbers as runs."""
    runs: List[List[int]] = []
    for f in frames:
        if runs and f == runs[-1][1] + 1:
            runs[-1][1] = f
        else:
            runs.append([f, f])
    text = ", ".join(str(a) if a == b else f"{a}-{b}" for a, b in runs)
    return ("frame " if len(frames) == 1 else "frames ") + text


def _reissue(per_frame: List[Tuple[int, List[Tuple[Type[Warning], str]]]]) -> None:
    """Issue the workers' warnings here, each message once with the frames that gave it."""
    seen: Dict[Tuple[Type[Warning], str], List[int]] = {}
    for frame, caught in per_frame:
        for key in caught:
            frames = seen.setdefault(key, [])
            if not frames or frames[-1] != frame:
                frames.append(frame)
    for (category, message), frames in seen.items():
        warnings.warn(f"{_frame_ranges(frames)}: {message}", category, stacklevel=3)


def render_frames(
    scene: Any,
    frames: Iterable[Frame],
    client: Any,
    out_pattern: str,
    *,
    start: int = 0,
    retries: int = 2,
    **options: Any,
) -> List[str]:
    """Render ``frames`` on the Dask ``client``'s cluster, one task per frame; returns the
    output paths in frame order once every frame is written.

    Frame ``i`` (numbered from ``start``) is written to ``frame_path(out_pattern, i)``.
    ``options`` are :func:`cloudgi.render`'s keyword arguments (``method``, ``width``, ...).
    A frame whose task raises is tried again up to ``retries`` times; a frame on a worker that
    dies is rescheduled by Dask on another. ``start`` (an int), ``retries`` (an int, at least 0),
    ``frames`` (a list, not one frame), the options' names and every output path (not a folder,
    in a folder that exists and can be written) are checked before anything is submitted.
    The warnings each frame's render issued on its worker are issued here once all are written,
    each message once, prefixed with the frames that gave it (``frames 0-3: ...``).
    """
    for name, value in (("start", start), ("retries", retries)):
        if isinstance(value, bool) or not isinstance(value, numbers.Integral):
            raise TypeError(f"render_frames: {name} must be an int, not {type(value).__name__} {value!r}")
    if retries < 0:
        raise ValueError(f"render_frames: retries = {retries}; it must be at least 0 (the times a failed frame is tried again)")
    if isinstance(frames, (str, bytes, os.PathLike, Mapping)):
        raise TypeError(
            f"render_frames: frames must be a list of frames (dicts of overrides, scenes or (scene, overrides) pairs), "
            f"not one {type(frames).__name__}; give [frame] for one frame"
        )
    if "progress" in options:
        raise TypeError(
            "render_frames: progress= would be called on the workers, not here; follow the frames "
            "with the Dask dashboard (or render one frame locally with cloudgi.render(progress=...))"
        )
    try:
        inspect.signature(cloudgi.render).bind(None, overrides=None, **options)
    except TypeError as e:
        raise TypeError(f"render_frames: {e} (options are cloudgi.render's keyword arguments)") from None
    jobs = []
    for i, frame in enumerate(frames, start=start):
        own, overrides = _split(scene, frame)
        jobs.append((own, overrides, frame_path(out_pattern, i)))
    paths = [j[2] for j in jobs]
    if len(set(paths)) != len(paths):
        raise ValueError(f"out_pattern `{out_pattern}` gives several frames the same file; put {{frame}} in it")
    for p in paths:
        cloudgi._check_exr_output(p, "cloudgi.dask.render_frames", "out_pattern")
    if not all(callable(getattr(client, m, None)) for m in ("submit", "gather")):
        raise TypeError(f"render_frames: client must be a dask.distributed.Client, not {type(client).__name__} {client!r}")
    if isinstance(options.get("density"), np.ndarray):
        # Sent to each worker once, not pickled into every frame's task (a 1 GB grid, 100 frames:
        # 1 GB, not 100); Dask hands each task the array.
        options = dict(options, density=client.scatter(options["density"], broadcast=True))
    futures = [
        client.submit(_frame_task, own, overrides, path, options, retries=int(retries), pure=False,
                      key=f"cloudgi-frame-{os.path.basename(path)}-{os.urandom(4).hex()}")
        for own, overrides, path in jobs
    ]
    done = list(client.gather(futures))
    _reissue([(i, caught) for i, (_, caught) in enumerate(done, start=start)])
    return [path for path, _ in done]
