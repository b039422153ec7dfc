"""cloudgi from Python against the command line: same images, same messages."""

import os
import platform
import select
import signal
import stat
import subprocess
import sys
import textwrap
import threading
import time
import warnings

import numpy as np
import pytest

import cloudgi
from conftest import cli_error, run_cli, tiny_scene


def test_version_is_the_crates():
    assert cloudgi.__version__ == "0.1.0"


def test_every_public_function_is_exported():
    # A public function missing from __all__ is left out by `from cloudgi import *`.
    public = {n for n, v in vars(cloudgi).items() if callable(v) and not n.startswith("_") and v.__module__ == "cloudgi"}
    assert public <= set(cloudgi.__all__), public - set(cloudgi.__all__)


@pytest.mark.skipif(
    not (sys.platform.startswith("linux") and platform.machine() == "x86_64"), reason="reads an x86-64 ELF symbol table"
)
def test_the_extension_keeps_the_avx_kernels_intrinsics_inlined():
    # The same structural check as tests/it/transport.rs makes on the binary: the extension is
    # its own link of the library, and an outlined core::arch AVX intrinsic (a kernel's closure
    # left outside its #[target_feature] copy) makes `transport` 3x slower with the same bits.
    so = cloudgi._cloudgi.__file__
    nm = subprocess.run(["nm", "--defined-only", so], capture_output=True, text=True)
    assert nm.returncode == 0, nm.stderr
    assert "sweep_ordinate_avx" in nm.stdout, f"{so} has no symbol table: the check cannot see"
    outlined = [line for line in nm.stdout.splitlines() if "core_arch3x863avx" in line]
    assert not outlined, f"{so} holds outlined AVX intrinsics: {outlined}"


def test_default_scene_equals_the_cli_exr_bit_for_bit(tmp_path):
    r = run_cli("render", "--quiet", "--width", 64, "--height", 48, "-o", tmp_path / "cli.exr")
    assert r.returncode == 0, r.stderr
    images = cloudgi.render(width=64, height=48)
    assert list(images) == ["rgb"]
    assert images["rgb"].shape == (48, 64, 3) and images["rgb"].dtype == np.float32
    cloudgi.write_exr(tmp_path / "py.exr", images)
    assert (tmp_path / "py.exr").read_bytes() == (tmp_path / "cli.exr").read_bytes()


def test_a_scene_file_with_aovs_equals_the_cli(tmp_path):
    scene = tmp_path / "s.toml"
    scene.write_text("[camera]\nwidth = 24\nheight = 16\n[medium]\nresolution = [30, 24, 18]\n[render]\nmethod = \"reference\"\nspp = 2\nstderr = true\n")
    r = run_cli("render", "--quiet", scene, "-o", tmp_path / "cli.exr")
    assert r.returncode == 0, r.stderr
    images = cloudgi.render(scene)
    assert list(images)[0] == "rgb" and "stderr" in images
    cloudgi.write_exr(tmp_path / "py.exr", images)
    assert (tmp_path / "py.exr").read_bytes() == (tmp_path / "cli.exr").read_bytes()


def test_a_path_a_toml_string_and_a_dict_are_the_same_scene(tmp_path):
    text = "[camera]\nwidth = 20\nheight = 12\n[medium]\nresolution = [30, 24, 18]\n"
    (tmp_path / "s.toml").write_text(text)
    from_path = cloudgi.render(str(tmp_path / "s.toml"), method="single")["rgb"]
    from_text = cloudgi.render(text, method="single")["rgb"]
    from_dict = cloudgi.render({"camera": {"width": 20, "height": 12}, "medium": {"resolution": [30, 24, 18]}}, method="single")["rgb"]
    assert np.array_equal(from_path, from_text) and np.array_equal(from_path, from_dict)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_a_numpy_density_equals_the_same_npy_file(tmp_path, dtype):
    rng = np.random.default_rng(7)
    density = (rng.random((12, 16, 20)) * 2.0).astype(dtype)  # [z][y][x]
    np.save(tmp_path / "grid.npy", density)
    scene = tiny_scene()
    scene["medium"].update({"voxel_size": 40.0, "origin": [-400.0, 50.0, -240.0]})
    from_array = cloudgi.render(scene, density=density)["rgb"]
    scene["medium"]["grid"] = str(tmp_path / "grid.npy")
    from_file = cloudgi.render(scene)["rgb"]
    assert np.array_equal(from_array, from_file)
    assert from_array.max() > 0


def test_voxel_size_and_origin_arguments_place_the_density():
    density = np.ones((4, 4, 4), np.float32)
    a = cloudgi.render(tiny_scene(), method="single", density=density, voxel_size=100.0, origin=[-200, 100, -200])["rgb"]
    scene = tiny_scene()
    scene["medium"].update({"voxel_size": 100.0, "origin": [-200.0, 100.0, -200.0]})
    b = cloudgi.render(scene, method="single", density=density)["rgb"]
    assert np.array_equal(a, b)


def npy_message(tmp_path, array) -> str:
    """The command line's message for `array` saved as medium.grid, without the file name."""
    np.save(tmp_path / "bad.npy", array)
    (tmp_path / "bad.toml").write_text('[medium]\ngrid = "bad.npy"\n')
    msg = cli_error("render", tmp_path / "bad.toml", "-o", tmp_path / "x.exr")
    prefix = f"{tmp_path / 'bad.npy'}: "
    assert msg.startswith(prefix), msg
    return msg[len(prefix):]


@pytest.mark.parametrize(
    "array",
    [
        np.ones((4, 4, 4), np.complex64),  # a dtype no density has
        np.ones((4, 4), np.float32),  # 2-D
        np.where(np.arange(64).reshape(4, 4, 4) == 21, np.nan, 1.0).astype(np.float32),  # NaN
        np.array(1.0, np.float32),  # 0-d: counted as 0 dimensions, as np.save writes it
        np.full((1, 2, 2), 1e300),  # float64 past float32's range: named, not called inf
        np.ones((2, 2, 2), object),  # numpy.save refuses it without pickle: the dtype is named
        np.zeros((2, 2, 2), [("density", "<f4")]),  # structured: named so, not "no 'descr'"
    ],
    ids=["dtype", "2d", "nan", "0d", "float64-huge", "object", "structured"],
)
def test_a_bad_density_raises_format_error_with_the_cli_message(tmp_path, array):
    with pytest.raises(cloudgi.FormatError) as e:
        cloudgi.render(tiny_scene(), density=array)
    assert str(e.value) == "in-memory density: " + npy_message(tmp_path, array)
    assert isinstance(e.value, cloudgi.CloudgiError)
    assert "'descr'" not in str(e.value)


def test_what_the_cli_refuses_for_memory_or_the_solver_is_an_error_not_a_crash_or_a_hang():
    # The command line's guards run for Python too: unguarded, a cloud wider than the diffusion
    # solver's rows panics in the render's thread and the call never returns, and an image larger
    # than the memory aborts the interpreter ("memory allocation of ... failed").
    with pytest.raises(cloudgi.SceneError, match="diffusion solver takes at most 131070"):
        cloudgi.render(tiny_scene(), method="diffusion", density=np.ones((2, 2, 300000), np.float32), voxel_size=0.01)
    with pytest.raises(cloudgi.SceneError, match=r"camera.width, camera.height.*32768×32768 image.*GiB"):
        cloudgi.render(tiny_scene(), method="full", width=32768, height=32768)


def test_a_masked_density_is_refused_and_a_0d_voxel_size_is_a_number():
    density = np.ones((2, 2, 2), np.float32)
    with pytest.raises(TypeError, match="masked array.*filled"):
        cloudgi.render(tiny_scene(), method="single", density=np.ma.masked_array(density))
    a = cloudgi.render(tiny_scene(), method="single", density=density, voxel_size=np.array(30.0))["rgb"]
    b = cloudgi.render(tiny_scene(), method="single", density=density, voxel_size=30.0)["rgb"]
    assert np.array_equal(a, b)


def test_an_unknown_dict_key_raises_scene_error_with_the_cli_message(tmp_path):
    (tmp_path / "s.toml").write_text("[camera]\nwdith = 5\n")
    cli = cli_error("render", tmp_path / "s.toml", "-o", tmp_path / "x.exr")
    with pytest.raises(cloudgi.SceneError) as e:
        cloudgi.render({"camera": {"wdith": 5}})
    assert str(e.value) == cli.replace(str(tmp_path / "s.toml"), "scene dict")
    assert "unknown field `wdith`" in str(e.value)


def test_a_negative_width_raises_scene_error_with_the_cli_message(tmp_path):
    (tmp_path / "s.toml").write_text("[camera]\nwidth = -5\n")
    cli = cli_error("render", tmp_path / "s.toml", "-o", tmp_path / "x.exr")
    with pytest.raises(cloudgi.SceneError) as e:
        cloudgi.render(width=-5)
    # The same parser's message, naming the keyword instead of a line of the merged scene.
    assert cli.splitlines()[-1] == "invalid value: integer `-5`, expected u32"
    assert str(e.value) == "keyword arguments on built-in scene: width=-5 (the scene's camera.width): " + cli.splitlines()[-1]
    with pytest.raises(cloudgi.SceneError) as e:
        cloudgi.render("[camera]\nwidth = -5\n")
    assert str(e.value) == cli.replace(str(tmp_path / "s.toml"), "TOML string")


def refine_like_the_renderer(density, k):
    """Each voxel split k times per axis (k odd), holding the trilinear field at its centre:
    per axis, the new centres in the old centres' units, clamped, linearly interpolated."""
    out = density.astype(np.float64)
    for axis in range(3):
        n = out.shape[axis]
        x = np.clip((np.arange(n * k) + 0.5) / k - 0.5, 0, n - 1)
        i0 = np.floor(x).astype(int)
        i1 = np.minimum(i0 + 1, n - 1)
        shape = [1, 1, 1]
        shape[axis] = n * k
        f = (x - i0).reshape(shape)
        out = np.take(out, i0, axis=axis) * (1 - f) + np.take(out, i1, axis=axis) * f
    return out.astype(np.float32)


def test_medium_refine_splits_a_numpy_density_as_its_trilinear_field():
    rng = np.random.default_rng(3)
    density = (rng.random((6, 5, 4)) * 2.0).astype(np.float32)  # [z][y][x]
    scene = tiny_scene()
    scene["medium"].update({"voxel_size": 90.0, "origin": [-180.0, 100.0, -270.0]})
    coarse = cloudgi.render(scene, method="single", density=density)["rgb"]
    refined = cloudgi.render({**scene, "medium": {**scene["medium"], "refine": 3}}, method="single", density=density)["rgb"]
    scene["medium"]["voxel_size"] = 30.0
    by_hand = cloudgi.render(scene, method="single", density=refine_like_the_renderer(density, 3))["rgb"]
    assert refined.max() > 0
    np.testing.assert_allclose(refined, by_hand, rtol=1e-4, atol=1e-6)
    # The same field on coarser voxels renders otherwise (the sun's transmittance per voxel).
    assert not np.allclose(coarse, by_hand, rtol=1e-4, atol=1e-6)


def test_an_even_refine_names_the_field_as_the_cli_does(tmp_path):
    (tmp_path / "s.toml").write_text("[medium]\nrefine = 2\n")
    cli = cli_error("render", tmp_path / "s.toml", "-o", tmp_path / "x.exr")
    with pytest.raises(cloudgi.SceneError) as e:
        cloudgi.render(str(tmp_path / "s.toml"))
    assert str(e.value) == cli and "medium.refine" in cli


def test_an_out_of_range_value_names_the_field(tmp_path):
    (tmp_path / "s.toml").write_text("[camera]\nwidth = 0\n")
    cli = cli_error("render", tmp_path / "s.toml", "-o", tmp_path / "x.exr")
    with pytest.raises(cloudgi.SceneError) as e:
        cloudgi.render(str(tmp_path / "s.toml"))
    assert str(e.value) == cli


@pytest.mark.parametrize("value, toml", [(float("nan"), "nan"), (float("-inf"), "-inf")])
def test_a_non_finite_float_in_a_dict_or_overrides_is_the_cli_message(tmp_path, value, toml):
    # JSON has no NaN or infinity; they must still reach the parser as floats, not as a JSON error.
    (tmp_path / "s.toml").write_text(f"[medium]\nsigma_t = {toml}\n")
    cli = cli_error("render", tmp_path / "s.toml", "-o", tmp_path / "x.exr")
    with pytest.raises(cloudgi.SceneError) as e:
        cloudgi.render({"medium": {"sigma_t": value}})
    assert str(e.value) == cli.replace(str(tmp_path / "s.toml"), "scene dict")
    with pytest.raises(cloudgi.SceneError) as e:
        cloudgi.render(overrides={"sun": {"irradiance": [1.0, value, 1.0]}})
    assert "field `sun.irradiance`" in str(e.value)
    # A string that merely starts like the marker is no float.
    with pytest.raises(cloudgi.SceneError) as e:
        cloudgi.render({"sky": {"model": "nan"}})
    assert "unknown variant `nan`" in str(e.value)


def test_numpy_scalars_and_arrays_in_a_dict_are_numbers_and_none_names_its_key():
    plain = cloudgi.scene_toml({"medium": {"sigma_t": 0.25, "origin": [0.0, 1.0, 2.0]}, "camera": {"width": 8}})
    numpy = cloudgi.scene_toml(
        {"medium": {"sigma_t": np.float64(0.25), "origin": np.array([0.0, 1.0, 2.0])}, "camera": {"width": np.int64(8)}}
    )
    assert numpy == plain
    with pytest.raises(cloudgi.SceneError) as e:
        cloudgi.render(overrides={"medium": {"sigma_t": None}})
    assert "`medium.sigma_t` is None" in str(e.value)


def test_an_integer_beyond_a_scene_files_names_its_key():
    # JSON carries any integer; TOML's are 64-bit signed, and the parser's own error named no key.
    with pytest.raises(cloudgi.SceneError) as e:
        cloudgi.render(seed=2**63, method="single", width=8, height=6)
    assert "`render.seed` = 9223372036854775808" in str(e.value)
    with pytest.raises(cloudgi.SceneError) as e:
        cloudgi.scene_toml({"camera": {"width": -(2**63) - 1}})
    assert "`camera.width`" in str(e.value)


def test_an_empty_scene_string_is_an_error_not_a_default_scene():
    # None is the built-in scene; "" is no path and no TOML a user means.
    for f in (cloudgi.render, cloudgi.scene_toml):
        with pytest.raises(ValueError, match="scene is an empty string"):
            f("")


@pytest.mark.parametrize(
    "kwargs, error, words",
    [
        ({"overrides": [1, 2]}, TypeError, ["overrides", "list [1, 2]", "dict of scene tables"]),
        ({"overrides": {"camera": 5}}, TypeError, ["overrides['camera']", "int 5", "dict of the table's keys"]),
        ({"width": "8"}, TypeError, ["width", "str '8'", "an int"]),
        ({"spp": 2.0}, TypeError, ["spp", "float 2.0", "an int"]),
        ({"aov": 1}, TypeError, ["aov", "int 1", "a bool"]),
        ({"method": 3}, TypeError, ["method", "int 3", "a str"]),
        ({"density": np.ones((2, 2, 2)), "origin": [0, 0]}, ValueError, ["origin", "2 values", "[x, y, z]"]),
        ({"density": np.ones((2, 2, 2)), "origin": "abc"}, TypeError, ["origin", "str 'abc'", "[x, y, z]"]),
        ({"density": np.ones((2, 2, 2)), "origin": [0, None, 0]}, TypeError, ["origin[1]", "None", "a number"]),
        ({"density": np.ones((2, 2, 2)), "voxel_size": "x"}, TypeError, ["voxel_size", "str 'x'", "one edge"]),
        ({"density": np.ones((2, 2, 2)), "voxel_size": True}, TypeError, ["voxel_size", "bool True", "a number"]),
        ({"origin": [0, 0, 0]}, ValueError, ["origin", "no density", "medium.origin"]),
        ({"voxel_size": 10.0}, ValueError, ["voxel_size", "no density", "medium.voxel_size"]),
        ({"progress": 5}, TypeError, ["progress", "int", "callable"]),
        ({"overrides": {"medium": {"grid": b"g.npy"}}}, TypeError, ["`medium.grid`", "bytes b'g.npy'", "a str, number"]),
        ({"overrides": {"sun": {"irradiance": {1, 2, 3}}}}, TypeError, ["`sun.irradiance`", "set", "a str, number"]),
        ({"overrides": {"camera": {1: 5}}}, TypeError, ["`camera`", "key 1", "str"]),
    ],
)
def test_a_wrong_argument_type_names_the_key_what_was_given_and_what_is_expected(kwargs, error, words):
    with pytest.raises(error) as e:
        cloudgi.render(tiny_scene(), **kwargs)
    assert all(w in str(e.value) for w in words), str(e.value)


def test_a_path_value_in_a_dict_is_its_string(tmp_path):
    np.save(tmp_path / "g.npy", np.ones((2, 3, 4), np.float32))
    as_path = cloudgi.scene_toml({"medium": {"grid": tmp_path / "g.npy"}})
    assert as_path == cloudgi.scene_toml({"medium": {"grid": str(tmp_path / "g.npy")}})


def test_a_keyword_argument_keeps_a_scene_without_camera_framing_its_cloud(tmp_path):
    # No [camera] table: camera.fit frames the cloud; width= must not make a table that turns it off.
    scene = tmp_path / "s.toml"
    scene.write_text('[medium]\nresolution = [10, 8, 6]\nvoxel_size = 25.0\n[render]\nmethod = "single"\n')
    r = run_cli("render", "--quiet", scene, "--width", 16, "--height", 12, "-o", tmp_path / "cli.exr")
    assert r.returncode == 0, r.stderr
    cloudgi.write_exr(tmp_path / "py.exr", cloudgi.render(scene, width=16, height=12))
    assert (tmp_path / "py.exr").read_bytes() == (tmp_path / "cli.exr").read_bytes()
    assert "fit = true" in cloudgi.scene_toml(str(scene), width=16)
    assert "fit = false" in cloudgi.scene_toml(str(scene), overrides={"camera": {"fit": False}})


def test_a_bad_override_value_is_blamed_on_the_keyword_arguments_not_the_scene_file(tmp_path):
    scene = tmp_path / "s.toml"
    scene.write_text("[camera]\nwidth = 8\nheight = 6\n")
    with pytest.raises(cloudgi.SceneError) as e:
        cloudgi.render(scene, overrides={"camera": {"width": "8"}})
    msg = str(e.value)
    assert msg.startswith(f"keyword arguments on {scene}: ") and 'width = "8"' in msg, msg
    assert msg.endswith('invalid type: string "8", expected u32'), msg


def test_a_missing_scene_file_is_the_cli_message(tmp_path):
    missing = tmp_path / "missing.toml"
    cli = cli_error("render", missing, "-o", tmp_path / "x.exr")
    with pytest.raises(cloudgi.CloudgiError) as e:
        cloudgi.render(missing)
    assert str(e.value) == cli


def test_progress_is_reported_on_the_calling_thread():
    calls = []
    caller = threading.get_ident()

    def progress(stage, done, total):
        assert threading.get_ident() == caller
        calls.append((stage, done, total))

    cloudgi.render(tiny_scene(width=64, height=48), method="reference", spp=64, progress=progress)
    assert calls, "the progress callback was never called"
    assert all(0 <= d <= t for _, d, t in calls)
    assert calls[-1] == ("reference paths", 64 * 64 * 48, 64 * 64 * 48)


def test_an_exception_in_the_progress_callback_cancels_the_render():
    def progress(stage, done, total):
        raise ValueError("stop here")

    t = time.monotonic()
    with pytest.raises(ValueError, match="stop here"):
        cloudgi.render(tiny_scene(width=160, height=120), method="reference", spp=100000, progress=progress)
    assert time.monotonic() - t < 30


def test_ctrl_c_raises_keyboard_interrupt_promptly():
    # The render would take hours (1.9e9 paths); Ctrl-C must end it with KeyboardInterrupt and
    # nothing else. No bound of a few seconds (that failed under CPU load): the child reports how
    # far the render got, which must be a sliver of it, and a child that ignores Ctrl-C runs
    # into the two-minute limit.
    script = textwrap.dedent(
        """
        import sys, cloudgi
        seen = []
        def progress(stage, done, total):
            seen.append((done, total))  # first: Ctrl-C may arrive during the print
            if len(seen) == 1:
                print("started", flush=True)
        try:
            cloudgi.render({"camera": {"width": 160, "height": 120}}, method="reference", spp=100000, progress=progress)
        except KeyboardInterrupt:
            done, total = seen[-1]
            print("interrupted", done, total, flush=True)
            sys.exit(3)
        """
    )
    p = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        ready, _, _ = select.select([p.stdout], [], [], 120)
        assert ready, "the render never reported progress"
        line = p.stdout.readline()
        assert line.strip() == "started", (line, p.poll())
        p.send_signal(signal.SIGINT)
        out, err = p.communicate(timeout=120)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    assert p.returncode == 3, (p.returncode, out, err)
    words = out.split()
    assert words[0] == "interrupted", out
    done, total = int(words[1]), int(words[2])
    assert total == 160 * 120 * 100000 and done < total // 100, (done, total)


def test_write_exr_checks_shapes(tmp_path):
    with pytest.raises(cloudgi.FormatError):
        cloudgi.write_exr(tmp_path / "x.exr", {"rgb": np.zeros((4, 5, 3), np.float32), "aov": np.zeros((4, 4, 3))})
    with pytest.raises(cloudgi.SceneError):
        cloudgi.write_exr(tmp_path / "x.exr", {"aov": np.zeros((4, 4, 3))})
    # No pixel, or a layer without a name: the file is named, not the EXR encoder.
    with pytest.raises(cloudgi.FormatError, match="x.exr.*at least 1×1"):
        cloudgi.write_exr(tmp_path / "x.exr", {"rgb": np.zeros((0, 4, 3), np.float32)})
    with pytest.raises(cloudgi.FormatError, match="x.exr.*second RGB"):
        cloudgi.write_exr(tmp_path / "x.exr", {"rgb": np.zeros((2, 2, 3)), "": np.zeros((2, 2, 3))})
    assert not (tmp_path / "x.exr").exists()


@pytest.mark.parametrize(
    "where, words",
    [
        (".", ["cloudgi.write_exr", "`.` is a folder"]),
        ("{tmp}", ["cloudgi.write_exr", "{tmp}` is a folder"]),
        ("{tmp}/sub/", ["ends in a path separator"]),
        ("{tmp}/missing/x.exr", ["the folder `{tmp}/missing` does not exist"]),
        ("", ["the path is empty"]),
    ],
)
def test_write_exr_to_a_folder_raises_file_error_naming_it_and_writes_nothing(tmp_path, where, words):
    images = {"rgb": np.ones((2, 2, 3), np.float32)}
    before = sorted(tmp_path.iterdir())
    with pytest.raises(cloudgi.FileError) as e:
        cloudgi.write_exr(where.format(tmp=tmp_path), images)
    assert all(w.format(tmp=tmp_path) in str(e.value) for w in words), str(e.value)
    assert sorted(tmp_path.iterdir()) == before


def test_write_exr_to_a_name_without_the_exr_extension_is_refused(tmp_path):
    images = {"rgb": np.ones((2, 2, 3), np.float32)}
    for name, said in [("c.png", "ends in `.png`"), ("c", "ends in no extension")]:
        with pytest.raises(cloudgi.FileError, match=f"^cloudgi.write_exr: field `path`: .*{said}.*\\.exr extension"):
            cloudgi.write_exr(tmp_path / name, images)
    assert not list(tmp_path.iterdir())
    cloudgi.write_exr(tmp_path / "c.EXR", images)
    assert (tmp_path / "c.EXR").read_bytes()[:4] == b"\x76\x2f\x31\x01", "the OpenEXR magic number"


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="named pipes are POSIX")
def test_write_exr_to_a_pipe_or_a_path_with_a_nul_is_refused_and_the_pipe_kept(tmp_path):
    # The atomic write renamed its file over the pipe (and, as root, over /dev/full, which then
    # held the EXR); a NUL reached the OS, whose message named neither the function nor `path`.
    fifo = tmp_path / "p.exr"
    os.mkfifo(fifo)
    image = {"rgb": np.ones((2, 2, 3), np.float32)}
    with pytest.raises(cloudgi.FileError, match=r"^cloudgi.write_exr: field `path`: `.*p.exr` is a device, pipe or socket, not a file"):
        cloudgi.write_exr(fifo, image)
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)
    with pytest.raises(cloudgi.FileError, match=r"^cloudgi.write_exr: field `path`: .* holds a NUL character"):
        cloudgi.write_exr(str(tmp_path / "a\0b.exr"), image)


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="named pipes are POSIX")
def test_a_scene_path_that_is_a_pipe_is_refused_not_waited_on(tmp_path):
    # The read waited for a writer on the render's thread, and Ctrl-C could not end it.
    fifo = tmp_path / "s.toml"
    os.mkfifo(fifo)

    def feed():
        # A reader still waiting after 5 s gets a scene, so the call returns (and the test fails).
        try:
            fd = os.open(fifo, os.O_WRONLY | os.O_NONBLOCK)
        except OSError:  # no reader: the call was refused
            return
        os.write(fd, b"[camera]\nwidth = 4\nheight = 3\n")
        os.close(fd)

    for call in (lambda: cloudgi.render(fifo, method="single"), lambda: cloudgi.scene_toml(str(fifo))):
        timer = threading.Timer(5, feed)
        timer.start()
        try:
            with pytest.raises(cloudgi.FormatError, match=r"s.toml: a named pipe, which cloudgi.render would wait on"):
                call()
        finally:
            timer.cancel()


def test_a_grid_file_given_as_the_scene_says_how_to_render_it(tmp_path):
    # `cloudgi render g.npy` renders the grid; the package read it as TOML: "not UTF-8 text".
    np.save(tmp_path / "g.npy", np.ones((2, 2, 2), np.float32))
    with pytest.raises(cloudgi.FormatError, match=r"g.npy: a .npy grid file, not a scene file; give it as the scene's grid"):
        cloudgi.render(tmp_path / "g.npy")
    images = cloudgi.render({"medium": {"grid": str(tmp_path / "g.npy")}}, method="single", width=4, height=3)
    assert images["rgb"].shape == (3, 4, 3)


def test_write_exr_takes_bytes_and_unicode_paths_and_refuses_what_is_no_image(tmp_path):
    images = {"rgb": np.ones((2, 2, 3), np.float32)}
    cloudgi.write_exr(bytes(tmp_path / "b.exr"), images)
    cloudgi.write_exr(tmp_path / "wolke-☁.exr", images)
    assert (tmp_path / "b.exr").read_bytes() == (tmp_path / "wolke-☁.exr").read_bytes()
    with pytest.raises(TypeError, match="images must be a dict"):
        cloudgi.write_exr(tmp_path / "x.exr", images["rgb"])
    with pytest.raises(TypeError, match="image names must be str.*int 5"):
        cloudgi.write_exr(tmp_path / "x.exr", {"rgb": images["rgb"], 5: images["rgb"]})
    for rgb in (np.ones((2, 2, 3), complex), np.ones((2, 2, 3), object), np.full((2, 2, 3), "a")):
        with pytest.raises(TypeError, match=f"image `rgb` has dtype {rgb.dtype}"):
            cloudgi.write_exr(tmp_path / "x.exr", {"rgb": rgb})
    assert not (tmp_path / "x.exr").exists()


def test_load_vdb_reads_the_grid_the_scene_renders(tmp_path):
    from conftest import ROOT

    vdb = ROOT / "tests" / "data" / "vdb" / "multi_grid_blosc.vdb"
    density, voxel, origin = cloudgi.load_grid(vdb)
    assert np.array_equal(cloudgi.load_vdb(vdb), density)
    assert np.array_equal(cloudgi.load_grid(bytes(vdb))[0], density)
    assert density.dtype == np.float32 and density.ndim == 3 and density.max() > 0
    scene = tiny_scene()
    scene["medium"] = {"grid": str(vdb)}
    a = cloudgi.render(scene, method="single")["rgb"]
    assert voxel[0] == voxel[1] == voxel[2]
    b = cloudgi.render(tiny_scene(), method="single", density=density, voxel_size=voxel[0], origin=origin)["rgb"]
    assert np.array_equal(a, b)


def test_load_grid_of_a_missing_file_or_a_folder_names_the_path_not_a_scene_key(tmp_path, monkeypatch):
    # A grid file is not a scene key: the message names the path, not "field `medium.grid`: ...
    # (paths are relative to the scene file)", and load_grid("procedural") is not the built-in cloud.
    with pytest.raises(cloudgi.FileError) as e:
        cloudgi.load_grid(tmp_path / "missing.vdb")
    assert str(e.value).startswith(f"{tmp_path / 'missing.vdb'}: ") and "medium.grid" not in str(e.value)
    with pytest.raises(cloudgi.FormatError, match="not a regular file"):
        cloudgi.load_vdb(tmp_path)
    monkeypatch.chdir(tmp_path)
    with pytest.raises(cloudgi.FileError, match="procedural"):
        cloudgi.load_grid("procedural")
    with pytest.raises(TypeError, match="grid must be a str"):
        cloudgi.load_grid(tmp_path / "missing.vdb", None)


def test_a_grid_with_cells_that_are_not_cubes_renders_as_its_file_does():
    from conftest import ROOT

    # OpenVDB's ScaleMap [0.1, 0.2, 0.1]: load_grid's three edges place it as the file does.
    vdb = ROOT / "tests" / "data" / "vdb" / "aniso_scale_blosc.vdb"
    density, voxel, origin = cloudgi.load_grid(vdb)
    assert voxel[0] == voxel[2] != voxel[1]
    scene = tiny_scene()
    scene["medium"] = {"grid": str(vdb), "sigma_t": 2.0}
    scene["camera"].update({"position": [3.0, 6.0, 20.0], "look_at": [3.0, 6.0, 3.0]})
    a = cloudgi.render(scene, method="single")["rgb"]
    del scene["medium"]["grid"]
    b = cloudgi.render(scene, method="single", density=density, voxel_size=voxel, origin=origin)["rgb"]
    assert a.max() > 0 and np.array_equal(a, b)
    with pytest.raises(ValueError, match="voxel_size has 2 values"):
        cloudgi.render(scene, method="single", density=density, voxel_size=[1.0, 2.0])


def test_the_command_lines_scene_warnings_are_runtime_warnings():
    # A camera looking away from the cloud: `cloudgi render` warns that the image shows no cloud,
    # and so does the package (it issued none of the scene's warnings before).
    scene = tiny_scene(width=8, height=6)
    scene["camera"].update({"position": [0.0, 300.0, 2000.0], "look_at": [0.0, 300.0, 4000.0]})
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        cloudgi.render(scene, method="single")
    seen = [str(w.message) for w in caught if w.category is RuntimeWarning]
    assert any("is not in the camera's view" in m for m in seen), seen
    # The framed scene warns about nothing.
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        cloudgi.render(tiny_scene(width=8, height=6), method="single")
    assert not [str(w.message) for w in caught if w.category is RuntimeWarning]


def _ignored(*args, **kwargs) -> list:
    """The "does not apply" RuntimeWarnings of a render."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        cloudgi.render(*args, **kwargs)
    return [str(w.message) for w in caught if w.category is RuntimeWarning and "does not apply" in str(w.message)]


def test_a_key_the_method_does_not_read_is_a_runtime_warning_as_on_the_command_line(tmp_path):
    # `cloudgi render --method single` warns that a scene's render.transport_order is ignored;
    # the package said nothing. Each way of giving the key is named as the command line names it.
    scene = tiny_scene(width=8, height=6)
    scene["render"] = {"transport_order": 5}
    assert _ignored(scene, method="single") == [
        "scene dict: `render.transport_order` does not apply to method single (only transport uses it); it is ignored"
    ]
    path = tmp_path / "s.toml"
    path.write_text('[camera]\nwidth = 8\nheight = 6\n[medium]\nresolution = [8, 6, 4]\n[render]\nmethod = "single"\nspp = 4\n')
    cli = run_cli("render", path, "-o", tmp_path / "c.exr").stderr
    python = _ignored(str(path))
    assert len(python) == 1 and f"warning: {python[0]}" in cli, (python, cli)
    assert _ignored(tiny_scene(width=8, height=6), method="single", aov=True) == [
        "keyword argument `aov=` does not apply to method single (only full and transport write AOV layers); it is ignored"
    ]
    assert _ignored(tiny_scene(width=8, height=6), method="single", overrides={"sky": {"path": "x.exr"}}) == [
        'overrides: `sky.path` does not apply unless sky.model = "envmap"; it is ignored'
    ]
    # A density array replaces medium.grid, and with it the procedural cumulus' keys.
    scene = {"camera": {"width": 8, "height": 6}, "medium": {"seed": 3, "voxel_size": 100.0}}
    assert _ignored(scene, method="single", density=np.ones((2, 2, 2), np.float32)) == [
        "scene dict: `medium.seed` does not apply to a density array (it replaces medium.grid); it is ignored"
    ]


@pytest.mark.parametrize("method", cloudgi.METHODS)
def test_the_framed_default_scene_warns_of_no_ignored_key_whatever_the_method(method):
    # The built-in scene's own keys are defaults, not given: only what the caller sets warns.
    assert _ignored(None, method=method, width=8, height=6) == []


def test_a_density_of_zeros_or_of_values_float32_reads_as_zero_is_a_runtime_warning():
    # The image showed sky and ground only, and nothing said why.
    for value, warned in ((0.0, True), (1e-300, True), (1e-3, False)):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            cloudgi.render({"camera": {"width": 8, "height": 6}}, method="single", density=np.full((2, 2, 2), value))
        seen = [str(w.message) for w in caught if "every density of the grid is 0" in str(w.message)]
        assert bool(seen) == warned, (value, seen)


def test_a_clipped_sun_taken_out_of_the_sky_map_is_a_runtime_warning(tmp_path):
    # A 1024×512 map of 0.5 with a Gaussian sun (σ = 2 pixels, peak 1e6), whole and cut at 65504.
    j, i = np.mgrid[0:512, 0:1024].astype(np.float32)
    sun = 0.5 + 1e6 * np.exp(-((i - 200.3) ** 2 + (j - 120.6) ** 2) / 8.0)
    for name, ceiling in [("whole.exr", np.inf), ("clipped.exr", 65504.0)]:
        rgb = np.repeat(np.minimum(sun, ceiling)[:, :, None], 3, axis=2).astype(np.float32)
        cloudgi.write_exr(tmp_path / name, {"rgb": rgb})
        scene = tiny_scene(width=8, height=6)
        scene["sky"] = {"model": "envmap", "path": str(tmp_path / name), "extract_sun": True}
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            cloudgi.render(scene, method="single")
        clipped = [w for w in caught if "is clipped" in str(w.message)]
        assert len(clipped) == (name == "clipped.exr"), [str(w.message) for w in caught]
        assert all(w.category is RuntimeWarning and "65504 in the file" in str(w.message) for w in clipped)


def test_a_sun_taken_out_of_the_sky_map_is_noted_and_kept_with_extract_sun_false(tmp_path):
    # A 256×128 map of 0.5 with a 2×2-pixel sun of 1e5: left out, sky.extract_sun takes it out
    # as the scene's sun (the default [sun] has no light of its own) and says so; false keeps it.
    rgb = np.full((128, 256, 3), 0.5, np.float32)
    rgb[38:40, 60:62] = 1e5
    cloudgi.write_exr(tmp_path / "sunny.exr", {"rgb": rgb})
    for extract, noted in [(None, True), (False, False)]:
        scene = tiny_scene(width=8, height=6)
        scene["sky"] = {"model": "envmap", "path": str(tmp_path / "sunny.exr")}
        if extract is not None:
            scene["sky"]["extract_sun"] = extract
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            cloudgi.render(scene, method="single")
        seen = [str(w.message) for w in caught if w.category is RuntimeWarning]
        assert any("holds a sun: it is taken out" in m for m in seen) == noted, seen


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"voxel_size": 1e300}, "voxel_size = 1e+300 is out of range"),
        ({"voxel_size": [1.0, 1.0, 1e39]}, "voxel_size[2] = 1e+39 is out of range"),
        ({"voxel_size": 1e-50}, "voxel_size = 1e-50 is out of range"),
        ({"origin": [0.0, 3.5e38, 0.0]}, "origin[1] = 3.5e+38 is out of range"),
        ({"origin": [0, 10**400, 0]}, "origin[1] = 100000000000... (401 digits) is out of range"),
        ({"origin": [0.0, 0.0, float("nan")]}, "origin[2] = nan is not a finite number"),
    ],
)
def test_voxel_size_and_origin_past_float32_name_the_argument_and_value(kwargs, message):
    # Checked before the cast to float32, which would make them inf (or 0 for 1e-50) and name
    # `medium.voxel_size`: Vec3(inf, inf, inf); an int past float64 is not a bare OverflowError.
    with pytest.raises(cloudgi.SceneError) as e:
        cloudgi.render(tiny_scene(), method="single", density=np.ones((2, 2, 2), np.float32), **kwargs)
    assert str(e.value).startswith(message), str(e.value)
    assert "float32" in str(e.value) or "finite" in str(e.value)


def test_a_coordinate_float32_rounds_to_zero_is_zero():
    # An origin of 1e-50 m is 0 to the renderer's precision, not an error (a voxel size is).
    density = np.ones((2, 2, 2), np.float32)
    at_zero = cloudgi.render(tiny_scene(), method="single", density=density, origin=[0.0, 0.0, 0.0])["rgb"]
    tiny = cloudgi.render(tiny_scene(), method="single", density=density, origin=[1e-50, 0.0, -1e-50])["rgb"]
    assert np.array_equal(at_zero, tiny)


def test_a_placement_argument_out_of_the_scenes_range_names_the_argument():
    with pytest.raises(cloudgi.SceneError, match=r"field `voxel_size \(argument\)`: .* at most 1e6 m"):
        cloudgi.render(tiny_scene(), method="single", density=np.ones((2, 2, 2), np.float32), voxel_size=1e7)
    with pytest.raises(cloudgi.SceneError, match=r"field `origin \(argument\)`: .* within ±1e7 m"):
        cloudgi.render(tiny_scene(), method="single", density=np.ones((2, 2, 2), np.float32), origin=[1e8, 0, 0])


@pytest.mark.parametrize(
    "image, words",
    [
        (np.full((2, 3, 3), 1e300), r"images\['aov'\] holds 1e\+300 at pixel \(row 0, column 0\), channel R \(largest magnitude 1e\+300\), past float32"),
        (np.where(np.arange(18).reshape(2, 3, 3) == 7, -4e38, 1.0), r"holds -4e\+38 at pixel \(row 0, column 2\), channel G \(largest magnitude 4e\+38\)"),
        (np.where(np.arange(18).reshape(2, 3, 3) == 5, np.nan, 1.0).astype(np.float32), r"holds nan at pixel \(row 0, column 1\), channel B \(1 non-finite values\)"),
        (np.full((2, 3, 3), np.inf, np.float16), r"holds inf at pixel \(row 0, column 0\), channel R \(18 non-finite values\)"),
    ],
    ids=["float64-huge", "float64-huge-negative", "nan", "float16-inf"],
)
def test_write_exr_refuses_non_finite_pixels_and_values_past_float32(tmp_path, image, words):
    # Checked before writing: float64 past float32's range would be cast to inf; NaN and inf are refused as given.
    images = {"rgb": np.ones((2, 3, 3), np.float32), "aov": image}
    if not np.isfinite(image).all():
        images = {"rgb": image, "aov": np.ones((2, 3, 3), np.float32)}
        words = words.replace("aov", "rgb")
    with pytest.raises(cloudgi.FormatError, match=words):
        cloudgi.write_exr(tmp_path / "x.exr", images)
    assert not list(tmp_path.iterdir())


def test_write_exr_takes_float64_within_float32_and_negative_values(tmp_path):
    # What float32 holds is written as the cast gives it (an AOV or a difference may be negative).
    image = np.array([[[3.4e38, -2.0, 0.1]]])
    cloudgi.write_exr(tmp_path / "x.exr", {"rgb": image})
    assert (tmp_path / "x.exr").stat().st_size > 0


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"spp": -1}, "spp=-1 (the scene's render.spp): invalid value: integer `-1`, expected u32"),
        ({"width": 2**40}, "width=1099511627776 (the scene's camera.width): invalid value: integer `1099511627776`, expected u32"),
        ({"method": "fast"}, 'method="fast" (the scene\'s render.method): unknown variant `fast`, expected one of'),
        ({"overrides": {"sun": {"elevaton": 3}}}, "sun.elevaton = 3: unknown field `elevaton`, expected one of"),
        ({"overrides": {"snu": {}}}, "snu = {}: unknown field `snu`, expected one of"),
        ({"overrides": {"sun": {"direction": [1, 2, 3, 4]}}}, "sun.direction = [1, 2, 3, 4]: has 4 items; give exactly 3"),
    ],
)
def test_a_bad_keyword_value_names_the_keyword_and_value_not_a_line_of_merged_toml(kwargs, message):
    # The message showed a line of the scene merged with the keyword arguments ("TOML parse error
    # at line 10 ... 10 | spp = -1"), which the caller never wrote.
    for call in (cloudgi.render, cloudgi.scene_toml):
        with pytest.raises(cloudgi.SceneError) as e:
            call(tiny_scene(), **kwargs)
        msg = str(e.value)
        assert msg.startswith("keyword arguments on scene dict: " + message), msg
        assert "line" not in msg and "|" not in msg, msg


def test_an_out_of_range_keyword_value_is_blamed_on_the_keyword_not_the_scene():
    with pytest.raises(cloudgi.SceneError) as e:
        cloudgi.render(tiny_scene(), width=0)
    assert str(e.value).startswith("keyword argument width= on scene dict: field `camera.width`: 0 is not allowed"), str(e.value)
    with pytest.raises(cloudgi.SceneError) as e:
        cloudgi.render(tiny_scene(), overrides={"render": {"spp": 0}})
    assert str(e.value).startswith("keyword arguments on scene dict: field `render.spp`: 0 is not allowed"), str(e.value)
    # A bad value of the scene itself is still the scene's.
    scene = tiny_scene()
    scene["render"] = {"spp": 0}
    with pytest.raises(cloudgi.SceneError, match=r"^scene dict: field `render.spp`"):
        cloudgi.render(scene, width=8)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the available memory is known on Linux")
def test_a_virtual_density_too_large_is_refused_from_its_shape_before_numpy_copies_it():
    # np.broadcast_to costs nothing, but np.save materialised it: a MemoryError from numpy for
    # this one, and for one that nearly fits, the machine swapping before the check.
    huge = np.broadcast_to(np.float32(1.0), (100000, 100000, 100000))
    t = time.monotonic()
    with pytest.raises(cloudgi.SceneError, match=r"^in-memory density: field `density`: 100000×100000×100000 values need about .* PiB of memory"):
        cloudgi.render(tiny_scene(), method="single", density=huge)
    assert time.monotonic() - t < 5


def test_odd_layouts_and_dtypes_of_a_density_render_as_its_c_order_float32():
    rng = np.random.default_rng(3)
    base = (rng.random((6, 8, 10)) * 2).astype(np.float32)
    want = cloudgi.render(tiny_scene(), method="single", density=base)["rgb"]
    for variant in (
        np.asfortranarray(base),
        np.repeat(base, 2, axis=0)[::2],  # strided
        base.astype(">f4"),  # big-endian
        base.astype(np.float64),
        np.frombuffer(base.tobytes(), np.float32).reshape(base.shape),  # read-only
    ):
        assert np.array_equal(cloudgi.render(tiny_scene(), method="single", density=variant)["rgb"], want)


@pytest.mark.parametrize(
    "name, words",
    [
        ("a\0b", "holds a NUL character"),
        ("x" * 254, "is 254 bytes of UTF-8; an EXR channel name .* a name at most 253"),
        ("é" * 127, "is 254 bytes of UTF-8"),
        ("\ud800", "is not valid Unicode"),
    ],
    ids=["nul", "long", "long-utf8", "surrogate"],
)
def test_write_exr_refuses_a_layer_name_an_exr_cannot_hold(tmp_path, name, words):
    # Such a name makes a file no reader opens ("missing or invalid channels attribute").
    with pytest.raises(cloudgi.FormatError, match=words):
        cloudgi.write_exr(tmp_path / "x.exr", {"rgb": np.ones((2, 2, 3), np.float32), name: np.ones((2, 2, 3), np.float32)})
    assert not list(tmp_path.iterdir())


def test_the_longest_layer_name_writes_a_file_the_command_line_reads(tmp_path):
    ones = np.ones((2, 2, 3), np.float32)
    cloudgi.write_exr(tmp_path / "ref.exr", {"rgb": ones})
    cloudgi.write_exr(tmp_path / "x.exr", {"rgb": ones, "x" * 253: ones, "é" * 126: ones})
    r = run_cli("compare", tmp_path / "x.exr", tmp_path / "ref.exr", "--all-pixels")
    assert r.returncode == 0, r.stderr


def test_a_scene_path_may_be_bytes_as_every_other_path(tmp_path):
    scene = tmp_path / "szène ☁.toml"
    scene.write_text("[camera]\nwidth = 8\nheight = 6\n[medium]\nresolution = [10, 8, 6]\n")
    want = cloudgi.render(str(scene), method="single")["rgb"]
    assert np.array_equal(cloudgi.render(os.fsencode(scene), method="single")["rgb"], want)
    assert cloudgi.scene_toml(os.fsencode(scene)) == cloudgi.scene_toml(scene)


def test_renders_from_several_threads_at_once_equal_one_alone():
    import threading

    want = cloudgi.render(tiny_scene(), method="reference", spp=4)["rgb"]
    got = [None] * 3

    def run(i):
        got[i] = cloudgi.render(tiny_scene(), method="reference", spp=4)["rgb"]

    threads = [threading.Thread(target=run, args=(i,)) for i in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=120)
    assert all(g is not None and np.array_equal(g, want) for g in got)


def test_errors_survive_pickling_as_dask_sends_them():
    import pickle

    with pytest.raises(cloudgi.SceneError) as e:
        cloudgi.render(tiny_scene(), spp=-1)
    back = pickle.loads(pickle.dumps(e.value))
    assert type(back) is cloudgi.SceneError and str(back) == str(e.value)


def test_a_missing_scene_path_with_brackets_or_equals_is_named_as_a_file(tmp_path):
    # A path, not TOML text: not "TOML string: TOML parse error at line 1 ... expected `.`, `=`".
    for name in ("a=1", "[v2]"):
        missing = tmp_path / name / "scene.toml"
        cli = cli_error("render", missing, "-o", tmp_path / "x.exr")
        with pytest.raises(cloudgi.FileError) as e:
            cloudgi.render(str(missing))
        assert str(e.value) == cli
    (tmp_path / "[v2]").mkdir()
    (tmp_path / "[v2]" / "scene.toml").write_text("[camera]\nwidth = 8\nheight = 6\n")
    assert "width = 8" in cloudgi.scene_toml(str(tmp_path / "[v2]" / "scene.toml"))


def test_a_key_given_both_as_a_keyword_and_in_overrides_is_refused():
    # The keyword won silently: spp=4 rendered 4 samples whatever overrides said.
    for call in (cloudgi.render, cloudgi.scene_toml):
        with pytest.raises(TypeError, match=r"spp=4 and overrides\['render'\]\['spp'\]=8 both set the scene's render.spp"):
            call(tiny_scene(), spp=4, overrides={"render": {"spp": 8}})
    assert "spp = 8" in cloudgi.scene_toml(tiny_scene(), overrides={"render": {"spp": 8}})


def test_an_empty_axis_or_a_tiny_voxel_is_named_as_the_caller_wrote_it():
    # The empty axis was named as [5, 4, 0] (nx, ny, nz) for an array of shape (0, 4, 5), and the
    # tiny voxel as `Vec3(1e-30, 1e-30, 1e-30)`, the Rust type's debug form.
    with pytest.raises(cloudgi.FormatError, match=r"array of shape \(0, 4, 5\) holds no voxel"):
        cloudgi.render(tiny_scene(), method="single", density=np.ones((0, 4, 5), np.float32))
    with pytest.raises(cloudgi.SceneError, match=r"`voxel_size \(argument\)`: \[1e-30, 1e-30, 1e-30\] is not allowed"):
        cloudgi.render(tiny_scene(), method="single", density=np.ones((2, 2, 2)), voxel_size=1e-30)


def test_a_bad_density_value_is_located_by_its_array_index_too():
    # (x, y, z) = (3, 2, 1) alone would send a numpy user to density[3, 2, 1].
    density = np.ones((4, 5, 6), np.float32)
    density[1, 2, 3] = np.nan
    with pytest.raises(cloudgi.FormatError, match=r"voxel \(x, y, z\) = \(3, 2, 1\), array index \[1, 2, 3\], is NaN"):
        cloudgi.render(tiny_scene(), density=density)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the available memory is known on Linux")
def test_a_virtual_image_too_large_is_refused_from_its_shape_before_numpy_converts_it(tmp_path):
    # np.ascontiguousarray materialised it: a MemoryError from numpy, or swapping for one that
    # nearly fits.
    huge = np.broadcast_to(np.float32(1.0), (2**20, 2**20, 3))
    t = time.monotonic()
    with pytest.raises(cloudgi.SceneError, match=r"x.exr: field `images`: a 1048576×1048576 image of 2 layers needs about .* TiB of memory"):
        cloudgi.write_exr(tmp_path / "x.exr", {"rgb": huge, "aov": huge})
    assert time.monotonic() - t < 5
    assert not list(tmp_path.iterdir())
    with pytest.raises(cloudgi.FormatError, match=r"an EXR holds at most 2147483647 pixels a side"):
        cloudgi.write_exr(tmp_path / "x.exr", {"rgb": np.broadcast_to(np.float32(1.0), (1, 2**31, 3))})
