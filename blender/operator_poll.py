"""The poll shared by VoxGI's scene operators (a mixin, so the message stays in one place)."""
from __future__ import annotations


class VoxGISceneOperator:
    """Mixin: available when the context has a scene with ``Scene.voxgi`` settings."""

    @classmethod
    def poll(cls, context):
        if context.scene is None or not hasattr(context.scene, "voxgi"):
            cls.poll_message_set("No scene with VoxGI settings")
            return False
        return True
