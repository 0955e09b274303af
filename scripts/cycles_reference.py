# Renders one rayforge JSON scene with Blender's Cycles, for the reference
# images of tests/data/cycles. Run by scripts/make-cycles-references.sh:
#
#   blender -b --factory-startup -noaudio --python-exit-code 1 -P scripts/cycles_reference.py -- SCENE.json OUT.exr SEED SPP
#
# Reads the same JSON file rayforge reads (the subset the reference scenes
# use: meshes with a material override, materials, camera, environment colour,
# render size and max_depth) and expresses it in Cycles as written in
# docs/rendering.md "Independent references":
#   - geometry: the OBJ files imported without axis conversion (rayforge's
#     coordinates are Blender's); glTF files imported and rotated back from
#     Blender's Z-up to the file's Y-up;
#   - camera: eye/target/up, vertical fov, square pixels, box pixel filter of
#     width 1 (uniform jitter in the pixel, as rayforge);
#   - bounces: rayforge's max_depth counts bounces after the camera ray and
#     needs one of them for direct light, so Cycles gets max_bounces = max_depth - 1;
#   - no clamping, no glossy filter, no light threshold, no denoising, no
#     adaptive sampling; Standard view transform; linear float EXR output;
#   - materials: Lambert (specular 0) -> Diffuse BSDF (roughness 0); white
#     conductor -> Glossy BSDF (Multiscatter GGX, roughness r); clear glass ->
#     Glass BSDF (Multiscatter GGX, roughness r, IOR); emitter -> Emission
#     (one-sided: masked by Geometry.Backfacing; plus a Diffuse BSDF when the
#     emitter has a base colour); glTF base colour textures -> Diffuse BSDF fed
#     by the same image (sRGB, closest texel: see lambert_from_gltf); an OBJ without a material
#     override keeps its MTL materials, mapped the same way (Lambert only).
import json
import math
import os
import sys

import bpy
from mathutils import Matrix, Vector


def args():
    argv = sys.argv[sys.argv.index("--") + 1:]
    if len(argv) != 4:
        raise SystemExit("usage: ... -- SCENE.json OUT.exr SEED SPP")
    return argv[0], argv[1], int(argv[2]), int(argv[3])


def reset():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    return scene


def nodes_of(material):
    material.use_nodes = True
    tree = material.node_tree
    for n in list(tree.nodes):
        tree.nodes.remove(n)
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    return tree, out


def make_material(name, spec):
    """One rayforge JSON material as a Cycles node tree (the subset the references use)."""
    known = {"base_color", "specular", "metallic", "roughness", "transmission", "ior", "emission",
             "two_sided_emission"}
    unknown = set(spec) - known
    if unknown:
        raise SystemExit("material %s: no Cycles mapping for %s" % (name, sorted(unknown)))
    material = bpy.data.materials.new(name)
    tree, out = nodes_of(material)
    color = list(spec.get("base_color", [0.8, 0.8, 0.8])) + [1.0]
    roughness = float(spec.get("roughness", 1.0))
    if "emission" in spec:
        emission = tree.nodes.new("ShaderNodeEmission")
        emission.inputs["Color"].default_value = list(spec["emission"]) + [1.0]
        emission.inputs["Strength"].default_value = 1.0
        emitted = emission.outputs[0]
        if not spec.get("two_sided_emission", False):  # front face only: no emission from the back
            geometry = tree.nodes.new("ShaderNodeNewGeometry")
            black = tree.nodes.new("ShaderNodeEmission")
            black.inputs["Strength"].default_value = 0.0
            mix = tree.nodes.new("ShaderNodeMixShader")
            tree.links.new(geometry.outputs["Backfacing"], mix.inputs["Fac"])
            tree.links.new(emission.outputs[0], mix.inputs[1])
            tree.links.new(black.outputs[0], mix.inputs[2])
            emitted = mix.outputs[0]
        if max(color[:3]) > 0:  # an emitter that also reflects (Lambert)
            diffuse = tree.nodes.new("ShaderNodeBsdfDiffuse")
            diffuse.inputs["Color"].default_value = color
            diffuse.inputs["Roughness"].default_value = 0.0
            both = tree.nodes.new("ShaderNodeAddShader")
            tree.links.new(diffuse.outputs[0], both.inputs[0])
            tree.links.new(emitted, both.inputs[1])
            emitted = both.outputs[0]
        tree.links.new(emitted, out.inputs["Surface"])
        return material
    if float(spec.get("transmission", 0)) >= 1.0:
        bsdf = tree.nodes.new("ShaderNodeBsdfGlass")
        bsdf.distribution = "MULTI_GGX"
        bsdf.inputs["IOR"].default_value = float(spec.get("ior", 1.5))
        bsdf.inputs["Roughness"].default_value = roughness
    elif float(spec.get("metallic", 0)) >= 1.0:
        if min(color[:3]) < 1.0:
            raise SystemExit("material %s: reference conductors are white (F0 = 1)" % name)
        bsdf = tree.nodes.new("ShaderNodeBsdfGlossy")
        bsdf.distribution = "MULTI_GGX"
        bsdf.inputs["Roughness"].default_value = roughness
    elif float(spec.get("specular", 1)) == 0.0:
        bsdf = tree.nodes.new("ShaderNodeBsdfDiffuse")
        bsdf.inputs["Roughness"].default_value = 0.0
    else:
        raise SystemExit("material %s: only Lambert, white conductors, glass and emitters are mapped" % name)
    bsdf.inputs["Color"].default_value = color
    tree.links.new(bsdf.outputs[0], out.inputs["Surface"])
    return material


def read_mtl(path):
    """The MTL materials of an OBJ file as rayforge JSON materials (Lambert
    with Kd when Ks = 0 or illum 0/1, emission Ke); others are refused."""
    materials, name = {}, None
    with open(path) as f:
        for line in f:
            words = line.split("#")[0].split()
            if not words:
                continue
            if words[0] == "newmtl":
                name = " ".join(words[1:])
                materials[name] = {"Kd": [0.8] * 3, "Ks": [0.0] * 3, "Ke": [0.0] * 3, "illum": 2}
            elif name and words[0] in ("Kd", "Ks", "Ke"):
                materials[name][words[0]] = [float(x) for x in words[1:4]]
            elif name and words[0] == "illum":
                materials[name]["illum"] = int(words[1])
    out = {}
    for name, m in materials.items():
        if max(m["Ks"]) > 0 and m["illum"] not in (0, 1):
            raise SystemExit("%s: material %s has a specular layer; the references map only Lambert MTL materials"
                             % (path, name))
        spec = {"base_color": m["Kd"], "specular": 0}
        if max(m["Ke"]) > 0:
            spec["emission"] = m["Ke"]
        out[name] = spec
    return out


def mtl_of(obj_path):
    with open(obj_path) as f:
        for line in f:
            if line.startswith("mtllib"):
                return os.path.join(os.path.dirname(obj_path), line.split(None, 1)[1].strip())
    return None


def lambert_from_gltf(material):
    """Replaces an imported glTF material (metallic 0, specular 0) by a
    Diffuse BSDF fed by its base colour texture."""
    tree = material.node_tree
    images = [n for n in tree.nodes if n.type == "TEX_IMAGE"]
    if len(images) != 1:
        raise SystemExit("glTF material %s: expected one base colour image" % material.name)
    image = images[0]
    # Cycles filters 8-bit sRGB texels before decoding them (in sRGB space),
    # which darkens every edge between light and dark texels; rayforge decodes
    # first. Nearest texels make the region means the same integral.
    image.interpolation = "Closest"
    out = next(n for n in tree.nodes if n.type == "OUTPUT_MATERIAL")
    diffuse = tree.nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Roughness"].default_value = 0.0
    tree.links.new(image.outputs["Color"], diffuse.inputs["Color"])
    tree.links.new(diffuse.outputs[0], out.inputs["Surface"])


def import_mesh(path, material):
    before = set(bpy.data.objects)
    if path.lower().endswith(".obj"):
        bpy.ops.wm.obj_import(filepath=path, forward_axis="Y", up_axis="Z")
    elif path.lower().endswith((".gltf", ".glb")):
        import numpy  # Debian's glTF add-on (Blender 3.4) still uses np.bool, gone since numpy 1.24
        if "bool" not in numpy.__dict__:
            numpy.bool = bool
        bpy.ops.import_scene.gltf(filepath=path)
    else:
        raise SystemExit("%s: the references import only OBJ and glTF" % path)
    added = [o for o in bpy.data.objects if o not in before]
    if path.lower().endswith((".gltf", ".glb")):
        y_up = Matrix.Rotation(-math.pi / 2, 4, "X")  # undo the importer's Y-up -> Z-up
        for o in added:
            if o.parent is None:
                o.matrix_world = y_up @ o.matrix_world
    for o in added:
        if o.type != "MESH":
            continue
        if material is not None:
            o.data.materials.clear()
            o.data.materials.append(material)
        elif path.lower().endswith(".obj"):
            mtl = mtl_of(path)
            specs = read_mtl(mtl) if mtl else {}
            for i, m in enumerate(o.data.materials):
                name = m.name if m.name in specs else m.name.rsplit(".", 1)[0]
                if name not in specs:
                    raise SystemExit("%s: material %s is not in its MTL file" % (path, m.name))
                o.data.materials[i] = make_material(name, specs[name])
        else:
            for m in o.data.materials:
                lambert_from_gltf(m)


def place_camera(scene, camera, size):
    eye, target = Vector(camera["eye"]), Vector(camera["target"])
    up = Vector(camera.get("up", [0, 1, 0]))
    forward = (target - eye).normalized()
    right = forward.cross(up).normalized()
    true_up = right.cross(forward)
    rotation = Matrix((right, true_up, -forward)).transposed()  # camera looks down its -Z, up +Y
    data = bpy.data.cameras.new("camera")
    data.sensor_fit = "VERTICAL"
    data.angle_y = math.radians(float(camera.get("fov", 45)))
    data.clip_start = 1e-3
    data.clip_end = 1e4
    obj = bpy.data.objects.new("camera", data)
    obj.matrix_world = Matrix.Translation(eye) @ rotation.to_4x4()
    scene.collection.objects.link(obj)
    scene.camera = obj


def set_world(scene, environment):
    world = bpy.data.worlds.new("world")
    world.use_nodes = True
    background = world.node_tree.nodes["Background"]
    color = list(environment.get("color", [0, 0, 0])) if environment else [0, 0, 0]
    background.inputs["Color"].default_value = color + [1.0]
    background.inputs["Strength"].default_value = float(environment.get("strength", 1.0)) if environment else 0.0
    scene.world = world


def configure(scene, render, seed, spp):
    size = (int(render["width"]), int(render["height"]))
    scene.render.resolution_x, scene.render.resolution_y = size
    scene.render.resolution_percentage = 100
    scene.render.pixel_aspect_x = scene.render.pixel_aspect_y = 1
    c = scene.cycles
    c.device = "CPU"
    c.samples = spp
    c.seed = seed
    c.use_adaptive_sampling = False
    c.use_denoising = False
    c.pixel_filter_type = "BOX"
    c.filter_width = 1.0
    bounces = max(0, int(render.get("max_depth", 8)) - 1)
    c.max_bounces = c.diffuse_bounces = c.glossy_bounces = c.transmission_bounces = bounces
    c.transparent_max_bounces = c.volume_bounces = bounces
    c.min_light_bounces = c.min_transparent_bounces = 0
    c.caustics_reflective = c.caustics_refractive = True
    c.blur_glossy = 0.0
    c.sample_clamp_direct = c.sample_clamp_indirect = 0.0
    c.light_sampling_threshold = 0.0
    c.film_exposure = 1.0
    scene.render.film_transparent = False
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    scene.render.use_compositing = False
    scene.render.use_sequencer = False
    settings = scene.render.image_settings
    settings.file_format = "OPEN_EXR"
    settings.color_mode = "RGB"
    settings.color_depth = "16"
    settings.exr_codec = "ZIP"


def main():
    scene_path, out_path, seed, spp = args()
    with open(scene_path) as f:
        doc = json.load(f)
    base = os.path.dirname(os.path.abspath(scene_path))
    scene = reset()
    materials = {name: make_material(name, spec) for name, spec in doc.get("materials", {}).items()}
    for entry in doc["meshes"]:
        if "transform" in entry:
            raise SystemExit("mesh transforms are not mapped; bake them into the reference meshes")
        material = materials[entry["material"]] if "material" in entry else None
        import_mesh(os.path.join(base, entry["file"]), material)
    render = doc["render"]
    place_camera(scene, doc["camera"], (render["width"], render["height"]))
    set_world(scene, doc.get("environment"))
    configure(scene, render, seed, spp)
    scene.render.filepath = os.path.abspath(out_path)
    bpy.ops.render.render(write_still=True)


main()
