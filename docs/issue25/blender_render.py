"""Open a morph's glTF in Blender and render its first, middle and last frames.

    blender -b --python docs/issue25/blender_render.py -- morph.glb frame

prints the mesh, its shape keys and the action's frame range, and writes frame_<f>.png
(Cycles on the CPU; Blender 3.4 from Debian, whose glTF add-on needs the numpy.bool alias
that numpy 1.24 removed).
"""

import sys

import numpy

numpy.bool = bool  # Blender 3.4's glTF add-on uses the alias

import bpy  # noqa: E402
import mathutils  # noqa: E402

path, out = sys.argv[-2], sys.argv[-1]
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.gltf(filepath=path)
obj = next(o for o in bpy.context.scene.objects if o.type == "MESH")
keys = obj.data.shape_keys.key_blocks
action = obj.data.shape_keys.animation_data.action
print("BLENDER", len(obj.data.vertices), "vertices", len(obj.data.polygons), "faces",
      len(keys) - 1, "shape keys, frames", tuple(action.frame_range))
bpy.ops.object.shade_smooth()
clay = bpy.data.materials.new("clay")
clay.diffuse_color = (0.8, 0.55, 0.4, 1)
obj.data.materials.append(clay)
scene = bpy.context.scene
scene.render.engine = "CYCLES"
scene.cycles.samples, scene.cycles.device, scene.cycles.use_denoising = 16, "CPU", False
scene.render.resolution_x, scene.render.resolution_y = 360, 300
scene.world = bpy.data.worlds.new("white")
sun = bpy.data.objects.new("sun", bpy.data.lights.new("sun", "SUN"))
sun.data.energy, sun.rotation_euler = 3, (0.6, 0.3, 0.8)
scene.collection.objects.link(sun)
corners = [obj.matrix_world @ mathutils.Vector(c) for c in obj.bound_box]
centre = sum(corners, mathutils.Vector()) / 8
radius = max((c - centre).length for c in corners)
camera = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
scene.collection.objects.link(camera)
scene.camera = camera
camera.location = centre + mathutils.Vector((0, -3.2 * radius, 0.8 * radius))
camera.rotation_euler = (centre - camera.location).to_track_quat("-Z", "Y").to_euler()
end = int(action.frame_range[1])
for frame in (0, end // 2, end):
    scene.frame_set(frame)
    scene.render.filepath = f"{out}_{frame}.png"
    bpy.ops.render.render(write_still=True)
    print("BLENDER frame", frame, "shape keys at weight 1:",
          [k.name for k in keys if k.value > 0.5])
