"""displace: ray queries and renders of displaced surfaces, from numpy.

A height field becomes a conservative 3D distance map once (``bake``), and
rays find the displaced surface by sphere tracing that map and refining
exactly on the bilinear height surface (Donnelly, *Per-Pixel Displacement
Mapping with Distance Functions*, GPU Gems 2 ch. 8): the answers of a
tessellated mesh at the map's resolution, from a few megabytes instead of
millions of triangles and their BVH.

    import numpy as np, displace
    face = displace.bake(heights, size=(512, 512, 16), extent=(100.0, 100.0, 8.0))
    hits = face.intersect(origins, directions)      # t, position, normal, uv, cell
    blocked = face.occluded(origins, directions, t_max)

``displace.Scene`` answers the same queries on a whole scene file and
renders it (``Scene.render``); both extend ``Queries``. ``DistanceMap.run`` and ``Scene.run`` take
embreex's ``EmbreeScene.run`` arguments; ``intersects_first``,
``intersects_any``, ``intersects_location`` and ``intersects_id`` take
trimesh's ``ray`` arguments, so existing code switches by changing the
object it queries.
"""

from ._native import DistanceMap, Queries, Scene, __version__, bake, load

__all__ = ["DistanceMap", "Queries", "Scene", "bake", "load", "__version__"]
