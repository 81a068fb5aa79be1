"""A frame-to-frame monocular tracker in pure numpy, for the Python plug-in.

Vertex features carry their vertex id, so association is an id compare. The tracker:
  1. Initialises from two views: the first frame and the first later frame whose shared
     features have enough parallax. The essential matrix comes from the linear 8-point
     algorithm on the shared normalised coordinates; of its four (R, t) the one that puts the
     most points in front of both cameras wins; points are triangulated linearly (DLT). The
     world is the first camera's frame and the scale makes the median depth 1 (the library's
     convention).
  2. Tracks each later frame by Gauss-Newton on the reprojection error of the known points
     (Huber weights), started from the previous pose.
  3. Triangulates a new point from a feature's first observation and the current one as soon
     as the two rays are min_parallax_deg apart.
There is no map refinement (bundle adjustment) and no relocalisation: a method to compare
against, and a template for one's own.

Plug-in config: {"module": "python/examples/pnp_tracker.py", "class": "Tracker",
                 "options": {"min_parallax_deg": 2.0}}
"""

import numpy as np

DEFAULT_OPTIONS = {
    "min_parallax_deg": 2.0,  # initialisation and new points
    "min_points": 12,  # tracked points needed for a pose
    "iterations": 10,  # Gauss-Newton iterations per frame
    "huber_px": 2.0,  # Huber threshold, pixels
    "inlier_px": 3.0,  # reprojection error of an inlier, pixels
}


def _skew(w):
    return np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])


def _exp_so3(w):
    angle = np.linalg.norm(w)
    if angle < 1e-12:
        return np.eye(3) + _skew(w)
    k = _skew(w / angle)
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def _triangulate(cam_from_world_a, xy_a, cam_from_world_b, xy_b):
    """Linear (DLT) triangulation of N points from two camera_from_world matrices: 3x4, or
    (N,3,4) for one per point."""
    a, b = cam_from_world_a, cam_from_world_b
    rows = np.stack(
        [
            xy_a[:, :1] * a[..., 2, :] - a[..., 0, :],
            xy_a[:, 1:] * a[..., 2, :] - a[..., 1, :],
            xy_b[:, :1] * b[..., 2, :] - b[..., 0, :],
            xy_b[:, 1:] * b[..., 2, :] - b[..., 1, :],
        ],
        axis=1,
    )
    _, _, vt = np.linalg.svd(rows)
    homogeneous = vt[:, -1, :]
    return homogeneous[:, :3] / homogeneous[:, 3:]


def _parallax_deg(rays_a, rays_b):
    cos = np.sum(rays_a * rays_b, axis=1) / (
        np.linalg.norm(rays_a, axis=1) * np.linalg.norm(rays_b, axis=1))
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def _rays(xy):
    return np.hstack([xy, np.ones((len(xy), 1))])


def _essential_8point(xy1, xy2):
    """E with x2^T E x1 = 0 (x2 = R x1 + t), rank 2, from N >= 8 correspondences."""
    x1, y1 = xy1[:, 0], xy1[:, 1]
    x2, y2 = xy2[:, 0], xy2[:, 1]
    a = np.stack([x2 * x1, x2 * y1, x2, y2 * x1, y2 * y1, y2, x1, y1, np.ones_like(x1)], axis=1)
    _, _, vt = np.linalg.svd(a, full_matrices=False)
    e = vt[-1].reshape(3, 3)
    u, _, vt = np.linalg.svd(e)
    return u @ np.diag([1.0, 1.0, 0.0]) @ vt


def _relative_pose(xy1, xy2):
    """cam2_from_cam1 (R, t with |t| = 1) and the points in camera 1, from the 8-point E."""
    u, _, vt = np.linalg.svd(_essential_8point(xy1, xy2))
    if np.linalg.det(u) < 0:
        u = -u
    if np.linalg.det(vt) < 0:
        vt = -vt
    w = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    best = None
    p1 = np.hstack([np.eye(3), np.zeros((3, 1))])
    for r in (u @ w @ vt, u @ w.T @ vt):
        for t in (u[:, 2], -u[:, 2]):
            p2 = np.hstack([r, t[:, None]])
            points = _triangulate(p1, xy1, p2, xy2)
            in_front = np.count_nonzero((points[:, 2] > 0) & ((points @ r.T + t)[:, 2] > 0))
            if best is None or in_front > best[0]:
                best = (in_front, r, t, points)
    return best[1], best[2], best[3]


class Tracker:
    """The plug-in class: Tracker(camera, options), process_frame(...) -> (state, pose)."""

    def __init__(self, camera, options):
        unknown = set(options) - set(DEFAULT_OPTIONS)
        if unknown:
            raise ValueError("unknown options: " + ", ".join(sorted(unknown)))
        self.options = dict(DEFAULT_OPTIONS, **options)
        self.focal = np.array([camera["fx"], camera["fy"]])
        self.centre = np.array([camera["cx"], camera["cy"]])
        self.reset()

    def reset(self):
        self.point_ids = np.zeros(0, dtype=np.uint32)
        self.points = np.zeros((0, 3))
        self.pending = {}  # id -> (camera_from_world 3x4, normalised xy) of its first sighting
        self.reference = None  # (ids, normalised xy) of the initialisation's first frame
        self.camera_from_world = None  # 4x4, the last tracked frame's

    # ---- the plug-in methods ----

    def process_frame(self, seq, timestamp, ids, u, v):
        xy = (np.stack([u, v], axis=1).astype(np.float64) - self.centre) / self.focal
        ids = np.asarray(ids, dtype=np.uint32)
        if self.camera_from_world is None:
            return self._initialise(ids, xy)
        known = np.isin(ids, self.point_ids)
        if np.count_nonzero(known) < self.options["min_points"]:
            return "lost", None
        order = np.searchsorted(self.point_ids, ids[known])
        pose, inliers = self._solve_pose(self.points[order], xy[known], self.camera_from_world)
        if inliers < self.options["min_points"]:
            return "lost", None
        self.camera_from_world = pose
        self._add_points(ids[~known], xy[~known])
        return "ok", np.linalg.inv(pose), inliers

    def map_points(self):
        return self.point_ids, self.points.astype(np.float32)

    # ---- internals ----

    def _initialise(self, ids, xy):
        if self.reference is None:
            self.reference = (ids, xy)
            return "not_initialized", None
        ref_ids, ref_xy = self.reference
        shared, in_ref, in_cur = np.intersect1d(ref_ids, ids, return_indices=True)
        if len(shared) < 50:
            self.reference = (ids, xy)
            return "not_initialized", None
        r, t, points = _relative_pose(ref_xy[in_ref], xy[in_cur])
        parallax = _parallax_deg(points, points - (-r.T @ t))
        if np.median(parallax) < self.options["min_parallax_deg"]:
            return "not_initialized", None
        scale = 1.0 / np.median(points[:, 2])
        camera_from_world = np.eye(4)
        camera_from_world[:3, :3] = r
        camera_from_world[:3, 3] = t * scale
        order = np.argsort(shared)
        self.point_ids = shared[order]
        self.points = points[order] * scale
        self.camera_from_world, inliers = self._solve_pose(self.points,
                                                           xy[in_cur][order], camera_from_world)
        new = ~np.isin(ids, shared)
        self._add_points(ids[new], xy[new])
        return "ok", np.linalg.inv(self.camera_from_world), inliers

    def _solve_pose(self, points, xy, camera_from_world):
        """Gauss-Newton on the normalised reprojection error (left perturbation)."""
        rotation = camera_from_world[:3, :3].copy()
        translation = camera_from_world[:3, 3].copy()
        huber = self.options["huber_px"] / self.focal[0]
        for _ in range(self.options["iterations"]):
            pc = points @ rotation.T + translation
            z = pc[:, 2]
            residual = (pc[:, :2] / z[:, None] - xy).ravel()
            jac_proj = np.zeros((len(pc), 2, 3))
            jac_proj[:, 0, 0] = 1 / z
            jac_proj[:, 1, 1] = 1 / z
            jac_proj[:, 0, 2] = -pc[:, 0] / z**2
            jac_proj[:, 1, 2] = -pc[:, 1] / z**2
            jac_point = np.zeros((len(pc), 3, 6))
            jac_point[:, :, :3] = np.eye(3)
            jac_point[:, 0, 4], jac_point[:, 0, 5] = pc[:, 2], -pc[:, 1]  # -[pc]x
            jac_point[:, 1, 3], jac_point[:, 1, 5] = -pc[:, 2], pc[:, 0]
            jac_point[:, 2, 3], jac_point[:, 2, 4] = pc[:, 1], -pc[:, 0]
            jac = (jac_proj @ jac_point).reshape(-1, 6)
            norm = np.abs(residual)
            weight = np.where(norm <= huber, 1.0, huber / np.maximum(norm, 1e-300))
            h = jac.T @ (jac * weight[:, None])
            g = jac.T @ (weight * residual)
            delta = -np.linalg.solve(h, g)
            update = _exp_so3(delta[3:])
            rotation = update @ rotation
            translation = update @ translation + delta[:3]
            if np.linalg.norm(delta) < 1e-12:
                break
        u, _, vt = np.linalg.svd(rotation)  # re-orthonormalise
        pose = np.eye(4)
        pose[:3, :3] = u @ vt
        pose[:3, 3] = translation
        pc = points @ pose[:3, :3].T + pose[:3, 3]
        error_px = np.linalg.norm(pc[:, :2] / pc[:, 2:] - xy, axis=1) * self.focal[0]
        inliers = int(np.count_nonzero((error_px < self.options["inlier_px"]) & (pc[:, 2] > 0)))
        return pose, inliers

    def _add_points(self, ids, xy):
        """Triangulates features first seen in an earlier frame once their rays diverge."""
        current = self.camera_from_world[:3]
        seen = np.array([vertex in self.pending for vertex in ids.tolist()], dtype=bool)
        for vertex, x in zip(ids[~seen].tolist(), xy[~seen]):
            self.pending[vertex] = (current, x)
        if not seen.any():
            return
        first = [self.pending[vertex] for vertex in ids[seen].tolist()]
        first_cameras = np.stack([f[0] for f in first])
        first_xy = np.stack([f[1] for f in first])
        rays_first = np.einsum("nji,nj->ni", first_cameras[:, :, :3], _rays(first_xy))
        rays_now = _rays(xy[seen]) @ current[:, :3]
        ready = _parallax_deg(rays_first, rays_now) >= self.options["min_parallax_deg"]
        if not ready.any():
            return
        points = _triangulate(first_cameras[ready], first_xy[ready], current, xy[seen][ready])
        in_front = (points @ current[:, :3].T + current[:, 3])[:, 2] > 0
        new_ids = ids[seen][ready][in_front]
        for vertex in new_ids.tolist():
            del self.pending[vertex]
        ids_all = np.concatenate([self.point_ids, new_ids])
        points_all = np.vstack([self.points, points[in_front]])
        order = np.argsort(ids_all)
        self.point_ids, self.points = ids_all[order], points_all[order]
