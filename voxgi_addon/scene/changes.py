"""What a scene change costs: depsgraph update records → the GI stages to run (numpy-free).

The viewport (``render/viewport.py``) gets Blender's depsgraph updates as ``UpdateRecord``s
(``blender/updates.py`` reads them on the main thread) and asks ``plan_updates`` for the
cheapest correct work, given a ``SceneIndex`` of the last snapshot (which object uses which
cache key, material, armature):

=====================================  ==========================================================
change                                 stages
=====================================  ==========================================================
object / bone (pose) moved             snapshot, transform, inject, octree, trace (no voxelizing)
light moved or edited, world edited    snapshot, inject, octree, trace (cascades reused)
mesh geometry edited                   snapshot, voxelize that mesh key only, transform, …
material edited                        snapshot, albedo of the mesh keys using it, transform, …
node group or image edited             snapshot (full), transform, …; voxelizing follows the
                                       caches' fingerprints
object added / removed / hidden        snapshot, transform, inject, octree, trace; new keys are
  (a VISIBILITY record)                voxelized (``voxelize/incremental`` finds them)
view moved                             trace only (``view_plan``; plus the cascade stages when
                                       the view leaves the cascades' anchor cell)
=====================================  ==========================================================

Object records flagged for shading only and Collection and Action records are ignored: Blender
sends them for many things that change no voxel (a snapshot's own temporary modifier, for one);
material slots and colours arrive as Mesh / Material records. The exception: an object whose
materials read Object Info, whose Color (``ObjectEntry.color``) differs from the record's — an
edit of Object Properties › Viewport Display › Color, which Blender sends as shading alone.
Only a full snapshot reads meshes, modifiers and materials: a bone, object, light or camera change needs a posed one
(docs/gi_pipeline.md "Posed updates"). The geometry updates of a skinned object whose rest
shape may animate (its modifiers, mesh or shape keys animated: ``ObjectEntry.rest_animated``)
are not taken for poses.

"albedo" is carried out by re-voxelizing the mesh's attributes (``voxelize/incremental``:
the key's fingerprint includes its triangles' albedo, so its caches are rebuilt); the plan
keeps it apart so the cause stays visible.
"""
from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["STAGES", "UpdateRecord", "ObjectEntry", "SceneIndex", "UpdatePlan", "plan_updates",
           "view_plan", "full_plan", "StageCounter"]

# In the order they run; "snapshot" on the main thread, "trace" in view_draw, the rest on the
# worker.
STAGES = ("snapshot", "voxelize", "albedo", "transform", "inject", "octree", "trace")
_CASCADE_STAGES = frozenset({"transform", "inject", "octree", "trace"})
_LIGHT_STAGES = frozenset({"snapshot", "inject", "octree", "trace"})
_MOVE_STAGES = frozenset({"snapshot"}) | _CASCADE_STAGES

# ``UpdateRecord.id_type`` values the planner knows (Blender's ID type, lights folded to LIGHT).
# VISIBILITY is not Blender's: the set of visible mesh objects differs from the last snapshot
# (hiding an object reaches the depsgraph as a bare Scene update; blender/updates.py adds it).
ID_TYPES = ("OBJECT", "MESH", "MATERIAL", "LIGHT", "ARMATURE", "WORLD", "SCENE", "COLLECTION",
            "CAMERA", "NODETREE", "IMAGE", "ACTION", "KEY", "VISIBILITY", "OTHER")


@dataclass(frozen=True)
class UpdateRecord:
    """One ``DepsgraphUpdate`` as plain data.

    id_type : one of ``ID_TYPES``; name : the ID's ``name_full``; object_type : for OBJECT
    records the object's type ('MESH', 'LIGHT', 'ARMATURE', 'CAMERA', …), else ''.
    """

    id_type: str
    name: str
    transform: bool = False
    geometry: bool = False
    shading: bool = False
    object_type: str = ""
    color: tuple | None = None  # an OBJECT record's object's Color (what Object Info gives)


@dataclass(frozen=True)
class ObjectEntry:
    """A mesh object of the last snapshot: its cache key, mesh datablock, materials, armature;
    rest_animated: a skinned object whose rest shape a frame change may alter (animated
    modifiers, mesh or shape keys)."""

    key: str
    mesh: str = ""
    materials: tuple[str, ...] = ()
    kind: str = "static"
    armature: str | None = None        # the deforming armature object's name
    armature_data: str | None = None   # that object's Armature datablock name
    rest_animated: bool = False
    color: tuple | None = None  # its Color, where a material of it reads Object Info


@dataclass(frozen=True)
class SceneIndex:
    """Who uses what in the last snapshot. objects : mesh object name → entry; lights : light
    object names; light_data : light datablock names; visible : see below."""

    objects: dict[str, ObjectEntry] = field(default_factory=dict)
    lights: frozenset[str] = frozenset()
    light_data: frozenset[str] = frozenset()
    # the renderable objects visible when the snapshot was taken, faceless ones included (they
    # are in no snapshot; a VISIBILITY record is a change of this set); None: ``objects``' names
    visible: frozenset[str] | None = None

    def keys_of(self, predicate) -> set[str]:
        return {e.key for e in self.objects.values() if predicate(e)}


@dataclass(frozen=True)
class UpdatePlan:
    """stages : subset of ``STAGES``; voxelize / albedo : mesh keys to rebuild; full_snapshot :
    mesh data must be read again (else matrices, lights and poses suffice); triggers : why,
    in words, for the panel."""

    stages: frozenset[str] = frozenset()
    voxelize: frozenset[str] = frozenset()
    albedo: frozenset[str] = frozenset()
    full_snapshot: bool = False
    rescan: bool = False  # objects may have appeared: every key is checked (fingerprints)
    triggers: tuple[str, ...] = ()

    @property
    def empty(self) -> bool:
        return not self.stages

    def merged(self, other: "UpdatePlan") -> "UpdatePlan":
        """Both plans' work (a newer change arriving before the older one ran)."""
        return UpdatePlan(self.stages | other.stages, self.voxelize | other.voxelize,
                          self.albedo | other.albedo, self.full_snapshot or other.full_snapshot,
                          self.rescan or other.rescan,
                          tuple(dict.fromkeys(self.triggers + other.triggers)))


def full_plan(why: str = "first update") -> UpdatePlan:
    """Everything: read the whole scene, voxelize what has no valid cache, rebuild, trace."""
    return UpdatePlan(frozenset(STAGES) - {"albedo"}, full_snapshot=True, rescan=True,
                      triggers=(why,))


def view_plan(reanchored: bool) -> UpdatePlan:
    """The view moved: trace again; rebuild the cascades too when their anchor cell changed."""
    if reanchored:
        return UpdatePlan(_CASCADE_STAGES, triggers=("view moved: cascades re-anchored",))
    return UpdatePlan(frozenset({"trace"}), triggers=("view moved",))


def plan_updates(records, index: SceneIndex | None) -> UpdatePlan:
    """The cheapest correct plan for one batch of depsgraph updates (see the module table).

    index : of the snapshot the current results were built from; None (no results yet) gives
    ``full_plan``. An empty plan means nothing VoxGI shows changed.
    """
    if index is None:
        return full_plan()
    records = list(records)
    stages: set[str] = set()
    voxelize: set[str] = set()
    albedo: set[str] = set()
    triggers: list[str] = []
    full = rescan = False
    material_changed = any(r.id_type == "MATERIAL" for r in records)
    armature_objects = {r.name for r in records
                        if r.id_type == "OBJECT" and r.object_type == "ARMATURE"}
    armature_data = {r.name for r in records if r.id_type == "ARMATURE"}

    def posed(entry: ObjectEntry) -> bool:
        return entry.kind == "skinned" and not entry.rest_animated and (
            entry.armature in armature_objects or entry.armature_data in armature_data)

    def add(work, why):
        stages.update(work)
        if why not in triggers:
            triggers.append(why)

    for r in records:
        if r.id_type == "OBJECT":
            entry = index.objects.get(r.name)
            if r.object_type == "MESH" and entry is None:
                full = rescan = True
                add(_MOVE_STAGES, f"object '{r.name}' added or shown")
            elif entry is not None:
                if r.geometry and not posed(entry):
                    full = True
                    voxelize.add(entry.key)
                    add(_MOVE_STAGES | {"voxelize"}, f"mesh of '{r.name}' edited")
                elif r.transform or r.geometry:
                    add(_MOVE_STAGES, f"bones of '{r.name}' posed" if r.geometry
                        else f"object '{r.name}' moved")
                if r.shading and entry.color is not None and r.color is not None and \
                        tuple(r.color) != tuple(entry.color):
                    # its materials read Object Info › Color: their variants or bakes change
                    full = True
                    albedo.add(entry.key)
                    add(_MOVE_STAGES | {"albedo"}, f"colour of object '{r.name}' changed")
            elif r.object_type == "LIGHT" and (r.transform or r.geometry or r.shading):
                add(_LIGHT_STAGES, f"light '{r.name}' " + ("moved" if r.transform else "edited"))
            elif r.object_type == "ARMATURE" and (r.transform or r.geometry):
                if any(posed(e) for e in index.objects.values()):
                    add(_MOVE_STAGES, f"armature '{r.name}' posed or moved")
        elif r.id_type == "MESH":
            keys = index.keys_of(lambda e: e.mesh == r.name)
            if keys and r.geometry:
                full = True
                voxelize |= keys
                add(_MOVE_STAGES | {"voxelize"}, f"mesh '{r.name}' edited")
            elif keys and r.shading and not material_changed:
                full = True
                albedo |= keys
                add(_MOVE_STAGES | {"albedo"}, f"materials of mesh '{r.name}' changed")
        elif r.id_type == "MATERIAL":
            keys = index.keys_of(lambda e: r.name in e.materials)
            if keys:
                full = True
                albedo |= keys
                add(_MOVE_STAGES | {"albedo"}, f"material '{r.name}' edited")
        elif r.id_type == "LIGHT":
            if r.name in index.light_data:
                add(_LIGHT_STAGES, f"light '{r.name}' edited")
        elif r.id_type == "ARMATURE":
            if any(posed(e) for e in index.objects.values()):
                add(_MOVE_STAGES, f"armature '{r.name}' posed")
        elif r.id_type == "WORLD":
            add(_LIGHT_STAGES, "world edited")
        elif r.id_type in ("NODETREE", "IMAGE") and index.objects:
            # a node group (a material's, a modifier's) or an image (a texture): whoever uses
            # it is read again, and the caches' fingerprints say what to voxelize
            full = True
            add(_MOVE_STAGES, f"{'node group' if r.id_type == 'NODETREE' else 'image'} "
                f"'{r.name}' edited")
        elif r.id_type == "VISIBILITY":
            full = rescan = True
            add(_MOVE_STAGES, "objects added, removed, hidden or shown")
    albedo -= voxelize  # a key both edited and recoloured is voxelized once
    if not albedo:
        stages.discard("albedo")
    return UpdatePlan(frozenset(stages), frozenset(voxelize), frozenset(albedo), full, rescan,
                      tuple(triggers))


class StageCounter:
    """How often each stage was scheduled and which mesh keys were (re)built; tests and the
    panel read it."""

    def __init__(self):
        self.stages = {name: 0 for name in STAGES}
        self.voxelized: list[str] = []
        self.recoloured: list[str] = []

    def count(self, plan: UpdatePlan) -> None:
        for name in plan.stages:
            self.stages[name] += 1
        self.voxelized.extend(sorted(plan.voxelize))
        self.recoloured.extend(sorted(plan.albedo))

    def snapshot(self) -> dict[str, int]:
        return dict(self.stages)
