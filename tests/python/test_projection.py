"""mesh2slam.project against an independent pinhole projection and m2s_features' CSV."""

import csv
import os
import subprocess
import tempfile
import unittest

import numpy as np

import mesh2slam

BUILD_DIR = os.environ.get("M2S_BINARY_DIR", "")


def pinhole(positions, camera, world_from_camera):
    """Visible vertices (near <= Z <= far, pixel inside the image) in double precision."""
    rotation, centre = world_from_camera[:3, :3], world_from_camera[:3, 3]
    p = (positions.astype(np.float64) - centre) @ rotation  # camera_from_world
    z = p[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = camera["fx"] * p[:, 0] / z + camera["cx"]
        v = camera["fy"] * p[:, 1] / z + camera["cy"]
    visible = ((z >= camera["near"]) & (z <= camera["far"]) & (u >= 0) & (u < camera["width"]) &
               (v >= 0) & (v < camera["height"]))
    return visible, u, v, z


class ProjectionTest(unittest.TestCase):

    @classmethod
    def setUpClass(cls):
        cls.scene = mesh2slam.load_scene()
        cls.times, cls.poses = mesh2slam.default_trajectory()

    def test_scene_arrays(self):
        positions = self.scene.positions
        self.assertEqual(positions.shape, (self.scene.num_vertices, 3))
        self.assertEqual(positions.dtype, np.float32)
        self.assertFalse(positions.flags.writeable)
        triangles = self.scene.triangles
        self.assertEqual(triangles.shape, (self.scene.num_triangles, 3))
        self.assertLess(int(triangles.max()), self.scene.num_vertices)
        # The documented default room: about 6 x 5 x 2.7 m, floor at z = 0.
        extent = positions.max(axis=0) - positions.min(axis=0)
        np.testing.assert_allclose(extent, [6.0, 5.0, 2.7], atol=0.3)
        self.assertAlmostEqual(float(positions[:, 2].min()), 0.0, places=5)

    def test_matches_independent_pinhole(self):
        for camera in (mesh2slam.default_camera(),
                       {"width": 320, "height": 200, "fx": 250.0, "fy": 240.0, "cx": 150.5,
                        "cy": 110.25, "near": 0.3, "far": 4.0}):
            for index in (0, 300, 900, 1500):
                pose = self.poses[index]
                features = mesh2slam.project(self.scene, camera, pose)
                visible, u, v, z = pinhole(self.scene.positions, camera, pose)
                ids = features["id"]
                self.assertEqual(ids.dtype, np.uint32)
                self.assertGreater(len(ids), 100)
                np.testing.assert_array_equal(ids, np.nonzero(visible)[0])
                self.assertLess(np.abs(features["u"] - u[ids]).max(), 1e-4)
                self.assertLess(np.abs(features["v"] - v[ids]).max(), 1e-4)
                np.testing.assert_allclose(features["depth"], z[ids], rtol=1e-6)

    def test_occlusion_removes_hidden_vertices_only(self):
        camera = mesh2slam.default_camera()
        pose = self.poses[600]
        all_visible = mesh2slam.project(self.scene, camera, pose)
        occluded = mesh2slam.project(self.scene, camera, pose, occlusion=True)
        self.assertTrue(np.all(np.isin(occluded["id"], all_visible["id"])))
        self.assertLess(len(occluded["id"]), len(all_visible["id"]))
        budget = mesh2slam.project(self.scene, camera, pose, occlusion=True, budget=500)
        self.assertEqual(len(budget["id"]), 500)
        self.assertTrue(np.all(np.isin(budget["id"], occluded["id"])))

    @unittest.skipUnless(BUILD_DIR, "M2S_BINARY_DIR not set")
    def test_equals_m2s_features_csv(self):
        tool = os.path.join(BUILD_DIR, "bin", "m2s_features")
        if not os.path.exists(tool):
            self.skipTest("m2s_features not built")
        index = 450
        with tempfile.TemporaryDirectory() as tmp:
            out = os.path.join(tmp, "features.csv")
            subprocess.run([tool, "--default-scene", "--index", str(index), "--occlusion",
                            "--budget", "700", "--noise-sigma", "0.5", "--dropout", "0.1",
                            "--seed", "7", "--out", out], check=True)
            with open(out, newline="") as f:
                rows = list(csv.DictReader(f))
        features = mesh2slam.project(
            self.scene, mesh2slam.default_camera(), self.poses[index], occlusion=True,
            budget=700, noise={"pixel_noise_sigma": 0.5, "dropout_probability": 0.1, "seed": 7},
            frame_index=index)
        self.assertEqual(len(rows), 700)
        np.testing.assert_array_equal(features["id"], [int(r["id"]) for r in rows])
        for key in ("u", "v", "depth"):  # %.9g reads back to the same float32
            np.testing.assert_array_equal(features[key],
                                          np.array([r[key] for r in rows], dtype=np.float32))


class BadInputTest(unittest.TestCase):

    @classmethod
    def setUpClass(cls):
        cls.scene = mesh2slam.load_scene()
        cls.camera = mesh2slam.default_camera()

    def assert_raises(self, error, fragment, fn, *args, **kwargs):
        with self.assertRaises(error) as raised:
            fn(*args, **kwargs)
        self.assertIn(fragment, str(raised.exception))
        self.assertNotIn("\n", str(raised.exception))

    def test_bad_pose(self):
        project = lambda pose: mesh2slam.project(self.scene, self.camera, pose)
        self.assert_raises(ValueError, "4x4", project, np.eye(3))
        self.assert_raises(ValueError, "4x4", project, [[1, 2], [3, 4]])
        pose = np.eye(4)
        pose[0, 3] = np.nan
        self.assert_raises(ValueError, "non-finite", project, pose)
        pose = np.eye(4)
        pose[:3, :3] *= 1.01
        self.assert_raises(ValueError, "rotation", project, pose)
        self.assert_raises(ValueError, "rotation", project, np.diag([1.0, 1.0, -1.0, 1.0]))
        pose = np.eye(4)
        pose[3, 0] = 1
        self.assert_raises(ValueError, "last row", project, pose)

    def test_bad_camera(self):
        project = lambda camera: mesh2slam.project(self.scene, camera, np.eye(4))
        camera = dict(self.camera)
        del camera["fx"]
        self.assert_raises(ValueError, "missing key 'fx'", project, camera)
        self.assert_raises(ValueError, "unknown key 'fov'", project, dict(self.camera, fov=90))
        self.assert_raises(ValueError, "camera", project, dict(self.camera, width=-1))
        self.assert_raises(ValueError, "camera", project, dict(self.camera, fy="wide"))
        self.assert_raises(ValueError, "dict", project, [640, 480])
        # near and far are optional, as in CAMERA.json.
        minimal = {k: self.camera[k] for k in ("width", "height", "fx", "fy", "cx", "cy")}
        self.assertGreater(len(mesh2slam.project(self.scene, minimal, np.eye(4))["id"]), 0)

    def test_bad_options(self):
        project = lambda **kw: mesh2slam.project(self.scene, self.camera, np.eye(4), **kw)
        self.assert_raises(ValueError, "budget", project, budget=-1)
        self.assert_raises(ValueError, "unknown key 'sigma'", project, noise={"sigma": 1})
        self.assert_raises(ValueError, "noise", project, noise={"dropout_probability": 2.0})
        self.assert_raises(ValueError, "seed", project, noise={"seed": -1})
        self.assert_raises(ValueError, "occlusion", project, occlusion=True, occlusion_scale=0)

    def test_bad_files(self):
        self.assert_raises(RuntimeError, "no_such_mesh.obj", mesh2slam.load_scene,
                           "/nonexistent/no_such_mesh.obj")
        self.assert_raises(RuntimeError, "no_such.tum", mesh2slam.load_trajectory,
                           "/nonexistent/no_such.tum")
        self.assert_raises(ValueError, "scale", mesh2slam.load_scene, None, scale=2.0)


if __name__ == "__main__":
    unittest.main()
