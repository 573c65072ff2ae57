"""Open3D's FGR and ICP on partial ModelNet40 pairs, for side-by-side checks with rgm-geom.

Writes each pair (source, target, ground truth) and Open3D's results under OUT so that the
`compare_open3d` example of rgm-geom can run the same pairs. Pairs follow spec §1 (partial
setting: random pose up to 45° per axis and ±0.5, RPM-Net crop keeping 70 %, jitter 0.01
clipped at 0.05); they are drawn here with NumPy, not by rgm-data.

    python3 -m venv /tmp/o3d && /tmp/o3d/bin/pip install open3d-cpu==0.20.0 numpy scipy
    apt-get install -y libusb-1.0-0
    OMP_NUM_THREADS=1 /tmp/o3d/bin/python crates/rgm-geom/tools/open3d_fgr_icp.py DATA_DIR OUT [PAIRS]
"""
import sys, os, time, glob
import numpy as np
import open3d as o3d
from scipy.spatial.transform import Rotation

data, out = sys.argv[1], sys.argv[2]
pairs = int(sys.argv[3]) if len(sys.argv) > 3 else 40
os.makedirs(out, exist_ok=True)
files = sorted(glob.glob(os.path.join(data, '*', 'test', '*.npy')))


def rot(a, b, c):
    rx = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    ry = np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])
    rz = np.array([[np.cos(c), -np.sin(c), 0], [np.sin(c), np.cos(c), 0], [0, 0, 1]])
    return rx @ ry @ rz


def crop(rng, p):
    n = rng.normal(size=3)
    n /= np.linalg.norm(n)
    d = (p - p.mean(0)) @ n
    return p[d > np.percentile(d, 30)]


def jitter(rng, p):
    return p + np.clip(0.01 * rng.normal(size=p.shape), -0.05, 0.05)


def cloud(p):
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(p))
    pcd.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=0.2, max_nn=30))
    n = np.asarray(pcd.normals)
    flip = ((p - p.mean(0)) * n).sum(1) < 0
    n[flip] *= -1
    pcd.normals = o3d.utility.Vector3dVector(n)
    return pcd


def mae(pred, gt):
    e = lambda m: Rotation.from_matrix(m[:3, :3]).as_euler('xyz', degrees=True)
    return np.abs(e(pred) - e(gt)).mean(), np.abs(pred[:3, 3] - gt[:3, 3]).mean()


rows = []
cpu = [0.0, 0.0]
for i in range(pairs):
    rng = np.random.default_rng(i)
    pts = np.load(files[(i * 61) % len(files)]).astype(np.float64)
    a, b, c = np.radians(rng.uniform(0, 45, 3))
    g = np.eye(4)
    g[:3, :3] = rot(a, b, c)
    g[:3, 3] = rng.uniform(-0.5, 0.5, 3)
    src = jitter(rng, crop(rng, pts @ g[:3, :3].T + g[:3, 3]))
    tgt = jitter(rng, crop(rng, pts))
    src, tgt = rng.permutation(src), rng.permutation(tgt)
    gt = np.linalg.inv(g)
    np.savetxt(f'{out}/{i:04}_src.txt', src, fmt='%.17g')
    np.savetxt(f'{out}/{i:04}_tgt.txt', tgt, fmt='%.17g')
    np.savetxt(f'{out}/{i:04}_gt.txt', gt, fmt='%.17g')
    c0 = time.process_time()
    t0 = time.perf_counter()
    s, t = cloud(src), cloud(tgt)
    param = o3d.geometry.KDTreeSearchParamHybrid(radius=0.4, max_nn=100)
    fs = o3d.pipelines.registration.compute_fpfh_feature(s, param)
    ft = o3d.pipelines.registration.compute_fpfh_feature(t, param)
    fgr = o3d.pipelines.registration.registration_fgr_based_on_feature_matching(
        s, t, fs, ft, o3d.pipelines.registration.FastGlobalRegistrationOption())
    t1 = time.perf_counter()
    c1 = time.process_time()
    icp = o3d.pipelines.registration.registration_icp(
        s, t, 0.1, np.eye(4), o3d.pipelines.registration.TransformationEstimationPointToPoint())
    t2 = time.perf_counter()
    c2 = time.process_time()
    cpu = [cpu[0] + c1 - c0, cpu[1] + c2 - c1]
    fr, ft_ = mae(fgr.transformation, gt)
    ir, it = mae(icp.transformation, gt)
    rows.append((fr, ft_, 1e3 * (t1 - t0), ir, it, 1e3 * (t2 - t1)))
    np.savetxt(f'{out}/{i:04}_open3d_fgr.txt', fgr.transformation, fmt='%.17g')
    np.savetxt(f'{out}/{i:04}_open3d_icp.txt', icp.transformation, fmt='%.17g')
r = np.array(rows)
rec = lambda er, et: np.mean((er < 1) & (et < 0.1))
print(f'pairs {len(r)}')
print(f'Open3D FGR: MAE(R) {r[:,0].mean():.3f} MAE(t) {r[:,1].mean():.4f} recall {rec(r[:,0], r[:,1]):.3f} '
      f'median time {np.median(r[:,2]):.1f} ms, mean CPU {1e3 * cpu[0] / len(r):.1f} ms (normals+FPFH+FGR, both clouds)')
print(f'Open3D ICP: MAE(R) {r[:,3].mean():.3f} MAE(t) {r[:,4].mean():.4f} recall {rec(r[:,3], r[:,4]):.3f} '
      f'median time {np.median(r[:,5]):.1f} ms, mean CPU {1e3 * cpu[1] / len(r):.1f} ms')
