"""A progressive render from Python: a renderer over a world, a few passes,
a camera change (the accumulation restarts), then passes to a PNG.

    python3 examples/python/progressive_render.py [SCENE] [-o render.png] [--spp 16]
"""
import argparse

import rayforge


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scene", nargs="?", default="builtin:cornell")
    parser.add_argument("-o", "--output", default="render.png")
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--size", default="320x240")
    parser.add_argument("--device", default="cpu")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))

    world = rayforge.open_world(args.scene, device=args.device)
    camera = world.camera()
    renderer = rayforge.Renderer(world, camera, width=width, height=height, spp=args.spp, integrator="path")
    for _ in range(2):
        renderer.render_pass()
    print(f"{renderer.passes} passes")
    camera.eye = tuple(e + 0.1 * (t - e) for e, t in zip(camera.eye, camera.target))  # a step towards the target
    renderer.set_camera(camera)
    print(f"camera moved: {renderer.passes} passes accumulated")
    while renderer.passes < args.spp:
        renderer.render_pass()
    rayforge.write_image(args.output, renderer.image())
    print(f"wrote {args.output}: {width}x{height}, {renderer.passes} passes on {renderer.device}")


if __name__ == "__main__":
    main()
