"""Path-traced test scenes for degs, rendered by Blender's Cycles (issue #32).

Scenes made by a renderer that is not the project's own, so that the analytic `degs
synth` presets' blind spots (no anti-aliasing noise, no soft shadows, shading that the
project's own model can represent exactly) do not hide a weakness:

  spin   a textured, bevelled box spinning under a sun, the camera drifting sideways
  slide  two cubes and a ball sliding and turning across a textured floor, the camera
         panning

Run with Debian's blender (not needed by degs itself):

  blender -b -noaudio --factory-startup -P scripts/blender_scenes.py -- \
      --scene spin --out DIR [--size 128] [--rate 480] [--seconds 1] [--samples 64]

DIR receives
  hr/frame_NNNNN.png   every frame at --rate fps, 16-bit sRGB, and hr/timestamps.txt
                       (seconds): the input of an event simulator (`evflow simulate`)
  images/              8-bit sRGB frames: hr_NNNNN.png (the frames a train split may
                       use), test_NNNN.png (in-between times), novel_NNNN.png (a camera
                       rotated --novel-deg about the vertical axis through the target,
                       at the test times)
  gt/{test,novel}/object_NNNN.png  nonzero where a moving object covers the test frame
                       or novel view (anti-aliased edges included), else 0
  cameras.json         intrinsics (degs conventions: pixel centres at integers, so
                       cx = (w - 1) / 2) and every rendered view's camera-to-world
                       matrix (OpenGL axes, as Blender's camera) and time
  depth/hr_NNNNN.exr   with --depth-only (into an earlier render's DIR): the camera
                       depth (channel Z, −z in the camera's axes, each pixel's ray cast
                       through the scene) of every hr frame on the 20 fps grid, for a
                       depth prior

`scripts/outside_scene.py` turns DIR into degs scene directories at a chosen train
frame rate. Times: frame i of hr/ is at i / rate seconds; the test times are the hr
frames 24k + 6 and 24k + 18 at the default rate (midway between 20 fps frames, a
quarter of the way between 10 fps frames).
"""

import argparse
import json
import math
import os
import sys

import bpy
from mathutils import Matrix, Vector


def parse_args():
    argv = sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else []
    p = argparse.ArgumentParser(prog="blender_scenes.py")
    p.add_argument("--scene", choices=["spin", "slide"], required=True)
    p.add_argument("--out", required=True)
    p.add_argument("--size", type=int, default=128)
    p.add_argument("--rate", type=int, default=240, help="hr frames per second")
    p.add_argument("--seconds", type=float, default=1.0)
    p.add_argument("--samples", type=int, default=48)
    p.add_argument("--seed", type=int, default=0, help="Cycles' sampling seed")
    p.add_argument("--novel-deg", type=float, default=15.0)
    p.add_argument("--fov-deg", type=float, default=50.0)
    p.add_argument(
        "--masks-only",
        action="store_true",
        help="render only the moving-object masks (into an earlier render's DIR)",
    )
    p.add_argument(
        "--depth-only",
        action="store_true",
        help="render only the train frames' depth (into an earlier render's DIR)",
    )
    args = p.parse_args(argv)
    if args.rate % 20:
        p.error("--rate must be a multiple of 20 (train frames at 10 and 20 fps)")
    return args


def clear():
    bpy.ops.wm.read_factory_settings(use_empty=True)


def material(name, build):
    """A node material; `build(nodes, links, bsdf)` wires the base colour."""
    m = bpy.data.materials.new(name)
    m.use_nodes = True
    nodes, links = m.node_tree.nodes, m.node_tree.links
    for n in list(nodes):
        nodes.remove(n)
    out = nodes.new("ShaderNodeOutputMaterial")
    bsdf = nodes.new("ShaderNodeBsdfPrincipled")
    bsdf.inputs["Roughness"].default_value = 0.55
    bsdf.inputs["Specular"].default_value = 0.3
    links.new(bsdf.outputs["BSDF"], out.inputs["Surface"])
    build(nodes, links, bsdf)
    return m


def object_coords(nodes):
    tc = nodes.new("ShaderNodeTexCoord")
    return tc.outputs["Object"]


def ramp(nodes, links, fac, colours):
    r = nodes.new("ShaderNodeValToRGB")
    els = r.color_ramp.elements
    while len(els) < len(colours):
        els.new(0.5)
    for i, (pos, c) in enumerate(colours):
        els[i].position = pos
        els[i].color = (*c, 1.0)
    links.new(fac, r.inputs["Fac"])
    return r.outputs["Color"]


def checker_mat(name, scale, c1, c2):
    def build(nodes, links, bsdf):
        t = nodes.new("ShaderNodeTexChecker")
        t.inputs["Scale"].default_value = scale
        t.inputs["Color1"].default_value = (*c1, 1.0)
        t.inputs["Color2"].default_value = (*c2, 1.0)
        links.new(object_coords(nodes), t.inputs["Vector"])
        links.new(t.outputs["Color"], bsdf.inputs["Base Color"])

    return material(name, build)


def noise_mat(name, scale, colours, voronoi=False):
    def build(nodes, links, bsdf):
        if voronoi:
            t = nodes.new("ShaderNodeTexVoronoi")
            t.inputs["Scale"].default_value = scale
            fac = t.outputs["Distance"]
        else:
            t = nodes.new("ShaderNodeTexNoise")
            t.inputs["Scale"].default_value = scale
            t.inputs["Detail"].default_value = 6.0
            fac = t.outputs["Fac"]
        links.new(object_coords(nodes), t.inputs["Vector"])
        links.new(ramp(nodes, links, fac, colours), bsdf.inputs["Base Color"])

    return material(name, build)


def add(kind, name, mat, **kw):
    if kind == "plane":
        bpy.ops.mesh.primitive_plane_add(**kw)
    elif kind == "cube":
        bpy.ops.mesh.primitive_cube_add(**kw)
    elif kind == "sphere":
        bpy.ops.mesh.primitive_uv_sphere_add(segments=64, ring_count=32, **kw)
    o = bpy.context.active_object
    o.name = name
    o.data.materials.append(mat)
    if kind == "sphere":
        bpy.ops.object.shade_smooth()
    return o


def bevel(o, width):
    m = o.modifiers.new("bevel", "BEVEL")
    m.width = width
    m.segments = 4


def world_and_light(strength=3.5, ambient=0.25):
    w = bpy.data.worlds.new("world")
    w.use_nodes = True
    bg = w.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (0.55, 0.6, 0.7, 1.0)
    bg.inputs["Strength"].default_value = ambient
    bpy.context.scene.world = w
    sun = bpy.data.lights.new("sun", "SUN")
    sun.energy = strength
    sun.angle = math.radians(3.0)
    o = bpy.data.objects.new("sun", sun)
    o.rotation_euler = (math.radians(40), math.radians(15), math.radians(35))
    bpy.context.scene.collection.objects.link(o)


def room():
    floor = add(
        "plane",
        "floor",
        checker_mat("floor", 6.0, (0.75, 0.7, 0.6), (0.2, 0.22, 0.3)),
        size=8,
        location=(0, 0, 0),
    )
    wall = add(
        "plane",
        "wall",
        noise_mat(
            "wall",
            2.5,
            [(0.3, (0.15, 0.3, 0.25)), (0.7, (0.85, 0.8, 0.55))],
            voronoi=True,
        ),
        size=8,
        location=(0, 3.0, 4.0),
        rotation=(math.radians(90), 0, 0),
    )
    return [floor, wall]


def look_at(eye, target):
    """Camera-to-world rotation of a camera at `eye` looking at `target`, world +Z up."""
    f = (Vector(target) - Vector(eye)).normalized()
    r = f.cross(Vector((0, 0, 1))).normalized()
    u = r.cross(f)
    # Blender camera axes: x right, y up, looking down -z (OpenGL).
    return Matrix(((r.x, u.x, -f.x), (r.y, u.y, -f.y), (r.z, u.z, -f.z)))


def scene_spin(seconds):
    room()
    box = add(
        "cube",
        "box",
        noise_mat(
            "box",
            5.0,
            [(0.15, (0.85, 0.15, 0.05)), (0.35, (0.95, 0.85, 0.3)), (0.6, (0.05, 0.2, 0.7))],
            voronoi=True,
        ),
        size=1.0,
        location=(0, 0, 0.9),
    )
    bevel(box, 0.08)
    box.rotation_mode = "XYZ"

    def animate(t):
        # One turn per second about a tilted axis: surface speed ~2 px per 10 ms at 128².
        box.rotation_euler = (math.radians(20), 0.35 * math.sin(2 * math.pi * t), 2 * math.pi * t)

    target = (0.0, 0.0, 0.8)

    def camera(t):
        eye = (-0.35 + 0.7 * t / seconds, -3.6, 1.7 + 0.1 * math.sin(math.pi * t / seconds))
        return eye, target

    return animate, camera, target, [box]


def scene_slide(seconds):
    room()
    a = add(
        "cube",
        "cube_a",
        checker_mat("cube_a", 4.0, (0.85, 0.2, 0.15), (0.95, 0.9, 0.8)),
        size=0.6,
        location=(0, 0, 0.3),
    )
    b = add(
        "cube",
        "cube_b",
        noise_mat("cube_b", 4.0, [(0.2, (0.1, 0.5, 0.2)), (0.8, (0.9, 0.9, 0.4))], voronoi=True),
        size=0.5,
        location=(0, 0, 0.25),
    )
    ball = add(
        "sphere",
        "ball",
        noise_mat("ball", 4.0, [(0.3, (0.2, 0.3, 0.9)), (0.7, (0.95, 0.95, 0.95))]),
        radius=0.3,
        location=(0, 0, 0.3),
    )

    def animate(t):
        s = t / seconds
        a.location = (-1.1 + 1.3 * s, 0.8, 0.3)
        a.rotation_euler = (0, 0, math.radians(100) * s)
        b.location = (1.0 - 1.1 * s, -0.2 + 0.3 * s, 0.25)
        b.rotation_euler = (0, 0, -math.radians(140) * s)
        # Rolling without slipping along +y then curving.
        d = 1.2 * s
        ball.location = (0.5 + 0.15 * math.sin(math.pi * s), -1.4 + d, 0.3)
        ball.rotation_euler = (-d / 0.3, 0, 0)

    target = (0.0, 0.0, 0.3)

    def camera(t):
        s = t / seconds
        yaw = math.radians(-8 + 16 * s)
        eye = (3.4 * math.sin(yaw) + 0.3 * s, -3.4 * math.cos(yaw), 1.9)
        pan = (0.25 * math.sin(2 * math.pi * s), 0.0, 0.3)
        return eye, pan

    return animate, camera, target, [a, b, ball]


def camera_matrix(eye, target):
    m = look_at(eye, target).to_4x4()
    m.translation = Vector(eye)
    return m


def rotate_about_vertical(m, centre, deg):
    c = Vector(centre)
    rot = Matrix.Rotation(math.radians(deg), 4, "Z")
    return Matrix.Translation(c) @ rot @ Matrix.Translation(-c) @ m


def setup_render(size, samples, seed):
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    sc.cycles.device = "CPU"
    sc.cycles.samples = samples
    sc.cycles.use_denoising = False
    sc.cycles.seed = seed
    sc.cycles.use_animated_seed = False
    sc.cycles.max_bounces = 3
    sc.cycles.diffuse_bounces = 2
    sc.cycles.glossy_bounces = 1
    sc.cycles.transmission_bounces = 0
    sc.cycles.sample_clamp_indirect = 2.0
    sc.render.resolution_x = size
    sc.render.resolution_y = size
    sc.render.resolution_percentage = 100
    sc.render.film_transparent = False
    sc.view_settings.view_transform = "Standard"
    sc.view_settings.look = "None"
    sc.view_settings.exposure = 0.0
    sc.view_settings.gamma = 1.0
    sc.display_settings.display_device = "sRGB"
    sc.render.image_settings.file_format = "PNG"
    sc.render.image_settings.color_mode = "RGB"


def render_to(paths_depths):
    """Render the current state once and save it at each (path, bit depth)."""
    sc = bpy.context.scene
    bpy.ops.render.render()
    img = bpy.data.images["Render Result"]
    for path, depth in paths_depths:
        sc.render.image_settings.color_depth = depth
        img.save_render(path, scene=sc)


def render_masks(moving, paths):
    """Each path: the moving objects white on black, sampled once per pixel lightly."""
    sc = bpy.context.scene
    white = bpy.data.materials.new("mask_white")
    white.use_nodes = True
    nt = white.node_tree
    for n in list(nt.nodes):
        nt.nodes.remove(n)
    em = nt.nodes.new("ShaderNodeEmission")
    em.inputs["Strength"].default_value = 1.0
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    nt.links.new(em.outputs["Emission"], out.inputs["Surface"])
    saved = {o.name: [s.material for s in o.material_slots] for o in moving}
    others = [o for o in sc.objects if o not in moving and o.type in ("MESH", "LIGHT")]
    for o in moving:
        for s in o.material_slots:
            s.material = white
    for o in others:
        o.hide_render = True
    bg = sc.world.node_tree.nodes["Background"].inputs["Strength"]
    strength = bg.default_value
    bg.default_value = 0.0
    sc.cycles.samples = 16
    dither = sc.render.dither_intensity
    sc.render.dither_intensity = 0.0  # 8-bit dither would mark the background
    sc.render.image_settings.color_mode = "BW"
    for (t, mat), path in paths:
        yield t, mat, path
    sc.render.image_settings.color_mode = "RGB"
    sc.render.dither_intensity = dither
    bg.default_value = strength
    for o in others:
        o.hide_render = False
    for o in moving:
        for s, m in zip(o.material_slots, saved[o.name]):
            s.material = m


def write_exr_z(path, w, h, z):
    """`z` (row-major floats, top row first) as an uncompressed single-channel f32 EXR
    with channel Z (the layout degs reads; OpenEXR 2 scanline format)."""
    import struct

    def attr(name, kind, data):
        return name.encode() + b"\0" + kind.encode() + b"\0" + struct.pack("<i", len(data)) + data

    box = struct.pack("<iiii", 0, 0, w - 1, h - 1)
    header = b"".join(
        [
            struct.pack("<ii", 20000630, 2),
            attr("channels", "chlist", b"Z\0" + struct.pack("<iB3xii", 2, 0, 1, 1) + b"\0"),
            attr("compression", "compression", b"\0"),
            attr("dataWindow", "box2i", box),
            attr("displayWindow", "box2i", box),
            attr("lineOrder", "lineOrder", b"\0"),
            attr("pixelAspectRatio", "float", struct.pack("<f", 1.0)),
            attr("screenWindowCenter", "v2f", struct.pack("<ff", 0.0, 0.0)),
            attr("screenWindowWidth", "float", struct.pack("<f", 1.0)),
            b"\0",
        ]
    )
    line = 8 + 4 * w
    first = len(header) + 8 * h
    offsets = b"".join(struct.pack("<Q", first + y * line) for y in range(h))
    rows = b"".join(
        struct.pack("<ii", y, 4 * w) + struct.pack(f"<{w}f", *z[y * w : (y + 1) * w]) for y in range(h)
    )
    with open(path, "wb") as f:
        f.write(header + offsets + rows)


def render_depth(cam, size, fov_deg, path):
    """Each pixel's camera depth (−z in the camera's axes) by casting its ray through
    the scene as it is now (pixel centres at integers, as in cameras.json), to `path`."""
    dg = bpy.context.evaluated_depsgraph_get()
    f = (size / 2) / math.tan(math.radians(fov_deg) / 2)
    c = (size - 1) / 2
    m = cam.matrix_world
    origin = m.translation
    rot = m.to_3x3()
    inv = m.inverted()
    z = []
    for y in range(size):
        for x in range(size):
            d = rot @ Vector(((x - c) / f, -(y - c) / f, -1.0))
            hit, loc, _, _, _, _ = bpy.context.scene.ray_cast(dg, origin, d.normalized())
            z.append(max(-(inv @ loc).z, 0.0) if hit else 0.0)
    write_exr_z(path, size, size, z)


def main():
    args = parse_args()
    clear()
    build = {"spin": scene_spin, "slide": scene_slide}[args.scene]
    animate, camera_at, target, moving = build(args.seconds)
    world_and_light()
    setup_render(args.size, args.samples, args.seed)
    sc = bpy.context.scene
    cam_data = bpy.data.cameras.new("cam")
    cam_data.sensor_fit = "HORIZONTAL"
    cam_data.angle = math.radians(args.fov_deg)
    cam = bpy.data.objects.new("cam", cam_data)
    sc.collection.objects.link(cam)
    sc.camera = cam

    out = os.path.abspath(args.out)
    if args.depth_only:
        if not os.path.isfile(os.path.join(out, "cameras.json")):
            sys.exit(f"{out}: not an earlier render of this script (no cameras.json)")
        os.makedirs(os.path.join(out, "depth"), exist_ok=False)
        n = int(round(args.rate * args.seconds))
        frames = [i for i in range(n + 1) if i % (args.rate // 20) == 0]
        for k, i in enumerate(frames):
            t = i / args.rate
            eye, look = camera_at(t)
            animate(t)
            cam.matrix_world = camera_matrix(eye, look)
            bpy.context.view_layer.update()
            path = os.path.join(out, "depth", f"hr_{i:05d}.exr")
            render_depth(cam, args.size, args.fov_deg, path)
            print(f"blender_scenes: {args.scene} depth {k + 1}/{len(frames)}", flush=True)
        return
    if args.masks_only:
        if not os.path.isfile(os.path.join(out, "cameras.json")):
            sys.exit(f"{out}: not an earlier render of this script (no cameras.json)")
    elif os.path.exists(out) and os.listdir(out):
        sys.exit(f"{out}: exists and is not empty; give a new folder")
    for d in ("hr", "images", "gt/novel", "gt/test"):
        os.makedirs(os.path.join(out, d), exist_ok=True)
    n = int(round(args.rate * args.seconds))
    period = args.rate // 10  # hr frames per 10 fps frame interval
    test_idx = [i for i in range(n + 1) if i % period in (period // 4, 3 * period // 4)]
    views = {"hr": [], "test": [], "novel": []}

    def place(t, mat):
        animate(t)
        cam.matrix_world = mat
        bpy.context.view_layer.update()

    total = (0 if args.masks_only else n + 1 + len(test_idx)) + 2 * len(test_idx)
    done = 0

    def progress(what):
        nonlocal done
        done += 1
        print(f"blender_scenes: {args.scene} {done}/{total} {what}", flush=True)

    with open(os.path.join(out, "hr", "timestamps.txt"), "w") as ts:
        for i in range(n + 1):
            t = i / args.rate
            eye, look = camera_at(t)
            mat = camera_matrix(eye, look)
            if not args.masks_only:
                place(t, mat)
                render_to(
                    [
                        (os.path.join(out, "hr", f"frame_{i:05d}.png"), "16"),
                        (os.path.join(out, "images", f"hr_{i:05d}.png"), "8"),
                    ]
                )
                progress("hr")
            ts.write(f"{t:.9f}\n")
            views["hr"].append({"index": i, "time": t, "transform_matrix": [list(r) for r in mat]})
    novel = []
    for k, i in enumerate(test_idx):
        t = i / args.rate
        eye, look = camera_at(t)
        mat = rotate_about_vertical(camera_matrix(eye, look), target, args.novel_deg)
        if not args.masks_only:
            place(t, mat)
            render_to([(os.path.join(out, "images", f"novel_{k:04d}.png"), "8")])
            progress("novel")
        views["novel"].append({"time": t, "transform_matrix": [list(r) for r in mat]})
        views["test"].append({"index": i, "time": t})
        novel.append((t, mat))
    jobs = [
        ((t, mat), os.path.join(out, "gt", "novel", f"object_{k:04d}.png"))
        for k, (t, mat) in enumerate(novel)
    ]
    for k, i in enumerate(test_idx):
        t = i / args.rate
        eye, look = camera_at(t)
        jobs.append(((t, camera_matrix(eye, look)), os.path.join(out, "gt", "test", f"object_{k:04d}.png")))
    for t, mat, path in render_masks(moving, jobs):
        place(t, mat)
        render_to([(path, "8")])
        progress("mask")
    fx = (args.size / 2) / math.tan(math.radians(args.fov_deg) / 2)
    meta = {
        "scene": args.scene,
        "renderer": f"Blender {bpy.app.version_string} Cycles, {args.samples} samples, seed {args.seed}",
        "camera": {
            "w": args.size,
            "h": args.size,
            "fl_x": fx,
            "fl_y": fx,
            "cx": (args.size - 1) / 2,
            "cy": (args.size - 1) / 2,
        },
        "rate": args.rate,
        "seconds": args.seconds,
        "novel_deg": args.novel_deg,
        "target": list(target),
        "views": views,
    }
    with open(os.path.join(out, "cameras.json"), "w") as f:
        json.dump(meta, f, indent=1)


main()
