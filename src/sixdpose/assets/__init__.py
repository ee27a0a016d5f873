"""YCB object assets: catalogue (``objects.csv``), meshes, derived physical properties, download."""

from .ycb import (
    AssetError,
    MeshData,
    PhysicalProperties,
    YcbObject,
    load_catalog,
    load_mesh,
    physical_properties,
    point_cloud_diameter,
    resolve_assets_dir,
    sample_surface,
)

__all__ = [
    "AssetError",
    "MeshData",
    "PhysicalProperties",
    "YcbObject",
    "load_catalog",
    "load_mesh",
    "physical_properties",
    "resolve_assets_dir",
    "sample_surface",
    "point_cloud_diameter",
]
