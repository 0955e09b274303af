"""rayforge.Renderer against the CLI: the same scene, camera and options give
the same image (the same C++ renderer underneath), and write_image's files
read back."""

import os
import subprocess

import numpy as np
import pytest

import rayforge


def read_pfm(path):
    with open(path, "rb") as f:
        kind = f.readline().strip()
        width, height = map(int, f.readline().split())
        scale = float(f.readline())
        data = np.frombuffer(f.read(), dtype="<f4" if scale < 0 else ">f4")
    assert kind == b"PF"
    return data.reshape(height, width, 3)[::-1]  # PFM rows run bottom to top


def cli():
    path = os.environ.get("RAYFORGE_CLI")
    if not path:
        pytest.skip("RAYFORGE_CLI not set (run through ctest)")
    return path


@pytest.mark.parametrize("integrator,spp", [("path", 4), ("whitted", 1), ("ao", 2), ("normals", 1)])
def test_renderer_image_equals_the_cli(tmp_path, integrator, spp):
    out = tmp_path / "cli.pfm"
    camera = "0,1,3.4,0,1,0,0,1,0,40"
    subprocess.run([cli(), "render", "builtin:cornell", "-o", str(out), "--res", "48x36", "--spp", str(spp),
                    "--integrator", integrator, "--seed", "5", "--threads", "2", "--camera", camera, "-q"],
                   check=True, capture_output=True)
    expected = read_pfm(out)
    world = rayforge.open_world("builtin:cornell")
    r = rayforge.Renderer(world, rayforge.Camera.parse(camera), width=48, height=36, spp=spp,
                          integrator=integrator, seed=5, threads=2)
    image = r.render()
    assert r.passes == spp
    assert image.shape == (36, 48, 3) and image.dtype == np.float32
    np.testing.assert_allclose(image, expected, rtol=1e-5, atol=1e-6)


def test_progressive_passes_and_aovs(tmp_path):
    world = rayforge.open_world("builtin:cornell")
    r = rayforge.Renderer(world, width=32, height=24, spp=8, integrator="path", aovs=True, threads=2)
    assert r.passes == 0
    assert r.render_pass() is not None
    assert r.passes == 1
    for _ in range(3):
        r.render_pass()
    assert r.passes == 4
    image = r.image()
    assert image.shape == (24, 32, 3) and np.isfinite(image).all() and image.max() > 0
    for aov in (r.albedo(), r.normal(), r.depth()):
        assert aov.shape == (24, 32, 3) and np.isfinite(aov).all()
    assert r.stats()["samples"] > 0
    # A new camera or new options restart the accumulation.
    cam = world.camera()
    cam.fov = 30.0
    r.set_camera(cam)
    r.render_pass()
    assert r.passes == 1
    r.set_options(integrator="ao", ao_samples=4)
    r.render_pass()
    assert r.passes == 1


def test_write_image_round_trip(tmp_path):
    image = np.random.default_rng(3).uniform(0, 2, size=(10, 14, 3)).astype(np.float32)
    rayforge.write_image(str(tmp_path / "a.pfm"), image)
    np.testing.assert_array_equal(read_pfm(tmp_path / "a.pfm"), image)
    rayforge.write_image(str(tmp_path / "a.png"), image, exposure=0.5, tonemap="aces")
    assert (tmp_path / "a.png").stat().st_size > 0
    with pytest.raises(ValueError, match="image"):
        rayforge.write_image(str(tmp_path / "b.png"), np.zeros((4, 3), np.float32))
    with pytest.raises(ValueError, match="tonemap"):
        rayforge.write_image(str(tmp_path / "b.png"), image, tonemap="filmic")


def test_renderer_option_errors():
    world = rayforge.open_world("builtin:cornell")
    with pytest.raises(TypeError, match="unknown option 'sampels'"):
        rayforge.Renderer(world, sampels=4)
    with pytest.raises(ValueError, match="integrator"):
        rayforge.Renderer(world, integrator="photon")
    with pytest.raises((ValueError, rayforge.Error)):
        rayforge.Renderer(world, width=0)
