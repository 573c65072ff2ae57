"""Register two Open3D point clouds with rgm, then check the result with Open3D's own score.

    python examples/open3d_pair.py SOURCE.ply TARGET.ply   # any files Open3D reads
    python examples/open3d_pair.py                         # a made-up pair with a known pose

rgm takes and returns NumPy arrays: ``np.asarray(cloud.points)`` in, a (4, 4) transform out,
in Open3D's convention (target ← source), ready for ``cloud.transform``.
"""

import sys

import numpy as np

import rgm

try:
    import open3d as o3d
except ImportError:
    print("This example needs Open3D (pip install open3d); rgm itself does not.")
    sys.exit(0)


def made_up_pair():
    """An asymmetric shape (points on the faces of three boxes of different sizes) as an Open3D
    cloud, and a copy moved by a known pose."""
    rng = np.random.default_rng(1)
    parts = []
    for size, centre in [((0.8, 0.4, 0.2), (0, 0, 0)), ((0.2, 0.2, 0.5), (0.3, 0.1, 0.35)),
                         ((0.3, 0.1, 0.1), (-0.35, -0.25, 0.0))]:
        points = rng.uniform(-0.5, 0.5, (400, 3))
        axis = rng.integers(0, 3, 400)
        points[np.arange(400), axis] = rng.choice([-0.5, 0.5], 400)  # onto a face
        parts.append(points * size + centre)
    source = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.concatenate(parts)))
    pose = np.eye(4)
    pose[:3, :3] = o3d.geometry.get_rotation_matrix_from_xyz(np.radians([20, -10, 30]))
    pose[:3, 3] = (0.2, -0.1, 0.3)
    target = o3d.geometry.PointCloud(source).transform(pose)
    return source, target, pose


def main():
    if len(sys.argv) == 3:
        source, target = (o3d.io.read_point_cloud(path) for path in sys.argv[1:])
        pose = None
    else:
        source, target, pose = made_up_pair()
    result = rgm.register(np.asarray(source.points), np.asarray(target.points))
    np.set_printoptions(precision=5, suppress=True)
    print(f"{result.method}: {result.time_ms:.0f} ms, fitness {result.fitness:.3f}, "
          f"inlier RMSE {result.inlier_rmse:.5f}")
    print(result.transformation)
    if pose is not None:
        print("true pose:\n", pose)
    # Open3D's score of the same transform, and the moved source.
    score = o3d.pipelines.registration.evaluate_registration(
        source, target, 0.05, result.transformation
    )
    print(f"Open3D's score at 0.05: fitness {score.fitness:.3f}, RMSE {score.inlier_rmse:.5f}")
    aligned = o3d.geometry.PointCloud(source).transform(result.transformation)
    print(f"aligned source: {len(aligned.points)} points")


if __name__ == "__main__":
    main()
