"""Properties: scene.viscoscope (the workflow) and object.viscoscope (an object's role).

Lengths and volumes are stored in Blender units (unit='LENGTH' / 'VOLUME', so the UI shows the
scene's units); scene export converts them to SI once. Material values are SI already.
"""

import bpy
from bpy.props import (BoolProperty, CollectionProperty, EnumProperty, FloatProperty,
                       FloatVectorProperty, IntProperty, PointerProperty, StringProperty)

from . import mantaflow, schema

ROLE_ITEMS = [
    ('NONE', "None", "Not part of a Viscoscope scene"),
    ('SOLID', "Solid", "Exported as a solid obstacle (triangle mesh)"),
    ('CUP', "Cup", "Parametric cup with a hole in its bottom, exported as an analytic 'cup' solid"),
    ('GROUND', "Ground", "Ground plane; its height is exported as a 'ground' solid"),
    ('LIQUID', "Liquid", "Initial liquid: its bounding box is filled at frame 0"),
    ('EMITTER', "Emitter", "Liquid emitter: a disc at the object's origin along its local +Z"),
    ('DOMAIN', "Domain", "Simulation domain: its bounding box bounds the simulation"),
]

MODEL_ITEMS = [
    ('NEWTONIAN', "Newtonian", "Constant viscosity η"),
    ('POWER_LAW', "Power law", "η(γ̇) = K γ̇^(n-1)"),
    ('CARREAU', "Carreau", "η(γ̇) = η∞ + (η - η∞)(1 + (λγ̇)²)^((n-1)/2)"),
    ('HERSCHEL_BULKLEY', "Herschel–Bulkley", "η(γ̇) = (τ_y + K γ̇^n)/γ̇: a yield stress τ_y with a power-law flow above it"),
]

# The job's grid_placement_schedule.
PLACEMENT_SCHEDULE_ITEMS = [
    ('by_generation', "By Generation",
     "Each generation of the search runs on one placement, in turn; the result is the minimum of the "
     "error's mean over them (no extra cost)"),
    ('each_evaluation', "Each Evaluation",
     "Every viscosity is simulated on all placements and scored by their mean (costs as many times as "
     "much per evaluation)"),
]

# What the identification compares against (the job's "video" and/or measured "track").
REFERENCE_ITEMS = [
    ('CLIP', "Clip", "The footage's silhouettes, seen through the matched camera"),
    ('TRACK', "Measured Track", "A lab's record of a front or a radius over time (CSV), without footage"),
    ('BOTH', "Clip and Track", "The footage's silhouettes and a measured track together"),
]

# The measured track's observable (the job's track "observable").
OBSERVABLE_ITEMS = [
    ('front', "Front", "How far the liquid near the ground reaches from the origin along the direction"),
    ('radius', "Radius", "The radius of the liquid on the ground around the vertical through the origin"),
]

# The job's "forward_model".
FORWARD_MODEL_ITEMS = [
    ('simulation', "3D Simulation", "The engine's 3D fluid simulation"),
    ('thin_film', "Thin Film",
     "An axisymmetric lubrication model of a current spreading on the ground from emitters at one centre: "
     "for slow spreading over minutes, which the 3D simulation cannot afford (measured radius only)"),
]


def _cup_update(self, _context):
    from . import cup_mesh
    cup_mesh.rebuild_cup(self.id_data)


class ViscoscopeObjectSettings(bpy.types.PropertyGroup):
    role: EnumProperty(name="Role", items=ROLE_ITEMS, default='NONE')
    cup_inner_radius: FloatProperty(name="Inner Radius", unit='LENGTH', default=0.043, min=1e-5, precision=4, update=_cup_update)
    cup_height: FloatProperty(name="Inner Depth", unit='LENGTH', default=0.06, min=1e-5, precision=4, update=_cup_update)
    cup_wall: FloatProperty(name="Wall", unit='LENGTH', default=0.003, min=1e-5, precision=4, update=_cup_update)
    cup_bottom: FloatProperty(name="Bottom", unit='LENGTH', default=0.004, min=1e-5, precision=4, update=_cup_update)
    cup_hole_radius: FloatProperty(name="Hole Radius", unit='LENGTH', default=0.009, min=0.0, precision=4, update=_cup_update)
    transparent: BoolProperty(name="Transparent (glass)", default=False,
                              description="The liquid shows through this solid in the footage; an opaque "
                                          "solid hides the liquid behind and inside it in the simulated silhouettes")
    emitter_radius: FloatProperty(name="Radius", unit='LENGTH', default=0.005, min=1e-6, precision=4)
    emitter_flux: FloatProperty(name="Flux", description="Volume per second (scene units³/s)",
                                default=1e-6, min=0.0, precision=8)
    emitter_start: FloatProperty(name="Start", unit='TIME_ABSOLUTE', default=0.0, min=0.0)
    emitter_end: FloatProperty(name="End", unit='TIME_ABSOLUTE', default=1.0, min=0.0)


def _viscosity_edited(fluid, _context):
    fluid.identified_from = ""  # η is no longer what the footage gave


class ViscoscopeFluid(bpy.types.PropertyGroup):
    """The fluid material: what a preset stores. Names, units, bounds and defaults are the engine's
    declarations (schema.py); the defaults of required ones are a honey's."""
    description: StringProperty(name="Description", default="")
    viscosity: FloatProperty(**schema.float_property_args("viscosity", 8.0), soft_max=1000.0, precision=4,
                             update=_viscosity_edited)
    density: FloatProperty(**schema.float_property_args("density", 1400.0))
    surface_tension: FloatProperty(**schema.float_property_args("surface_tension", 0.0), precision=4)
    slip_length: FloatProperty(**schema.float_property_args("slip_length", 0.0), precision=5)
    model: EnumProperty(name="Model", items=MODEL_ITEMS, default='NEWTONIAN')
    consistency: FloatProperty(**schema.float_property_args("consistency", 8.0), soft_max=1000.0, precision=4)
    flow_index: FloatProperty(**schema.float_property_args("flow_index", 1.0))
    eta_infinity: FloatProperty(**schema.float_property_args("eta_infinity", 0.0), precision=4)
    relaxation_time: FloatProperty(**schema.float_property_args("relaxation_time", 1.0))
    yield_stress: FloatProperty(**schema.float_property_args("yield_stress", 0.0))
    color: FloatVectorProperty(name="Colour", subtype='COLOR', size=3, min=0.0, max=1.0,
                               default=(0.8, 0.45, 0.05))
    roughness: FloatProperty(name="Roughness", default=0.05, min=0.0, max=1.0)
    transmission: FloatProperty(name="Transmission", default=0.6, min=0.0, max=1.0)
    # The footage and interval of an identified η (identify.apply_identified_eta); setting η otherwise
    # clears it. Shown, not edited.
    identified_from: StringProperty(name="Identified From", default="")


# Where MOG2's background comes from (the job's "clean_plate_frame", "clean_plate" or "background_frames").
BACKGROUND_ITEMS = [
    ('PLATE_FRAME', "Plate: Frame of Footage", "Clean plate: one frame of the clip that shows no liquid"),
    ('PLATE_IMAGE', "Plate: Image File",
     "Clean plate: a rendered or photographed image of the scene without liquid, the clip's size"),
    ('LEADING_FRAMES', "First N Frames", "The clip's first frames, which must all show no liquid"),
]


class ViscoscopeJobStatus(bpy.types.PropertyGroup):
    """Run-time state of one kind of engine job, shown in the panel."""
    running: BoolProperty(default=False, options={'SKIP_SAVE'})
    progress: FloatProperty(name="Progress", subtype='PERCENTAGE', min=0.0, max=100.0, default=0.0)
    status: StringProperty(name="Status", default="")
    error: StringProperty(name="Error", default="")
    warning: StringProperty(name="Warning", default="")  # the engine's latest, e.g. a grid too coarse
    note: StringProperty(name="Note", default="")  # what the add-on chose for this run, e.g. a finer grid
    out_dir: StringProperty(name="Output", subtype='DIR_PATH', default="")
    can_resume: BoolProperty(default=False)


class ViscoscopeRun(bpy.types.PropertyGroup):
    """Another run of the same liquid: a scene of this file with its own container and reference."""
    scene: PointerProperty(name="Scene", type=bpy.types.Scene,
                           description="A scene set up like this one (domain, container or emitter, reference); "
                                       "its liquid is this scene's Fluid Material")


class ViscoscopeCameraPoint(bpy.types.PropertyGroup):
    label: StringProperty(name="Label", default="")
    world: FloatVectorProperty(name="World", subtype='TRANSLATION', unit='LENGTH', size=3)
    image: FloatVectorProperty(name="Pixel", size=2, description="Pixel (u right, v down) on the clip")


class ViscoscopeSceneSettings(bpy.types.PropertyGroup):
    work_dir: StringProperty(name="Work Folder", subtype='DIR_PATH', default="//viscoscope",
                             description="Where scene, job and result files are written")
    # Reference
    reference_kind: EnumProperty(name="Reference", items=REFERENCE_ITEMS, default='CLIP')
    video_path: StringProperty(name="Video", subtype='FILE_PATH', default="")
    clip: PointerProperty(name="Clip", type=bpy.types.MovieClip)
    track_csv: StringProperty(name="Track CSV", subtype='FILE_PATH', default="",
                              description="Measured track: first column time_s, then the measured column, metres")
    track_column: StringProperty(name="Column", default="",
                                 description="The CSV's measured column (empty: its second column)")
    track_observable: EnumProperty(name="Observable", items=OBSERVABLE_ITEMS, default='front')
    track_origin: FloatVectorProperty(name="Origin", subtype='TRANSLATION', unit='LENGTH', size=3,
                                      description="Where the lab measured from, in the scene")
    track_direction: FloatVectorProperty(name="Direction", subtype='XYZ', size=3, default=(1.0, 0.0, 0.0),
                                         description="Along which the front is measured (horizontal)")
    track_band: FloatProperty(name="Band", unit='LENGTH', default=0.005, min=1e-6, precision=4,
                              description="Liquid within this of the ground and of the measured line counts "
                                          "towards the front")
    track_weight: FloatProperty(name="Weight", default=1.0, min=1e-6,
                                description="The track's weight in E beside the silhouettes")
    # Other runs of this liquid, fitted together with this scene's reference (the job's "runs").
    runs: CollectionProperty(type=ViscoscopeRun)
    runs_index: IntProperty(default=0)
    time_offset: FloatProperty(name="Time Offset", unit='TIME_ABSOLUTE', default=0.0,
                               description="Simulation time at the reference's time 0 (footage or CSV)")
    forward_model: EnumProperty(name="Forward Model", items=FORWARD_MODEL_ITEMS, default='simulation')
    # Camera
    camera: PointerProperty(name="Camera", type=bpy.types.Object,
                            poll=lambda self, obj: obj.type == 'CAMERA')
    points: CollectionProperty(type=ViscoscopeCameraPoint)
    points_index: IntProperty(default=0)
    reprojection_error: FloatProperty(name="Reprojection Error", description="RMS, pixels", default=-1.0)
    # Container
    cup: PointerProperty(name="Cup", type=bpy.types.Object,
                         poll=lambda self, obj: obj.viscoscope.role == 'CUP')
    fill_volume: FloatProperty(name="Fluid Volume", unit='VOLUME', default=1.7e-4, min=0.0, precision=7)
    # Silhouettes
    background: EnumProperty(name="Background", items=BACKGROUND_ITEMS, default='PLATE_FRAME',
                             description="What the background model (MOG2) learns the scene without liquid from")
    clean_plate_frame: IntProperty(name="Plate Frame", default=0, min=0,
                                   description="Frame of the footage without liquid, counted from 0 at the clip's "
                                               "first frame")
    clean_plate_image: StringProperty(name="Plate Image", subtype='FILE_PATH', default="",
                                      description="Image of the scene without liquid, the clip's size")
    background_frames: IntProperty(name="Background Frames", default=10, min=1,
                                   description="Leading liquid-free frames that train the background model (MOG2)")
    var_threshold: FloatProperty(name="Variance Threshold", default=16.0, min=0.0,
                                 description="MOG2 variance threshold")
    mask_threshold: IntProperty(name="Threshold", default=127, min=0, max=254,
                                description="Mask = MOG2 output > threshold (shadows are 127)")
    shadow_threshold: FloatProperty(name="Shadow Threshold", default=0.7, min=0.01, max=1.0,
                                    description="A pixel darker than the background by a brightness ratio "
                                                "above this, colour unchanged, is a shadow, not liquid")
    edge_coverage: FloatProperty(name="Edge Coverage", default=0.5, min=0.0, max=0.99,
                                 description="Drop outline pixels the liquid covers less than this share of, "
                                             "so the masks match simulated silhouettes (0 = off)")
    close_diameter: IntProperty(name="Closing", default=5, min=0, max=64, subtype='PIXEL',
                                description="Morphological closing kernel diameter, pixels")
    open_diameter: IntProperty(name="Opening", default=0, min=0, max=64, subtype='PIXEL',
                               description="Morphological opening kernel diameter, pixels (0 = none: an opening "
                                           "also erases thin streams and small drops)")
    min_blob: IntProperty(name="Smallest Blob", default=3, min=0, max=10000, subtype='PIXEL',
                          description="Drop specks smaller than this many pixels")
    # The video and extraction settings the overlaid preview masks were made with (JSON).
    preview_made_with: StringProperty(default="")
    # Identify
    eta_initial: FloatProperty(name="Initial η (Pa·s)", description="Dynamic viscosity the search starts from, Pa·s",
                               default=5.0, min=schema.search_bounds("viscosity")[0],
                               max=schema.search_bounds("viscosity")[1], precision=4)
    eta_spread: FloatProperty(name="Spread (× η)", description="Initial CMA-ES spread, a factor of η (log space)",
                              default=3.0, min=1.01, max=1000.0)
    identify_resolution: IntProperty(name="Resolution", default=48, min=8, max=512,
                                     description="Cells along the domain's longest side; raised when the job is "
                                                 "written if the cup's hole would span too few cells")
    max_generations: IntProperty(name="Max Generations", default=20, min=1, max=1000)
    grid_placements: IntProperty(name="Grid Placements", default=2, min=1, max=8,
                                 description="Score viscosities on this many simulation grids moved by "
                                             "fractions of a cell, so that where small features such as the "
                                             "hole fall against the cells matters less")
    placement_schedule: EnumProperty(name="Placements", items=PLACEMENT_SCHEDULE_ITEMS, default='by_generation')
    time_budget_minutes: FloatProperty(name="Time Budget (min)", default=0.0, min=0.0, max=10000.0,
                                       description="A cap on the identification's wall time: the engine stops "
                                                   "before a generation that would overrun it, and a search it "
                                                   "stops is doubted as unconverged. 0 = none: the search ends "
                                                   "when it settles, at most after Max Generations, and takes "
                                                   "the same path on any machine")
    diagnosis_budget_minutes: FloatProperty(name="Time Budget (min)", default=30.0, min=0.0, max=10000.0,
                                            description="Wall time for the whole diagnosis, shared by its fits "
                                                        "(the base and each effect); 0 = each fit has the "
                                                        "Identify panel's time budget")
    diagnosis_effects: EnumProperty(
        name="Effects", options={'ENUM_FLAG'},
        items=[(e["name"], e["title"].capitalize(), e["description"]) for e in schema.EFFECTS],
        default={e["name"] for e in schema.EFFECTS},
        description="The effects the diagnosis tries beside the base model (each one a fit sharing the budget)")
    # Results
    result_eta: FloatProperty(name="η", default=0.0, precision=4)
    result_eta_low: FloatProperty(name="η low", default=0.0, precision=4)
    result_eta_high: FloatProperty(name="η high", default=0.0, precision=4)
    result_footage: StringProperty(name="Footage", default="")  # the video's file name
    # Why the result is probably wrong, one reason a line; while there are any, η is not applied.
    result_doubts: StringProperty(name="Doubts", default="")
    result_applied: BoolProperty(default=False)
    # Diagnosis: diagnosis.json's conclusion, its figures one line each, and the chosen model's
    # material as the engine writes it (JSON), which Apply Effect puts into the Fluid Material.
    diagnosis_conclusion: StringProperty(name="Conclusion", default="")
    diagnosis_verdict: StringProperty(default="")  # missing_effect, no_missing_effect or cannot_tell
    diagnosis_report: StringProperty(name="Report", default="")
    diagnosis_effect: StringProperty(name="Effect", default="")
    diagnosis_material: StringProperty(default="")
    diagnosis_source: StringProperty(default="")  # what Apply Effect records as the material's origin
    diagnosis_applied: BoolProperty(default=False)
    # diagnosis.json's suggested_settings (JSON) and the grid the diagnosis ran on, in words.
    diagnosis_suggested: StringProperty(default="")
    diagnosis_grid: StringProperty(default="")
    # Fluid material
    fluid: PointerProperty(type=ViscoscopeFluid)
    # Transfer simulation
    sim_resolution: IntProperty(name="Resolution", default=48, min=8, max=1024)
    sim_frames: IntProperty(name="Frames", default=60, min=1)
    sim_seed: IntProperty(name="Seed", default=1, min=0)
    # Job states
    identify_job: PointerProperty(type=ViscoscopeJobStatus)
    simulate_job: PointerProperty(type=ViscoscopeJobStatus)
    extract_job: PointerProperty(type=ViscoscopeJobStatus)
    diagnose_job: PointerProperty(type=ViscoscopeJobStatus)
    calibrate_job: PointerProperty(type=ViscoscopeJobStatus)
    # The last Mantaflow calibration (operators/mantaflow_calibration.read_calibration), JSON.
    mantaflow_calibration: StringProperty(default="")


classes = (
    ViscoscopeObjectSettings,
    ViscoscopeFluid,
    ViscoscopeJobStatus,
    ViscoscopeRun,
    ViscoscopeCameraPoint,
    ViscoscopeSceneSettings,
)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.Scene.viscoscope = PointerProperty(type=ViscoscopeSceneSettings)
    bpy.types.Object.viscoscope = PointerProperty(type=ViscoscopeObjectSettings)
    mantaflow.register()


def unregister():
    mantaflow.unregister()
    del bpy.types.Object.viscoscope
    del bpy.types.Scene.viscoscope
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
