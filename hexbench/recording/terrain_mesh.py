"""The terrain an episode walked on as a triangle mesh, for both recordings.

Heightfield terrains (rough) are sampled on a regular grid through `height_at` (the surface the
physics sees) at `DISPLAY_RESOLUTION_M`, which resolves the 0.2 m random features well;
profile terrains (flat, slopes, stairs: height depends on x only) become a strip across the
course with a vertex pair wherever the profile bends, so stair risers stay vertical to 1 cm.
The mesh covers the part of the course an episode can reach (|y| up to the lateral limit plus
margin), which keeps the per-episode files small.
"""

from __future__ import annotations

import numpy as np

DISPLAY_RESOLUTION_M = 0.1  # heightfield terrains: mesh vertex spacing [m]
PROFILE_SAMPLE_M = 0.01  # profile terrains: sampling step along x [m]
MESH_X_RANGE_M = (-0.5, 3.5)
MESH_HALF_WIDTH_M = 1.0


def terrain_mesh(terrain) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (V, 3) [m] float64, triangles (T, 3) uint32) of a built terrain."""
    x0, x1 = MESH_X_RANGE_M
    w = MESH_HALF_WIDTH_M
    if getattr(terrain, "heights_m", None) is not None:
        xs = np.arange(x0, x1 + 1e-9, DISPLAY_RESOLUTION_M)
        ys = np.arange(-w, w + 1e-9, DISPLAY_RESOLUTION_M)
        zs = np.array([[terrain.height_at(float(x), float(y)) for x in xs] for y in ys])
    else:
        xs_all = np.arange(x0, x1 + 1e-9, PROFILE_SAMPLE_M)
        z_all = np.array([terrain.height_at(float(x), 0.0) for x in xs_all])
        bend = np.abs(np.diff(z_all, 2)) > 1e-9
        keep = np.concatenate([[True], bend, [True]])
        xs, ys = xs_all[keep], np.array([-w, w])
        zs = np.tile(z_all[keep], (2, 1))
    gx, gy = np.meshgrid(xs, ys)
    vertices = np.stack([gx.ravel(), gy.ravel(), zs.ravel()], axis=1)
    nx = len(xs)
    r, c = np.meshgrid(np.arange(len(ys) - 1), np.arange(nx - 1), indexing="ij")
    v00 = (r * nx + c).ravel()
    v01, v10, v11 = v00 + 1, v00 + nx, v00 + nx + 1
    triangles = np.concatenate([np.stack([v00, v01, v11], 1), np.stack([v00, v11, v10], 1)]).astype(np.uint32)
    return vertices, triangles
