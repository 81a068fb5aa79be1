#!/usr/bin/env python3
"""Projects the default scene (or a mesh) along a trajectory, runs the SLAM system frame by
frame and prints its accuracy.

  PYTHONPATH=build/python python3 python/examples/run_slam.py --frames 300
  PYTHONPATH=build/python python3 python/examples/run_slam.py --mesh room.obj \
      --trajectory gt.tum --noise-sigma 0.5
  PYTHONPATH=build/python python3 python/examples/run_slam.py --tracker python/examples/pnp_tracker.py
"""

import argparse
import importlib.util
import sys
import time

import numpy as np

import mesh2slam


def load_tracker(path, camera):
    spec = importlib.util.spec_from_file_location("tracker", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.Tracker(camera, {})


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mesh", default=None, help="scene file (default: the default room)")
    parser.add_argument("--trajectory", default=None, help="TUM file (default: the default one)")
    parser.add_argument("--frames", type=int, default=300, help="frames to run (0: all)")
    parser.add_argument("--budget", type=int, default=1000, help="features per frame")
    parser.add_argument("--noise-sigma", type=float, default=0.0, help="pixel noise (px)")
    parser.add_argument("--no-occlusion", action="store_true")
    parser.add_argument("--tracker", default=None,
                        help="a Python tracker file (class Tracker) instead of the SLAM system")
    args = parser.parse_args()

    scene = mesh2slam.load_scene(args.mesh)
    if args.trajectory:
        times, poses = mesh2slam.load_trajectory(args.trajectory)
    else:
        times, poses = mesh2slam.default_trajectory()
    if args.frames > 0:
        times, poses = times[:args.frames], poses[:args.frames]
    camera = mesh2slam.default_camera()
    noise = {"pixel_noise_sigma": args.noise_sigma, "seed": 1} if args.noise_sigma > 0 else None

    system = None if args.tracker else mesh2slam.System(camera=camera, deterministic=True,
                                                        pixel_sigma=max(args.noise_sigma, 1.0))
    tracker = load_tracker(args.tracker, camera) if args.tracker else None
    estimates = np.full((len(times), 4, 4), np.nan)
    start = time.perf_counter()
    for i, (timestamp, pose) in enumerate(zip(times, poses)):
        features = mesh2slam.project(scene, camera, pose, occlusion=not args.no_occlusion,
                                     budget=args.budget, noise=noise, frame_index=i)
        if system is not None:
            result = system.track(i + 1, timestamp, features)
            if result["pose"] is not None:
                estimates[i] = result["pose"]
        else:
            out = tracker.process_frame(i + 1, timestamp, features["id"], features["u"],
                                        features["v"])
            if out[1] is not None:
                estimates[i] = out[1]
    elapsed = time.perf_counter() - start

    if system is not None:  # the refined trajectory (bundle adjustment moves keyframes)
        trajectory = system.trajectory()
        estimates = trajectory["pose"]
    tracked = ~np.isnan(estimates[:, 0, 0])
    print(f"{len(times)} frames in {elapsed:.1f} s, {tracked.sum()} with a pose")
    if tracked.sum() < 3:
        print("too few poses to evaluate", file=sys.stderr)
        return 1
    ate = mesh2slam.evaluate_ate(estimates[tracked], poses[tracked], align="sim3")
    rpe = mesh2slam.evaluate_rpe(estimates[tracked], poses[tracked], align="sim3")
    print(f"ATE (Sim3-aligned) rmse {ate['rmse'] * 1000:.4f} mm, max {ate['max'] * 1000:.4f} mm")
    print(f"RPE (1 frame) rmse {rpe['rmse'] * 1000:.4f} mm")
    if system is not None:
        stats = system.stats()
        print(f"{stats['keyframes']} keyframes, {stats['map_points']} map points")
    return 0


if __name__ == "__main__":
    sys.exit(main())
