"""Shared helpers: the command line to compare against, and small scenes that render fast."""

import os
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def cli_binary() -> str:
    """The `cloudgi` binary built from the same tree (CLOUDGI_BIN, else target/release)."""
    path = os.environ.get("CLOUDGI_BIN") or str(ROOT / "target" / "release" / "cloudgi")
    if not os.path.exists(path):
        pytest.fail(f"the cloudgi binary `{path}` is missing: run `cargo build --release` or set CLOUDGI_BIN")
    return path


def run_cli(*args, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run([cli_binary(), *map(str, args)], capture_output=True, text=True, cwd=cwd, timeout=300)


def cli_error(*args, cwd=None) -> str:
    """The command line's error message (stderr without `error: `); it must fail."""
    r = run_cli(*args, cwd=cwd)
    assert r.returncode != 0, r.stderr
    err = r.stderr.strip()
    assert err.startswith("error: "), err
    return err[len("error: "):]


def tiny_scene(**camera) -> dict:
    """A small scene that renders in well under a second."""
    return {
        "camera": {"width": camera.get("width", 32), "height": camera.get("height", 24)},
        "medium": {"resolution": [40, 32, 24], "voxel_size": 25.0},
    }
