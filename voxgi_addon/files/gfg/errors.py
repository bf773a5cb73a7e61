"""The one error type of the GFG reader and writer."""
from __future__ import annotations

from ...errors import VoxGIError


class GFGError(VoxGIError):
    """A GFG file (or a scene to write) that breaks the format.

    ``where`` names the part of the file ("header", "section table entry 3",
    "section 4 MESH 'Cube'"), ``field`` the field or array that is wrong; both are part of
    the message.
    """

    def __init__(self, where: str, field: str, problem: str):
        super().__init__(f"{where}: {field}: {problem}")
        self.where = where
        self.field = field
        self.problem = problem
