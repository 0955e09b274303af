"""examples/python/ run as a user runs them (small sizes), from a scratch folder."""

import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest

import rayforge

EXAMPLES = pathlib.Path(__file__).resolve().parents[2] / "examples" / "python"


def run_example(tmp_path, name, *args):
    # The rayforge this test imported, wherever the example runs from.
    env = dict(os.environ, PYTHONPATH=str(pathlib.Path(rayforge.__file__).resolve().parents[1]))
    result = subprocess.run([sys.executable, str(EXAMPLES / name), *args], cwd=tmp_path, capture_output=True,
                            text=True, env=env, timeout=300)
    assert result.returncode == 0, result.stderr
    return result.stdout


def test_raycast(tmp_path):
    out = run_example(tmp_path, "raycast.py", "builtin:spheres", "-o", "depth.png", "--size", "64x48")
    assert "wrote depth.png" in out
    assert (tmp_path / "depth.png").stat().st_size > 0 and (tmp_path / "depth_normals.png").stat().st_size > 0


def test_sdf_slice(tmp_path):
    out = run_example(tmp_path, "sdf_slice.py", "-o", "slice.png", "--resolution", "60")
    # The winding sign is right everywhere inside below the opening; parity is not.
    assert "the winding sign calls 100.0% of points inside" in out, out
    assert (tmp_path / "slice.png").stat().st_size > 0


def test_progressive_render(tmp_path):
    out = run_example(tmp_path, "progressive_render.py", "-o", "render.png", "--spp", "4", "--size", "48x36")
    assert "camera moved: 0 passes accumulated" in out
    assert "wrote render.png: 48x36, 4 passes on cpu" in out


def test_load_mesh_flattens_instances():
    vertices, triangles = rayforge.load_mesh("builtin:cornell")
    assert vertices.dtype == np.float32 and vertices.shape[1] == 3
    assert triangles.dtype == np.uint32 and triangles.shape[1] == 3 and triangles.max() < len(vertices)
    world = rayforge.open_world("builtin:cornell")
    assert len(triangles) == world.stats()["triangles"]
    lo, hi = world.bounds
    np.testing.assert_allclose(vertices.min(axis=0), lo, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(vertices.max(axis=0), hi, rtol=1e-6, atol=1e-6)
    with pytest.raises(rayforge.Error):
        rayforge.load_mesh("/nonexistent/mesh.obj")
