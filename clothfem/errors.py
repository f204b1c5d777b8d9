"""Exceptions the runners share."""

__all__ = ["RunStopped"]


class RunStopped(RuntimeError):
    """The run was interrupted (SIGTERM / Ctrl-C); results written so far are kept."""
