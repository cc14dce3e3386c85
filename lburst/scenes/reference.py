"""The scene reference (``SCENE/reference.json``): defined in :mod:`lburst.sfm.reference`,
which the SfM metrics use; this name is kept so that existing imports keep working."""

from lburst.sfm.reference import Reference

__all__ = ["Reference"]
