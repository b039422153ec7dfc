"""Frames on a real Dask cluster (LocalCluster with worker processes): identical to local
renders, and a worker killed mid-run loses no frame."""

import os
import signal
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import cloudgi
import cloudgi.dask
from conftest import tiny_scene

distributed = pytest.importorskip("distributed")


@pytest.fixture(scope="module")
def client():
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None)
    c = distributed.Client(cluster)
    yield c
    c.close()
    cluster.close()


FRAMES = [{"sun": {"elevation_deg": e}} for e in (20.0, 35.0, 50.0, 65.0)]


def local_bytes(tmp_path, scene, frame, **options) -> bytes:
    path = tmp_path / "local.exr"
    cloudgi.write_exr(path, cloudgi.render(scene, overrides=frame, **options))
    return path.read_bytes()


def test_frame_paths():
    assert cloudgi.dask.frame_path("out/c_{frame:04d}.exr", 7) == "out/c_0007.exr"
    assert cloudgi.dask.frame_path("out/c_###.exr", 7) == "out/c_007.exr"
    assert cloudgi.dask.frame_path(Path("out/c_{frame:04d}.exr"), 7) == "out/c_0007.exr"
    with pytest.raises(ValueError):
        cloudgi.dask.frame_path("out/c.exr", 7)
    # Braces that are not {frame}: a ValueError naming the pattern, not a KeyError or IndexError.
    for bad in ("out/c_{i}.exr", "out/c_{}.exr", "out/c_{frame.exr"):
        with pytest.raises(ValueError, match=r"out_pattern `.*` cannot be formatted.*\{frame\}"):
            cloudgi.dask.frame_path(bad, 7)


def test_four_frames_equal_local_renders(client, tmp_path):
    scene = tiny_scene()
    paths = cloudgi.dask.render_frames(scene, FRAMES, client, str(tmp_path / "f_{frame}.exr"), method="transport")
    assert paths == [str(tmp_path / f"f_{i}.exr") for i in range(4)]
    for frame, path in zip(FRAMES, paths):
        assert open(path, "rb").read() == local_bytes(tmp_path, scene, frame, method="transport")
    assert not [p for p in os.listdir(tmp_path) if ".tmp" in p]


def test_the_workers_warnings_reach_the_client_once_with_their_frames(client, tmp_path):
    # A camera looking away from the cloud warns on every frame; the client sees it once, naming
    # the frames, as a RuntimeWarning; a framed scene warns about nothing.
    scene = tiny_scene(width=8, height=6)
    scene["camera"].update({"position": [0.0, 300.0, 2000.0], "look_at": [0.0, 300.0, 4000.0]})
    with pytest.warns(RuntimeWarning) as caught:
        cloudgi.dask.render_frames(scene, FRAMES[:3], client, str(tmp_path / "w_{frame}.exr"), method="single", start=5)
    seen = [str(w.message) for w in caught if "is not in the camera's view" in str(w.message)]
    assert len(seen) == 1 and seen[0].startswith("frames 5-7: "), [str(w.message) for w in caught]
    import warnings

    with warnings.catch_warnings(record=True) as quiet:
        warnings.simplefilter("always")
        cloudgi.dask.render_frames(tiny_scene(width=8, height=6), FRAMES[:2], client, str(tmp_path / "q_{frame}.exr"), method="single")
    assert not [str(w.message) for w in quiet if w.category is RuntimeWarning]


def test_frame_ranges_read_as_runs():
    assert cloudgi.dask._frame_ranges([3]) == "frame 3"
    assert cloudgi.dask._frame_ranges([0, 1, 2, 3]) == "frames 0-3"
    assert cloudgi.dask._frame_ranges([0, 1, 5, 7, 8]) == "frames 0-1, 5, 7-8"


def test_a_killed_worker_loses_no_frame(client, tmp_path):
    # Frames of about a second each, so one is running when its worker is killed.
    scene = tiny_scene(width=48, height=36)
    options = {"method": "reference", "spp": 24}
    result = {}

    def run():
        result["paths"] = cloudgi.dask.render_frames(scene, FRAMES, client, str(tmp_path / "k_{frame}.exr"), **options)

    t = threading.Thread(target=run)
    t.start()
    pids = client.run(os.getpid)
    victim = None
    deadline = time.monotonic() + 60
    while victim is None and time.monotonic() < deadline:
        busy = [w for w, keys in client.processing().items() if keys]
        if busy:
            victim = busy[0]
        else:
            time.sleep(0.05)
    assert victim is not None, "no frame ever started"
    os.kill(pids[victim], signal.SIGKILL)
    t.join(timeout=240)
    assert not t.is_alive()
    assert result["paths"] == [str(tmp_path / f"k_{i}.exr") for i in range(4)]
    for frame, path in zip(FRAMES, result["paths"]):
        assert open(path, "rb").read() == local_bytes(tmp_path, scene, frame, **options)


def test_a_failing_frame_raises_after_its_retries(client, tmp_path):
    with pytest.raises(cloudgi.SceneError, match="wdith"):
        cloudgi.dask.render_frames(tiny_scene(), [{"camera": {"wdith": 3}}], client, str(tmp_path / "e_{frame}.exr"), retries=1)
    assert not os.listdir(tmp_path)


def test_a_missing_folder_is_found_before_submitting(client, tmp_path):
    with pytest.raises(cloudgi.FileError, match="does not exist"):
        cloudgi.dask.render_frames(tiny_scene(), FRAMES, client, str(tmp_path / "no" / "f_{frame}.exr"))


def test_bad_outputs_options_and_frames_are_found_before_submitting(client, tmp_path):
    # Each is refused here, with a message, before a worker renders (and retries) anything.
    (tmp_path / "f_1.exr").mkdir()
    with pytest.raises(cloudgi.FileError, match="out_pattern.*f_1.exr` is a folder"):
        cloudgi.dask.render_frames(tiny_scene(), FRAMES, client, str(tmp_path / "f_{frame}.exr"))
    with pytest.raises(cloudgi.FileError, match=r"out_pattern.*p_0.png` ends in `.png`.*\.exr extension"):
        cloudgi.dask.render_frames(tiny_scene(), FRAMES, client, str(tmp_path / "p_{frame}.png"))
    with pytest.raises(TypeError, match="widht"):
        cloudgi.dask.render_frames(tiny_scene(), FRAMES, client, str(tmp_path / "g_{frame}.exr"), widht=8)
    with pytest.raises(ValueError, match=r"\(scene, overrides\), not 3 items"):
        cloudgi.dask.render_frames(tiny_scene(), [(tiny_scene(), {}, 1)], client, str(tmp_path / "h_{frame}.exr"))
    assert not client.processing() or not any(client.processing().values())
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f_1.exr"]


@pytest.mark.parametrize(
    "kwargs, error, words",
    [
        ({"retries": -1}, ValueError, r"retries = -1; it must be at least 0"),
        ({"retries": 1.5}, TypeError, r"retries must be an int, not float 1.5"),
        ({"retries": True}, TypeError, r"retries must be an int, not bool"),
        ({"start": "1"}, TypeError, r"start must be an int, not str"),
    ],
)
def test_bad_numeric_arguments_are_refused_before_the_client_is_used(tmp_path, kwargs, error, words):
    # Checked here (Dask itself takes retries=-1); no client is needed to refuse them.
    with pytest.raises(error, match=words):
        cloudgi.dask.render_frames(tiny_scene(), FRAMES, None, str(tmp_path / "f_{frame}.exr"), **kwargs)


def test_frames_given_as_one_scene_are_refused(tmp_path):
    # Iterated, a str would be one frame per character, a dict one per table name.
    for frames in ("scene.toml", {"sun": {"elevation_deg": 20.0}}):
        with pytest.raises(TypeError, match=r"frames must be a list of frames .* give \[frame\] for one frame"):
            cloudgi.dask.render_frames(tiny_scene(), frames, None, str(tmp_path / "f_{frame}.exr"))


def test_a_client_that_is_not_one_is_named(tmp_path):
    # It failed with "'NoneType' object has no attribute 'submit'".
    with pytest.raises(TypeError, match=r"client must be a dask.distributed.Client, not NoneType"):
        cloudgi.dask.render_frames(tiny_scene(), FRAMES, None, str(tmp_path / "f_{frame}.exr"))


def test_a_density_option_is_sent_once_and_renders_as_locally(client, tmp_path):
    # Sent once (scattered), not pickled into every frame's task: a grid of N bytes would cost N per frame.
    density = np.random.default_rng(5).random((12, 16, 20)).astype(np.float32)
    submitted = []
    real_submit = client.submit

    def submit(fn, *args, **kwargs):
        submitted.append(args[3]["density"])
        return real_submit(fn, *args, **kwargs)

    client.submit = submit
    try:
        paths = cloudgi.dask.render_frames(tiny_scene(), FRAMES[:2], client, str(tmp_path / "d_{frame}.exr"),
                                           method="single", density=density, voxel_size=40.0)
    finally:
        del client.submit
    assert len(submitted) == 2 and all(isinstance(d, distributed.Future) for d in submitted)
    for frame, path in zip(FRAMES, paths):
        assert open(path, "rb").read() == local_bytes(tmp_path, tiny_scene(), frame, method="single", density=density, voxel_size=40.0)


def test_a_progress_callback_is_refused_as_it_would_run_on_the_workers(tmp_path):
    # Pickled to the workers (or failing to pickle, e.g. a tqdm bar), it would never be called here.
    with pytest.raises(TypeError, match=r"progress= would be called on the workers"):
        cloudgi.dask.render_frames(tiny_scene(), FRAMES, None, str(tmp_path / "f_{frame}.exr"), progress=print)
