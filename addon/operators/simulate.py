"""Transfer: "Simulate with Viscoscope" runs the native solver on this scene and imports the
result as a .vdb sequence on a Volume object with a Volume to Mesh modifier and the fluid material."""

import os

import bpy

from .. import cup_mesh, engine, mantaflow, prefs, scene_export
from . import fluid as fluid_ops
from .runner import EngineOperator, is_running


def transfer_dir(scene):
    return os.path.join(scene_export.work_dir(scene), "transfer")


def import_result(context, out_dir):
    """Import DIR/frame_*.vdb with the scene's fluid material; returns the Volume object."""
    fluid = context.scene.viscoscope.fluid
    material = mantaflow.fluid_material(fluid, fluid_ops.material_name(fluid))
    return cup_mesh.import_vdb_sequence(context, out_dir, "Viscoscope Liquid", material)


class VISCOSCOPE_OT_simulate(EngineOperator, bpy.types.Operator):
    """Run the Viscoscope solver on this scene (objects with a Viscoscope role, the fluid material) and import the result; Esc cancels"""
    bl_idname = "viscoscope.simulate"
    bl_label = "Simulate with Viscoscope"
    job_kind = "simulate"

    @classmethod
    def poll(cls, context):
        return not is_running("simulate")

    def prepare(self, context):
        scene = context.scene
        exe = prefs.find_engine(context)
        folder = transfer_dir(scene)
        out_dir = os.path.join(folder, "out")
        os.makedirs(out_dir, exist_ok=True)
        # The engine resumes a cancelled run of the same scene from out_dir, and removes the frames
        # of any other run before it starts over.
        scene_path = os.path.join(folder, "scene.json")
        scene_export.export_scene(scene, scene_path)
        return engine.simulate_args(exe, scene_path, out_dir, prefs.threads(context)), out_dir

    def on_success(self, context, out_dir):
        import_result(context, out_dir)


class VISCOSCOPE_OT_export_scene(bpy.types.Operator):
    """Write this scene as Viscoscope scene JSON (SI units) into the work folder"""
    bl_idname = "viscoscope.export_scene"
    bl_label = "Export Scene JSON"

    filepath: bpy.props.StringProperty(subtype='FILE_PATH', default="")

    def execute(self, context):
        path = self.filepath or os.path.join(transfer_dir(context.scene), "scene.json")
        try:
            scene_export.export_scene(context.scene, bpy.path.abspath(path))
        except (scene_export.ExportError, OSError) as exc:
            self.report({'ERROR'}, str(exc))
            return {'CANCELLED'}
        self.report({'INFO'}, "Scene written to %s" % path)
        return {'FINISHED'}


classes = (VISCOSCOPE_OT_simulate, VISCOSCOPE_OT_export_scene)
