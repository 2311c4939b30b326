"""hybmss: hybrid 3D mass-spring systems, validated against finite elements."""

from .scene import Body, Material, Model, Motion, Plate, Region, Scene

__all__ = ["Body", "Material", "Model", "Motion", "Plate", "Region", "Scene"]
__version__ = "0.1.0"
