from ..mesh._surface import mesh_surface, per_triangle_surface, shown_faces  # noqa: F401  (moved; pure numpy)
