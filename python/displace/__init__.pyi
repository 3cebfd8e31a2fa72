"""Type stubs of displace: what each call takes and returns."""

from os import PathLike
from typing import Callable, Dict, Literal, Optional, Sequence, Tuple, TypedDict, Union

import numpy as np
import numpy.typing as npt

__version__: str

_Points = npt.ArrayLike
"""(N, 3) float32 or float64, any memory order and stride; directions may be
one row (1, 3), used for every ray. Directions need not be unit length: ``t``
is measured in units of the direction as given (``hit = origin + t * dir``)."""

_Limits = Union[None, float, npt.ArrayLike]
"""None (unbounded), one number for every ray, or (N,) float32/float64."""

_Progress = Optional[Callable[[int, int], object]]
"""Called as ``progress(done, total)`` on the calling thread; an exception
it raises stops the job and is raised by the call."""

_Height = Union[npt.ArrayLike, str, "PathLike[str]"]
"""A 2-D array (rows, columns) of float32/float64 heights, or uint8/uint16
codes over their full scale; row j lies at v = (j + 0.5) / rows as an
image's rows do. Or a height-map file (PNG, JPEG, TIFF, EXR) or a built-in
``gen:NAME[?key=value&...]`` source, as the command line reads them."""

class FaceHits(TypedDict):
    t: npt.NDArray[np.float32]
    """(N,) ray parameter of the first hit; inf on a miss."""
    position: npt.NDArray[np.float32]
    """(N, 3) hit points in the face's physical frame; NaN on a miss."""
    normal: npt.NDArray[np.float32]
    """(N, 3) unit geometric normals of the bilinear surface (or of the
    shell's wall); NaN on a miss."""
    uv: npt.NDArray[np.float32]
    """(N, 2) texture coordinates in tiles; NaN on a miss."""
    cell: npt.NDArray[np.int64]
    """(N,) height-map cell hit, row-major (j * W + i); -1 on a miss."""
    iterations: npt.NDArray[np.uint32]
    """(N,) distance-map steps plus patches walked."""

class SceneHits(TypedDict):
    t: npt.NDArray[np.float32]
    """(N,) ray parameter of the first hit; inf on a miss."""
    position: npt.NDArray[np.float32]
    """(N, 3) world hit points; NaN on a miss."""
    normal: npt.NDArray[np.float32]
    """(N, 3) unit geometric normals as the shape defines them (not turned
    towards the ray); NaN on a miss."""
    shape: npt.NDArray[np.int64]
    """(N,) index in the file's ``[[shapes]]``; -1 on a miss, -2 on a
    visible area light."""

class EmbreeOutput(TypedDict):
    u: npt.NDArray[np.float32]
    v: npt.NDArray[np.float32]
    Ng: npt.NDArray[np.float32]
    tfar: npt.NDArray[np.float32]
    primID: npt.NDArray[np.int32]
    geomID: npt.NDArray[np.int32]

def bake(
    height: _Height,
    size: Tuple[int, int, int] = (256, 256, 16),
    extent: Tuple[float, float, float] = (1.0, 1.0, 0.1),
    *,
    height_range: Union[None, Literal["auto"], Tuple[float, float]] = None,
    address: Literal["clamp", "repeat"] = "clamp",
    method: Literal["sphere", "sphere-fixed", "exact"] = "sphere",
    iterations: int = 64,
    threads: Optional[int] = None,
    progress: _Progress = None,
) -> DistanceMap:
    """Bakes a height field into a conservative distance map of ``size``
    voxels (W, H, D) over a tile of ``extent`` (SX, SY, SZ: width, height
    and displacement depth, in the units of the rays).

    The map's W x H need not be the height field's: hits are refined on
    the full-resolution bilinear surface whatever the map's size, which
    sets only how far each step of the trace can go. A map a quarter of
    the heights a side (a voxel column over 4 x 4 texels, as Donnelly's
    maps are coarser than their textures) holds a sixteenth of the memory
    and is often as fast or faster, its codes staying in cache. The bake
    keeps no shading normals (queries never read them): its peak is the
    heights (4 bytes a texel) plus about 9 bytes a voxel.

    ``height_range`` maps the stored values to heights 0..1: None takes
    them as stored (floats must lie in [0, 1]; integer codes over their full
    scale), ``"auto"`` maps the lowest to 0 and the highest to 1, ``(lo,
    hi)`` maps lo to 0 and hi to 1 (an elevation model's metres).

    Raises ValueError for a bad array, value or option, FileNotFoundError or
    OSError for files, MemoryError when the estimated peak memory exceeds the
    machine's limit (refused before allocating), KeyboardInterrupt on Ctrl-C.
    """

def load(
    path: Union[str, "PathLike[str]"],
    height: _Height,
    extent: Optional[Tuple[float, float, float]] = None,
    *,
    height_range: Union[None, Literal["auto"], Tuple[float, float]] = None,
    address: Literal["clamp", "repeat"] = "clamp",
    method: Literal["sphere", "sphere-fixed", "exact"] = "sphere",
    iterations: int = 64,
) -> DistanceMap:
    """Loads a distance map written by ``displace bake`` or
    ``DistanceMap.save`` (.ktx2, .dds, .npy) with the height field it was
    baked from (hits are refined on it). KTX2 files carry their extent;
    .dds and .npy need ``extent`` as baked."""

class Queries:
    """Ray queries on numpy arrays, shared by ``DistanceMap`` (one face, in
    its physical frame; the id is the height-map cell) and ``Scene`` (world
    space; the id is the shape's index in ``[[shapes]]``)."""

    def intersect(
        self, origins: _Points, directions: _Points, t_max: _Limits = None, *, threads: Optional[int] = None
    ) -> Union[FaceHits, SceneHits]:
        """First hits: what ``displace trace`` (or ``trace --scene``)
        answers for the same rays, bit for bit."""
    def occluded(
        self, origins: _Points, directions: _Points, t_max: _Limits = None, *, threads: Optional[int] = None
    ) -> npt.NDArray[np.bool_]:
        """True where something lies on the ray within t_max (the shadow-ray
        query; ``trace --scene --any-hit``)."""
    def run(
        self,
        vec_origins: _Points,
        vec_directions: _Points,
        dists: _Limits = None,
        query: Literal["INTERSECT", "OCCLUDED", "DISTANCE"] = "INTERSECT",
        output: Optional[bool] = None,
        *,
        threads: Optional[int] = None,
    ) -> Union[npt.NDArray[np.int32], npt.NDArray[np.float32], EmbreeOutput]:
        """embreex's ``EmbreeScene.run``: INTERSECT gives the id hit (int32,
        -1 on a miss; embreex gives the triangle), or with ``output`` a dict
        u, v (a face's texture coordinate, not barycentrics; NaN for scenes),
        Ng, tfar, primID, geomID (0 on a hit, -1 on a miss); OCCLUDED gives
        int32 0 where blocked and -1 where not (embreex 4's convention);
        DISTANCE gives tfar (``dists``, 1e37 by default, on a miss)."""
    def intersects_first(
        self, ray_origins: _Points, ray_directions: _Points, *, threads: Optional[int] = None
    ) -> npt.NDArray[np.int64]:
        """trimesh's ``ray.intersects_first``: the id hit, -1 on a miss."""
    def intersects_any(
        self, ray_origins: _Points, ray_directions: _Points, *, threads: Optional[int] = None
    ) -> npt.NDArray[np.bool_]:
        """trimesh's ``ray.intersects_any``."""
    def intersects_location(
        self, ray_origins: _Points, ray_directions: _Points, multiple_hits: bool = True, *, threads: Optional[int] = None
    ) -> Tuple[npt.NDArray[np.float64], npt.NDArray[np.int64], npt.NDArray[np.int64]]:
        """trimesh's ``ray.intersects_location``: (locations, index_ray,
        index_tri) for the rays that hit. A displaced surface is the top of a
        solid, met once from outside: each ray has at most one hit whatever
        ``multiple_hits`` says (trimesh on an open sheet also lists exits)."""
    def intersects_id(
        self,
        ray_origins: _Points,
        ray_directions: _Points,
        multiple_hits: bool = True,
        max_hits: int = 20,
        return_locations: bool = False,
        *,
        threads: Optional[int] = None,
    ) -> Tuple[npt.NDArray[np.int64], ...]:
        """trimesh's ``ray.intersects_id``: (index_tri, index_ray[,
        locations]), one hit a ray at most (see ``intersects_location``)."""

class DistanceMap(Queries):
    """A displaced face: heights and the conservative distance map. Rays
    are in the face's physical frame: x along u in [0, SX], y along v in
    [0, SY], z up, the surface between z = 0 and z = SZ."""

    @property
    def size(self) -> Tuple[int, int, int]: ...
    @property
    def extent(self) -> Tuple[float, float, float]: ...
    @property
    def address(self) -> str: ...
    @property
    def nbytes(self) -> int:
        """Bytes held in memory (heights, distances, the heights' maximum pyramid that occluded walks)."""
    @property
    def heights(self) -> npt.NDArray[np.float32]:
        """(H, W) heights in [0, 1], a copy."""
    def save(
        self, path: Union[str, "PathLike[str]"], format: Optional[Literal["r8", "r16f", "r32f"]] = None
    ) -> None:
        """Writes .ktx2/.dds (r8 by default) or .npy (float32, physical
        units) as ``displace bake`` does, under a temporary name renamed
        last."""
    def intersect(
        self, origins: _Points, directions: _Points, t_max: _Limits = None, *, threads: Optional[int] = None
    ) -> FaceHits:
        """First hits, exactly on the bilinear surface: what ``displace
        trace`` answers for the same rays, bit for bit."""

class Scene(Queries):
    """A scene as ``displace render`` reads it: a path to a TOML file, TOML
    text, or None for the built-in default scene. Bakes are cached on disk
    (as the CLI caches them) unless ``cache=False``."""

    def __init__(self, source: Union[None, str, "PathLike[str]"] = None, *, cache: bool = True) -> None: ...
    @property
    def size(self) -> Tuple[int, int]: ...
    @property
    def spp(self) -> int: ...
    @property
    def integrator(self) -> str: ...
    @property
    def nbytes(self) -> int:
        """Bytes of the displacement maps the scene holds."""
    @property
    def warnings(self) -> Sequence[str]: ...
    def intersect(
        self, origins: _Points, directions: _Points, t_max: _Limits = None, *, threads: Optional[int] = None
    ) -> SceneHits:
        """First hits in world space: what ``displace trace --scene``
        answers for the same rays, bit for bit."""
    def render(
        self,
        spp: Optional[int] = None,
        size: Optional[Tuple[int, int]] = None,
        integrator: Optional[Literal["whitted", "path"]] = None,
        *,
        aovs: Optional[Sequence[Literal["depth", "normal", "uv", "position", "iterations"]]] = None,
        sampler: Optional[str] = None,
        threads: Optional[int] = None,
        progress: _Progress = None,
    ) -> Union[npt.NDArray[np.float32], Dict[str, npt.NDArray[np.float32]]]:
        """(H, W, 3) float32 linear RGB, as ``displace render`` renders it
        (the same pixels); ``size`` is (width, height). With ``aovs``, a dict
        of the colour image under ``"color"`` and each AOV under its name,
        (H, W, C) float32 as ``displace render --aov`` writes them. Ctrl-C
        raises KeyboardInterrupt."""
