"""Build small SceneSnapshots in plain numpy for engine tests."""
import numpy as np

from voxgi.voxgi_addon.scene.snapshot import MaterialData, MeshData, ObjectData, SceneSnapshot, SkinData


def mesh(name, positions, triangles, material=0, skin=None):
    return MeshData(name=name, positions=np.asarray(positions, np.float32),
                    triangles=np.asarray(triangles, np.int32),
                    triangle_materials=np.full(len(triangles), material, np.int32), skin=skin)


def translation(x=0.0, y=0.0, z=0.0, scale=(1.0, 1.0, 1.0)):
    m = np.diag([*scale, 1.0])
    m[:3, 3] = (x, y, z)
    return m


def snapshot(meshes, objects, materials=None):
    materials = materials or [MaterialData("grey", np.array([0.5, 0.5, 0.5], np.float32))]
    return SceneSnapshot(meshes={m.name: m for m in meshes}, materials=materials,
                         objects=[ObjectData(*o) if isinstance(o, tuple) else o for o in objects])


__all__ = ["mesh", "snapshot", "translation", "SkinData", "MaterialData", "ObjectData"]
