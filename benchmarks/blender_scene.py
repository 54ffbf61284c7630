"""Runs inside Blender (``blender -b --factory-startup -P benchmarks/blender_scene.py -- ARGS``): imports one
GLB with Blender's own glTF importer, reports what Blender sees in it, and renders its base-colour texture
from an orbit camera. ``benchmarks/blender_check.py`` drives it; nothing of mesh2tex is imported here.

    -- GLB OUT.png REPORT.json AZIMUTH ELEVATION DISTANCE FOV SIZE

The camera follows mesh2tex's orbit convention (``mesh2tex.render.cameras``: y up, azimuth about y,
elevation above the xz plane, looking at the origin, vertical field of view) carried into Blender's
z-up world the way the glTF importer carries the mesh: (x, y, z) -> (x, -z, y). Every material's
surface becomes an emission of its base-colour texture, so the render shows the albedo the GLB carries
with no light, and the film is transparent so that the alpha channel is the object's mask.
"""

import json
import math
import sys

import bpy


def main() -> None:
    glb, png, report_path, azimuth, elevation, distance, fov, size = sys.argv[sys.argv.index("--") + 1 :]
    azimuth, elevation, distance, fov, size = float(azimuth), float(elevation), float(distance), float(fov), int(size)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    import numpy

    # Blender 3.4's glTF importer uses numpy.bool, gone since numpy 1.24 (Debian 12 pairs them)
    if "bool" not in numpy.__dict__:
        numpy.bool = bool
    bpy.ops.import_scene.gltf(filepath=glb)
    meshes = [o for o in bpy.context.scene.objects if o.type == "MESH"]
    report = {"blender": bpy.app.version_string, "objects": len(meshes), "meshes": []}
    for obj in meshes:
        mesh = obj.data
        entry = {
            "name": obj.name,
            "vertices": len(mesh.vertices),
            "polygons": len(mesh.polygons),
            "uv_layers": [layer.name for layer in mesh.uv_layers],
            "smooth_polygons": sum(1 for p in mesh.polygons if p.use_smooth),
            "custom_normals": bool(mesh.has_custom_normals),
            "materials": [],
        }
        for material in mesh.materials:
            textures = []
            if material is not None and material.use_nodes:
                nodes = material.node_tree.nodes
                bsdf = next((n for n in nodes if n.type == "BSDF_PRINCIPLED"), None)
                image_node = None
                if bsdf is not None and bsdf.inputs["Base Color"].is_linked:
                    image_node = bsdf.inputs["Base Color"].links[0].from_node
                if image_node is not None and image_node.type == "TEX_IMAGE" and image_node.image is not None:
                    image = image_node.image
                    textures.append(
                        {
                            "size": list(image.size),
                            "colorspace": image.colorspace_settings.name,
                            "file_format": image.file_format,
                        }
                    )
                    tree = material.node_tree
                    emission = nodes.new("ShaderNodeEmission")
                    tree.links.new(image_node.outputs["Color"], emission.inputs["Color"])
                    output = next(n for n in nodes if n.type == "OUTPUT_MATERIAL")
                    tree.links.new(emission.outputs["Emission"], output.inputs["Surface"])
            entry["materials"].append({"name": material.name if material else None, "base_color_textures": textures})
        report["meshes"].append(entry)

    scene = bpy.context.scene
    world = bpy.data.worlds.new("black")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0, 0, 0, 1)
    scene.world = world
    az, el = math.radians(azimuth), math.radians(elevation)
    x, y, z = distance * math.cos(el) * math.sin(az), distance * math.sin(el), distance * math.cos(el) * math.cos(az)
    camera_data = bpy.data.cameras.new("camera")
    camera_data.sensor_fit = "VERTICAL"
    camera_data.angle_y = math.radians(fov)
    camera_data.clip_start, camera_data.clip_end = 0.01, 100.0
    camera = bpy.data.objects.new("camera", camera_data)
    scene.collection.objects.link(camera)
    camera.location = (x, -z, y)
    target = bpy.data.objects.new("target", None)
    scene.collection.objects.link(target)
    track = camera.constraints.new("TRACK_TO")
    track.target, track.track_axis, track.up_axis = target, "TRACK_NEGATIVE_Z", "UP_Y"
    scene.camera = camera

    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = 16
    scene.cycles.use_denoising = False
    scene.cycles.pixel_filter_type = "BOX"
    scene.cycles.filter_width = 1.0
    scene.render.film_transparent = True
    scene.render.resolution_x = scene.render.resolution_y = size
    scene.render.resolution_percentage = 100
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.render.image_settings.file_format = "PNG"
    scene.render.image_settings.color_mode = "RGBA"
    scene.render.filepath = png
    bpy.ops.render.render(write_still=True)
    with open(report_path, "w") as f:
        json.dump(report, f, indent=1)


main()
