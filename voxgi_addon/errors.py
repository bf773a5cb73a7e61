"""The engine's error types: one for unusable input, one for a cancelled job."""


class VoxGIError(ValueError):
    """Input the engine cannot use; the message says what and where."""


class VoxGICancelled(RuntimeError):
    """A job was cancelled before it finished; nothing partial is kept."""
