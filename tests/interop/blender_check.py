# SPDX-License-Identifier: Apache-2.0
"""Blender side of test_blender.py: opens .vdb files the way a Blender user does and reports.

Run as `blender -b --factory-startup --python blender_check.py -- JOB.json RESULT.json`.
JOB.json is {"imports": [PATH, ...], "meshes": [{"file", "grid", "threshold"}, ...],
"sequences": [{"file", "files", "grid", "frames"}, ...], "render": {"file", "grid", "size", "samples",
"output"} or null}. RESULT.json gets, per import, the object type and the grids Blender sees; per
mesh, the Volume to Mesh modifier's mesh (vertex and face counts, enclosed volume, bounding box);
per sequence (its files selected together in File > Import > OpenVDB, with frame-sequence
detection, Blender's default), the objects added, the sequence's frame range, and at each of the
given scene frames the file Blender loads and its Volume to Mesh measures; for the render, the
engine and how many pixels the volume covers. The assertions are in test_blender.py: this script only measures, and any
exception is written to RESULT.json as "error".
"""

import json
import math
import os
import sys
import traceback

import bmesh
import bpy


def clearScene():
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj, do_unlink=True)
    for volume in list(bpy.data.volumes):
        bpy.data.volumes.remove(volume)
    for mesh in list(bpy.data.meshes):
        bpy.data.meshes.remove(mesh)


def importVolume(path, sequence=()):
    """File > Import > OpenVDB of one file (no frame-sequence detection), or of the files of a
    sequence selected together in the file browser (with detection, Blender's default)."""
    before = set(bpy.data.objects)
    names = [os.path.basename(p) for p in sequence] or [os.path.basename(path)]
    bpy.ops.object.volume_import(
        filepath=path, directory=os.path.dirname(path),
        files=[{"name": n} for n in names], use_sequence_detection=bool(sequence))
    added = [o for o in bpy.data.objects if o not in before]
    if len(added) != 1:
        raise RuntimeError(f"{path}: volume_import added {len(added)} objects")
    return added[0]


def describeImport(path):
    obj = importVolume(path)
    result = {"file": path, "object_type": obj.type, "grids": [], "error_message": ""}
    if obj.type != "VOLUME":
        return result
    grids = obj.data.grids
    grids.load()
    result["is_loaded"] = bool(grids.is_loaded)
    result["error_message"] = grids.error_message
    for grid in grids:
        grid.load()
        result["grids"].append({
            "name": grid.name,
            "data_type": grid.data_type,
            "channels": grid.channels,
            "is_loaded": bool(grid.is_loaded),
            "matrix_object": [list(row) for row in grid.matrix_object],
        })
    return result


def meshVolume(mesh):
    """Signed enclosed volume of a closed mesh (divergence theorem over its triangles)."""
    bm = bmesh.new()
    bm.from_mesh(mesh)
    volume = bm.calc_volume(signed=True)
    bm.free()
    return volume


def volumeToMesh(job, volumeObj=None):
    """A mesh object with the Volume to Mesh modifier on the imported volume, evaluated."""
    volumeObj = volumeObj or importVolume(job["file"])
    mesh = bpy.data.meshes.new("v2m")
    meshObj = bpy.data.objects.new("v2m", mesh)
    bpy.context.scene.collection.objects.link(meshObj)
    modifier = meshObj.modifiers.new(name="VolumeToMesh", type="VOLUME_TO_MESH")
    modifier.object = volumeObj
    modifier.grid_name = job["grid"]
    modifier.threshold = job.get("threshold", 0.0)
    modifier.adaptivity = 0.0
    modifier.resolution_mode = "GRID"
    depsgraph = bpy.context.evaluated_depsgraph_get()
    evaluated = meshObj.evaluated_get(depsgraph)
    out = evaluated.to_mesh()
    coords = [v.co for v in out.vertices]
    result = {
        "file": job["file"], "grid": job["grid"],
        "vertices": len(out.vertices), "faces": len(out.polygons),
        "volume": meshVolume(out) if len(out.polygons) else 0.0,
        "bbox_min": [min(c[i] for c in coords) for i in range(3)] if coords else None,
        "bbox_max": [max(c[i] for c in coords) for i in range(3)] if coords else None,
    }
    evaluated.to_mesh_clear()
    return result


def describeSequence(job):
    """One import of a frame sequence, then Volume to Mesh at each of the job's frames."""
    before = len(bpy.data.objects)
    volumeObj = importVolume(job["file"], sequence=job["files"])
    volume = volumeObj.data
    result = {"file": job["file"], "objects_added": len(bpy.data.objects) - before,
              "object_type": volumeObj.type, "is_sequence": bool(volume.is_sequence),
              "frame_start": volume.frame_start, "frame_duration": volume.frame_duration,
              "frames": []}
    for frame in job["frames"]:
        bpy.context.scene.frame_set(frame)
        measured = volumeToMesh(job, volumeObj)
        measured["scene_frame"] = frame
        # The file of this frame is known to the evaluated volume (the one the modifier read).
        evaluated = volumeObj.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
        evaluated.grids.load()
        measured["frame"] = evaluated.grids.frame
        measured["frame_filepath"] = bpy.path.abspath(evaluated.grids.frame_filepath)
        result["frames"].append(measured)
    return result


def renderFog(job):
    """Cycles on the CPU: the fog volume with a Principled Volume material reading the grid."""
    clearScene()
    scene = bpy.context.scene
    volumeObj = importVolume(job["file"])
    material = bpy.data.materials.new("fog")
    material.use_nodes = True
    nodes = material.node_tree.nodes
    for node in list(nodes):
        nodes.remove(node)
    shader = nodes.new("ShaderNodeVolumePrincipled")
    shader.inputs["Density"].default_value = job.get("density", 5.0)
    shader.inputs["Density Attribute"].default_value = job["grid"]
    output = nodes.new("ShaderNodeOutputMaterial")
    material.node_tree.links.new(shader.outputs["Volume"], output.inputs["Volume"])
    volumeObj.data.materials.append(material)

    # Camera on +y looking at the volume's centre, far enough to frame its bounding box.
    lo, hi = job["bbox_min"], job["bbox_max"]
    centre = [(a + b) / 2 for a, b in zip(lo, hi)]
    radius = 0.5 * math.dist(lo, hi)
    cameraData = bpy.data.cameras.new("camera")
    cameraData.angle = math.radians(40)
    camera = bpy.data.objects.new("camera", cameraData)
    scene.collection.objects.link(camera)
    camera.location = (centre[0], centre[1] - radius / math.sin(math.radians(20)) * 1.1, centre[2])
    camera.rotation_euler = (math.radians(90), 0, 0)
    scene.camera = camera
    lightData = bpy.data.lights.new("sun", type="SUN")
    lightData.energy = 3.0
    light = bpy.data.objects.new("sun", lightData)
    scene.collection.objects.link(light)
    light.rotation_euler = (math.radians(45), 0, math.radians(30))

    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = job.get("samples", 4)
    scene.cycles.use_denoising = False
    scene.render.resolution_x = job["size"]
    scene.render.resolution_y = job["size"]
    scene.render.resolution_percentage = 100
    scene.render.film_transparent = True
    scene.render.image_settings.file_format = "PNG"
    scene.render.image_settings.color_mode = "RGBA"
    scene.render.filepath = job["output"]
    bpy.ops.render.render(write_still=True)

    image = bpy.data.images.load(job["output"])
    pixels = list(image.pixels)
    alphas = pixels[3::4]
    covered = sum(1 for a in alphas if a > 0.05)
    return {"file": job["file"], "engine": scene.render.engine, "output": job["output"],
            "width": image.size[0], "height": image.size[1],
            "covered_pixels": covered, "max_alpha": max(alphas),
            "centre_alpha": alphas[(job["size"] // 2) * job["size"] + job["size"] // 2]}


def main():
    argv = sys.argv[sys.argv.index("--") + 1:]
    jobPath, resultPath = argv
    with open(jobPath) as f:
        job = json.load(f)
    result = {"blender_version": bpy.app.version_string, "imports": [], "meshes": [],
              "sequences": [], "render": None}
    try:
        for path in job.get("imports", []):
            clearScene()
            result["imports"].append(describeImport(path))
        for meshJob in job.get("meshes", []):
            clearScene()
            result["meshes"].append(volumeToMesh(meshJob))
        for sequenceJob in job.get("sequences", []):
            clearScene()
            result["sequences"].append(describeSequence(sequenceJob))
        if job.get("render"):
            result["render"] = renderFog(job["render"])
    except Exception:  # reported to the test, which fails with it
        result["error"] = traceback.format_exc()
    with open(resultPath, "w") as f:
        json.dump(result, f, indent=1)


main()
