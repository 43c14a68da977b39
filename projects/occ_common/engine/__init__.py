"""What runs a training or a test around the model: the hooks
(:mod:`.hooks`, registered on import), checkpoint steps and checks, the
checks of a config and its overrides, and CPU ranks."""
from . import hooks

__all__ = ['hooks']
