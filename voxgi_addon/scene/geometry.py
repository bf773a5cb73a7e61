"""The scene's triangles in world space, for exact ray casting (primary visibility, shadows).

Static and rigid objects are placed with their world matrix; skinned objects with linear blend
skinning (``skinning.py``) of their rest-pose vertices (the snapshot stores skinned meshes in
the rest pose):
``world = Σ_b w_b · (arm_world · pose_b · rest_b⁻¹ · arm_world⁻¹ · object_world) · p``, which is
what Blender's Armature modifier does. A vertex whose weights are all zero follows the object.
Shading normals come from an optional ``corner_normals`` (T, 3, 3) object-space array on
``MeshData`` (Blender's ``Mesh.corner_normals`` per loop triangle), transformed like normals.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .short_axis import norm3
from .skinning import blend_matrices, skin_matrices, transform_normals, transform_points
from .snapshot import RAY_ALL, MeshData, ObjectData, SceneSnapshot
from .textures import SurfaceTextures, surface_textures

__all__ = ["SceneTriangles", "world_triangles", "object_vertices_world"]


@dataclass(frozen=True, eq=False)
class SceneTriangles:
    """All visible triangles of a snapshot, in world space.

    positions : (T, 3, 3) float64, world-space corners (metres).
    normals : (T, 3) float64 unit face normals (right-hand winding; zero for degenerate triangles).
    materials : (T,) int32 index into ``SceneSnapshot.materials`` (-1 = none).
    objects : (T,) int32 index into ``SceneSnapshot.objects``.
    corner_normals : (T, 3, 3) float64 unit shading normals at each corner (smooth shading), or
        None when no mesh of the snapshot carries them (then shading uses the face normals).
    textures : ``textures.SurfaceTextures`` (corner UVs, each material's Base Color texture),
        or None when no material of the snapshot has a texture.
    visibility : (T,) uint8 ``snapshot.RAY_*`` bits of the rays that see each triangle (its
        object's Cycles ray visibility), or None when every ray sees every triangle.
    holdout : (T,) bool triangles a camera ray sees nothing at (a holdout object or a Holdout
        shader), or None when there are none.
    object_meshes : (O,) int32 per snapshot object an id of the mesh it places (objects with
        one id place the same triangles, in the same order; -1 = not placed), or None: what
        ``bvh.build_scene_bvh`` builds once per instanced mesh.
    """

    positions: np.ndarray
    normals: np.ndarray
    materials: np.ndarray
    objects: np.ndarray
    corner_normals: np.ndarray | None = None
    textures: SurfaceTextures | None = None
    visibility: np.ndarray | None = None
    holdout: np.ndarray | None = None
    object_meshes: np.ndarray | None = None

    def accepted(self, ray: int) -> np.ndarray | None:
        """(T,) bool: the triangles a ray of kind ``ray`` (a ``RAY_*`` bit) can hit; None when
        it can hit all of them."""
        if self.visibility is None:
            return None
        seen = (np.asarray(self.visibility) & ray) != 0
        return None if seen.all() else seen

    def __len__(self) -> int:
        return len(self.positions)

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(3,) min and max corner of the triangles whose corners are all finite (zeros when
        none: ``finite_bounds``)."""
        return finite_bounds(self.positions) or (np.zeros(3), np.zeros(3))


# The box that holds all but STRAY_AREA of the triangles' area on each side of each axis stands
# for the scene where it is under 1 / STRAY_SHRINK of the whole box (``bulk_bounds``): a small
# object far from the rest (a helper, a stray cube, a distant prop) no longer stretches the
# radiance cache's voxels or the probes' volumes over the empty space between
# (docs/gi_pipeline.md "A stray object far away").
STRAY_AREA = 0.005
STRAY_SHRINK = 2.0
_STRAY_BINS = 1024


def finite_bounds(positions) -> tuple[np.ndarray, np.ndarray] | None:
    """(3,) float64 min and max corner of the (T, 3, 3) triangles ``positions`` whose corners
    are all finite, None when none is: a triangle with a NaN or infinite corner, which the
    voxelizer drops and counts and no ray hits, must not make the radiance cache's grids, the
    probe box or any bounds NaN."""
    corners = np.asarray(positions, np.float64).reshape(-1, 3, 3)
    # one pass each over every value tells whether all are finite (a NaN or an infinity
    # shows in the min or the max): the per-triangle test only when one is not
    if len(corners) and not (np.isfinite(corners.min()) and np.isfinite(corners.max())):
        corners = corners[np.isfinite(corners).all(axis=(1, 2))]
    flat = corners.reshape(-1, 3)
    if len(flat) == 0:
        return None
    # a column at a time: numpy's reduction over the rows of an (N, 3) array runs an
    # inner loop of 3 per row (20 times slower)
    return (np.array([flat[:, k].min() for k in range(3)]),
            np.array([flat[:, k].max() for k in range(3)]))


def _bulk_box(positions, lo, hi):
    """(lo, hi) of the triangles' area but STRAY_AREA of it on each side of each axis — per
    axis the triangles' lowest corners below which lies that share of the area, and their
    highest above which it lies, in _STRAY_BINS steps of [lo, hi] rounded outwards — or None
    (no area). float32 columns: 500k triangles in a few tens of ms."""
    corners = np.asarray(positions, np.float32).reshape(-1, 3, 3)
    if not (np.isfinite(corners.min()) and np.isfinite(corners.max())):
        corners = corners[np.isfinite(corners).all(axis=(1, 2))]
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    u, v = b - a, c - a
    area = np.sqrt((u[:, 1] * v[:, 2] - u[:, 2] * v[:, 1]) ** 2 +
                   (u[:, 2] * v[:, 0] - u[:, 0] * v[:, 2]) ** 2 +
                   (u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]) ** 2)
    total = float(area.sum(dtype=np.float64))
    if not total > 0.0:
        return None
    share = STRAY_AREA * total
    out_lo, out_hi = np.array(lo, np.float64), np.array(hi, np.float64)
    for k in range(3):
        extent = float(hi[k] - lo[k])
        if not extent > 0.0:
            continue
        scale = np.float32(_STRAY_BINS / extent)
        low = np.minimum(np.minimum(a[:, k], b[:, k]), c[:, k])
        high = np.maximum(np.maximum(a[:, k], b[:, k]), c[:, k])
        low = np.clip(((low - np.float32(lo[k])) * scale).astype(np.int64), 0, _STRAY_BINS - 1)
        high = np.clip(((high - np.float32(lo[k])) * scale).astype(np.int64), 0, _STRAY_BINS - 1)
        below = np.cumsum(np.bincount(low, area, _STRAY_BINS))
        above = np.cumsum(np.bincount(high, area, _STRAY_BINS)[::-1])[::-1]
        first = min(int(np.searchsorted(below, share, side="right")), _STRAY_BINS - 1)
        kept = np.flatnonzero(above > share)
        last = int(kept[-1]) if len(kept) else _STRAY_BINS - 1
        out_lo[k] = lo[k] + first * extent / _STRAY_BINS
        out_hi[k] = min(float(hi[k]), lo[k] + (last + 1) * extent / _STRAY_BINS)
    return out_lo, np.maximum(out_hi, out_lo)


def bulk_bounds(positions) -> tuple[np.ndarray, np.ndarray] | None:
    """``finite_bounds`` of the (T, 3, 3) triangles ``positions``, or the box of the bulk of
    their area (``_bulk_box``) where that is over STRAY_SHRINK times smaller: a stray few
    triangles far away then lie outside it. None without a finite triangle."""
    bounds = finite_bounds(positions)
    if bounds is None:
        return None
    lo, hi = bounds
    bulk = _bulk_box(positions, lo, hi)
    if bulk is not None and float((hi - lo).max()) > STRAY_SHRINK * float((bulk[1] - bulk[0]).max()):
        # once more in steps of the bulk's own box (the strays fall in its end steps)
        return _bulk_box(positions, *bulk) or bulk
    return lo, hi


def _vertex_matrices(obj: ObjectData, mesh: MeshData, snapshot: SceneSnapshot) -> np.ndarray:
    """(4, 4) world matrix of a rigid object, or (V, 4, 4) blended bone matrices of a skinned one."""
    world_matrix = np.asarray(obj.world_matrix, dtype=np.float64)
    armature = snapshot.armatures.get(obj.armature) if obj.armature is not None else None
    if obj.kind != "skinned" or mesh.skin is None or armature is None or len(armature.bone_names) == 0:
        return world_matrix
    bones = skin_matrices(armature, world_matrix)
    return blend_matrices(bones, mesh.skin.weights, mesh.skin.bone_indices, fallback=world_matrix)


def object_vertices_world(obj: ObjectData, mesh: MeshData, snapshot: SceneSnapshot) -> np.ndarray:
    """(V, 3) float64 world positions of ``mesh``'s vertices as placed (and posed) by ``obj``."""
    return transform_points(_vertex_matrices(obj, mesh, snapshot), np.asarray(mesh.positions, np.float64))


def _corner_normals_world(obj, mesh, snapshot, triangles) -> np.ndarray | None:
    """(T, 3, 3) world shading normals from the mesh's object-space ``corner_normals`` (T, 3, 3),
    an optional snapshot field; None when the mesh has none."""
    corners = getattr(mesh, "corner_normals", None)
    if corners is None:
        return None
    matrices = _vertex_matrices(obj, mesh, snapshot)
    if matrices.ndim == 3:
        matrices = matrices[triangles.reshape(-1)]
    flat = np.asarray(corners, dtype=np.float64).reshape(-1, 3)
    return transform_normals(matrices, flat).reshape(-1, 3, 3)


def _is_rigid(obj: ObjectData, mesh: MeshData, snapshot: SceneSnapshot) -> bool:
    """Is ``obj`` placed by its world matrix alone (``_vertex_matrices`` gives one matrix)?"""
    return obj.kind != "skinned" or mesh.skin is None or obj.armature not in snapshot.armatures \
        or len(snapshot.armatures[obj.armature].bone_names) == 0


_PLACED_CHUNK = 1 << 18  # triangles placed together (bounds the (K, T, 3, 3) temporaries)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.cross(a, b)`` over the last axis (size 3), bit for bit (the same products and
    differences in the same order), without its axis moves and broadcasting set-up: 0.1 ms a
    call on a few rows, and twice as quick on the 142k-triangle diorama's face normals
    (``world_triangles`` is the first step of entering Rendered mode's preparation)."""
    a, b = np.asarray(a), np.asarray(b)
    out = np.empty(np.broadcast_shapes(a.shape, b.shape), np.result_type(a, b))
    for k in range(3):
        i, j = (k + 1) % 3, (k + 2) % 3
        np.multiply(a[..., i], b[..., j], out=out[..., k])
        out[..., k] -= a[..., j] * b[..., i]
    return out


def _place_rigid(matrices: np.ndarray, mesh: MeshData, shading: bool = True):
    """(K, T, 3, 3) world corners and shading normals (None without ``corner_normals``, or
    unless ``shading``) of the K placements ``matrices`` (K, 4, 4) of ``mesh``:
    ``object_vertices_world`` and ``_corner_normals_world`` of many objects in one pass."""
    linear, offset = matrices[:, :3, :3], matrices[:, :3, 3]
    corners = np.asarray(mesh.positions, np.float64)[np.asarray(mesh.triangles, np.int64)]
    world = (np.matmul(corners.reshape(1, -1, 3), linear.transpose(0, 2, 1))
             + offset[:, None, :]).reshape(len(matrices), -1, 3, 3)
    if not shading or getattr(mesh, "corner_normals", None) is None:
        return world, None
    a, b, c = linear[..., :, 0], linear[..., :, 1], linear[..., :, 2]
    cofactor = np.stack([_cross(b, c), _cross(c, a), _cross(a, b)], axis=-1)
    sign = np.sign(np.einsum("ki,ki->k", a, cofactor[..., :, 0]))  # as skinning.transform_normals
    normals = np.matmul(np.asarray(mesh.corner_normals, np.float64).reshape(1, -1, 3),
                        (cofactor * sign[:, None, None]).transpose(0, 2, 1))
    normals = normals.reshape(len(matrices), -1, 3, 3)
    length = norm3(normals)[..., None]
    return world, np.divide(normals, length, out=np.zeros_like(normals), where=length > 1e-12)


def object_materials(obj, mesh: MeshData) -> np.ndarray:
    """(T,) int32 the materials of an object's triangles: its mesh's, with each index of
    ``obj.materials``' pairs replaced by the object's own."""
    own = np.asarray(mesh.triangle_materials, dtype=np.int32)
    pairs = getattr(obj, "materials", ())
    if not pairs:
        return own
    out = own.copy()
    for mesh_index, object_index in pairs:
        out[own == mesh_index] = object_index
    return out


def world_triangles(snapshot: SceneSnapshot, shading: bool = True) -> SceneTriangles:
    """Every triangle of every object in ``snapshot`` in world space (see ``SceneTriangles``).

    Objects whose mesh is missing from the snapshot are skipped. Triangles keep the order of
    ``snapshot.objects`` then of each mesh's triangles. The objects that place one mesh by
    their world matrices (linked duplicates, instances) are transformed together.
    shading : False leaves the shading normals out (``corner_normals`` None: face normals),
    for rays that only need where they hit (the view fit's probe).
    """
    placed = [(index, obj, snapshot.meshes.get(obj.mesh)) for index, obj in enumerate(snapshot.objects)]
    placed = [(index, obj, mesh) for index, obj, mesh in placed
              if mesh is not None and len(mesh.triangles) > 0]
    if not placed:
        empty = np.zeros(0, np.int32)
        return SceneTriangles(np.zeros((0, 3, 3)), np.zeros((0, 3)), empty, empty.copy())
    counts = np.array([len(mesh.triangles) for _, _, mesh in placed], np.int64)
    starts = np.cumsum(counts) - counts
    tri = np.empty((int(counts.sum()), 3, 3))
    smooth = shading and any(getattr(mesh, "corner_normals", None) is not None
                             for _, _, mesh in placed)
    normals = np.empty_like(tri) if smooth else None
    flat = np.zeros(len(tri), bool)  # rows whose mesh has no corner normals
    kept = [index for index, _, _ in placed]  # the objects whose triangles are in, in order
    rigid: dict[str, list[int]] = {}
    for k, (_, obj, mesh) in enumerate(placed):
        rows = slice(starts[k], starts[k] + counts[k])
        flat[rows] = getattr(mesh, "corner_normals", None) is None
        if _is_rigid(obj, mesh, snapshot):
            rigid.setdefault(obj.mesh, []).append(k)
            continue
        triangles = np.asarray(mesh.triangles, dtype=np.int64)
        tri[rows] = object_vertices_world(obj, mesh, snapshot)[triangles]
        if smooth and not flat[rows.start]:
            normals[rows] = _corner_normals_world(obj, mesh, snapshot, triangles)
    for name, group in rigid.items():
        mesh = snapshot.meshes[name]
        step = max(1, _PLACED_CHUNK // len(mesh.triangles))
        for at in range(0, len(group), step):
            ks = np.asarray(group[at:at + step])
            matrices = np.stack([np.asarray(placed[k][1].world_matrix, np.float64) for k in ks])
            world, placed_normals = _place_rigid(matrices, mesh, smooth)
            rows = (starts[ks][:, None] + np.arange(len(mesh.triangles))).ravel()
            tri[rows] = world.reshape(-1, 3, 3)
            if placed_normals is not None:
                normals[rows] = placed_normals.reshape(-1, 3, 3)
    # An object placed by a matrix of negative determinant (a mirror: a scale of -1) turns its
    # triangles' winding: their second and third corners are swapped, so that each triangle's
    # cross product faces out of the surface as its shading normals do (they are placed by the
    # cofactor matrix, which keeps them out), as Cycles flips a mirrored object's triangles
    mirrored = np.array([np.linalg.det(np.asarray(obj.world_matrix, np.float64)[:3, :3]) < 0.0
                         for _, obj, _ in placed])
    turned = np.repeat(mirrored, counts)
    if turned.any():
        tri[turned] = tri[turned][:, [0, 2, 1]]
        if smooth:
            normals[turned] = normals[turned][:, [0, 2, 1]]
    normal = _cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    length = norm3(normal)[:, None]
    normal = np.divide(normal, length, out=np.zeros_like(normal), where=length > 0)
    if smooth and flat.any():  # meshes without corner normals shade flat
        normals[flat] = normal[flat][:, None]
    materials = [object_materials(obj, mesh) for _, obj, mesh in placed]
    objects = [np.full(count, index, np.int32) for (index, _, _), count in zip(placed, counts)]
    uvs = [np.zeros((len(mesh.triangles), 3, 2), np.float32) if mesh.uvs is None else
           np.asarray(mesh.uvs, np.float32).reshape(len(mesh.triangles), 3, 2)
           for _, _, mesh in placed]
    uvs = [uv[:, [0, 2, 1]] if flip else uv for uv, flip in zip(uvs, mirrored)]
    materials = np.concatenate(materials)
    objects = np.concatenate(objects)
    textures = surface_textures(snapshot, tri, materials, np.concatenate(uvs), length)
    visibility, holdout = _ray_visibility(snapshot, kept, objects, materials)
    ids: dict[str, int] = {}
    placed = np.full(len(snapshot.objects), -1, np.int32)
    for index in kept:
        placed[index] = ids.setdefault(snapshot.objects[index].mesh, len(ids))
    return SceneTriangles(tri, normal, materials, objects, normals, textures, visibility, holdout,
                          placed)


def _ray_visibility(snapshot: SceneSnapshot, kept: list[int], objects: np.ndarray,
                    materials: np.ndarray):
    """(visibility, holdout) per triangle (``SceneTriangles``) from the objects' ray visibility
    and holdout and the snapshot's Holdout-shader materials; None where nothing is special."""
    bits = np.full(len(snapshot.objects), RAY_ALL, np.uint8)
    held = np.zeros(len(snapshot.objects), bool)
    for index in kept:
        obj = snapshot.objects[index]
        bits[index] = int(getattr(obj, "visibility", RAY_ALL)) & RAY_ALL
        held[index] = bool(getattr(obj, "holdout", False))
    visibility = None if (bits[kept] == RAY_ALL).all() else bits[objects]
    holdout = held[objects]
    shaders = tuple(getattr(snapshot, "holdout_materials", ()))
    if shaders:
        holdout |= np.isin(materials, np.asarray(shaders, np.int32))
    return visibility, (holdout if holdout.any() else None)
