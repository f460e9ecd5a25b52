"""From a depth image and scene flow to the moving cars, as on KITTI.

The paper's KITTI pipeline: back-project the depth of the first frame with the camera's
intrinsics, add the scene flow (from a network) to get the b-points, take initial
clusters from SegmentAnything masks and register. Here the depth, flow and masks come
from a generated KITTI-like street (``make_street``); with real data, load them instead.
Run: ``python examples/kitti_pipeline.py [OUT_DIR]`` (about 5 s); OUT_DIR: write the
labels, motions and a picture there.
"""

import sys
from pathlib import Path

import numpy as np

from mmreg import MultiModelRegistration
from mmreg.datasets import make_street
from mmreg.init import PrecomputedMasks
from mmreg.metrics import iou_score, objects_found

scene = make_street(n_cars=7, n_moving=3, random_state=0)
# KITTI: depth from a stereo network or the disparity maps, K from calib_cam_to_cam.txt.
depth, K = scene.depth_image, scene.camera["K"]  # (H, W) metres, 0 = invalid; 3 x 3
columns, rows = scene.pixels.T  # the sampled valid pixels, (column, row)
flow = scene.flow  # (n, 3) scene flow of those pixels, metres

# 1. Back-project: a = depth * K^-1 [u, v, 1]; the flow gives b = a + flow.
z = depth[rows, columns]
a = np.column_stack([(columns - K[0, 2]) * z / K[0, 0], (rows - K[1, 2]) * z / K[1, 1], z])
X = np.hstack([a, a + flow])

# 2. Initial clusters from the masks of the first image, 3. register.
init = PrecomputedMasks(scene.masks, scene.pixels)
est = MultiModelRegistration(init=init, tau=1.5, random_state=0).fit(X)

# 4. Which clusters move relative to the static world (the largest cluster)?
R0, t0 = est.rotations_[0], est.translations_[0]
for j in range(est.n_clusters_):
    pts = a[est.labels_ == j]
    moved = np.linalg.norm(pts @ (est.rotations_[j] - R0).T + est.translations_[j] - t0, axis=1)
    if moved.mean() > 0.2:  # metres between the frames (0.1 s)
        print(f"cluster {j}: {len(pts)} points, moves {moved.mean():.2f} m vs the static world")

truth = np.where(scene.outlier_mask, -1, scene.labels)  # 0 static, 1..3 moving cars
print(
    f"IoU {iou_score(truth, est.labels_):.3f}, moving cars found "
    f"{objects_found(truth, est.labels_, objects=[1, 2, 3]):.0%}"
)

if len(sys.argv) > 1:  # write the result (mmreg.io) and a picture (mmreg.plotting)
    from mmreg import io
    from mmreg.plotting import plot_street

    out = Path(sys.argv[1])
    out.mkdir(parents=True, exist_ok=True)
    io.write_labels(out / "labels.npy", est.labels_)
    io.write_motions(out / "motions.json", est.rotations_, est.translations_)
    motions = (est.rotations_, est.translations_)
    plot_street(a, est.labels_, motions=motions, camera=scene.camera).savefig(out / "street.png")
    print(f"written: {out}/labels.npy, motions.json, street.png")
